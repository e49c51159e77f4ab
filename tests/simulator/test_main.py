"""The simulator process main's own wording (in-process: nothing is started)."""
from __future__ import annotations

import pytest

from amlink.protocol import STATUSTEXT_MAX
from simulator.main import _told


@pytest.mark.parametrize("reason,told", [
    ("aborted by the GCS at t = 12.74 s", "mission failed: aborted by the GCS at t = 12.74 s"),
    ("am5 landed by the GCS at t = 15.70 s", "mission failed: am5 landed (GCS) at t = 15.70 s"),
    ("am4 disarmed in flight by the GCS at t = 3.00 s", "mission failed: ended by a GCS command"),
])
def test_the_last_statustext_names_a_gcs_command_within_one_statustext(reason, told):
    assert _told({"class": "commanded", "reason": reason}) == told
    assert len(told.encode()) <= STATUSTEXT_MAX


def test_other_failures_are_named_by_their_class():
    assert _told({"class": "dropped", "reason": "dropped at t = 12.40 s"}) == "mission failed: dropped"


def test_the_simulator_warms_its_kernels_under_their_lock_before_it_listens(tmp_path, monkeypatch, capsys):
    """The standalone simulator makes its kernels' first calls (`simulator.core.kernel_group`)
    through `amruntime.jitcache.warm_groups`, under the simulator group's lock, before it binds
    its endpoint: here the bind fails (the port is taken), after the warm-up."""
    import socket

    from amruntime import jitcache
    from simulator import main as sim_main

    events = []
    real_warm, real_open = jitcache.warm_groups, sim_main.SimServer.open

    def warm_groups(groups):
        events.append(("warm", [g.lock for g in groups]))
        return real_warm(groups)

    def server_open(self):
        events.append(("open", None))
        return real_open(self)
    monkeypatch.setattr(jitcache, "warm_groups", warm_groups)
    monkeypatch.setattr(sim_main.SimServer, "open", server_open)
    monkeypatch.setattr(sim_main.signal, "signal", lambda *_: None)  # pytest keeps its own SIGINT handler
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        bind = f"udp:127.0.0.1:{taken.getsockname()[1]}"
        code = sim_main.main(["--bind", bind, "--gcs", "none", "--no-telemetry", "--run-dir", str(tmp_path / "run"),
                              "--progress", "none"])
    assert code == 1 and f"cannot listen on {bind}" in capsys.readouterr().err
    assert events == [("warm", [jitcache.SIMULATOR_LOCK]), ("open", None)]
