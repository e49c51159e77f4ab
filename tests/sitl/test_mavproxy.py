"""MAVProxy, the real GCS, against `am-run`, as docs/mavlink.md shows it: the amstack dialect by
name, the run's GCS signing key kept in a file (`am-run --gcs-key-file`), MAVProxy started
with `--non-interactive` and its commands repeated by its own `repeat` (it reads no prompt).
And against the free-running simulator's GCS port (`simulator --realtime`, PX4 SITL's), as a
PX4 user runs it: MAVProxy's own default dialect, signed with the port's key file.

MAVProxy comes with the test extra (pip install -e '.[test]'; it brings opencv-python and vtk,
~245 MB; the mavproxy extra has it alone). In this environment the dialect is amstack's own. With
AMSTACK_MAVPROXY_PYTHON naming the interpreter of an environment of its own, MAVProxy runs
from there, after the documented install step (`python -m amlink.dialect_export`). Without
either the test skips, saying so."""
from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.ports import free_udp_ports

from .runner import SCENARIOS, FreeSim, script

pytestmark = pytest.mark.sitl

PASSPHRASE = "kept-across-runs"


def _mavproxy() -> tuple[str, str, bool] | None:
    """(python, mavproxy.py, its own environment?) or None."""
    own = os.environ.get("AMSTACK_MAVPROXY_PYTHON")
    if own:
        return own, str(Path(own).parent / "mavproxy.py"), True
    here = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent))
    return (sys.executable, here, False) if here else None


FOUND = _mavproxy()


class Lines(threading.Thread):
    """Every line a process prints, as it comes."""

    def __init__(self, stream) -> None:
        super().__init__(daemon=True)
        self.stream, self.lines = stream, []

    def run(self) -> None:
        for line in self.stream:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, text: str, timeout_s: float) -> int:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for i, line in enumerate(list(self.lines)):
                if text in line:
                    return i
            time.sleep(0.1)
        raise AssertionError(f"no {text!r} within {timeout_s} s: {self.lines[-30:]}")


def _unsigned_heartbeats(port: int, n: int = 3) -> None:
    """What killed MAVProxy's receive thread with a dialect lacking ardupilotmega: unsigned
    MAVLink 2 frames while its signing is on."""
    from pymavlink.dialects.v20 import common

    mav = common.MAVLink(None, srcSystem=42, srcComponent=1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for _ in range(n):
            msg = mav.heartbeat_encode(common.MAV_TYPE_GCS, common.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            s.sendto(msg.pack(mav), ("127.0.0.1", port))
            time.sleep(0.05)


def _start_mavproxy(python: str, mavproxy: str, port: int, cwd: Path, commands: str, *args: str):
    """MAVProxy listening on `port`, non-interactive, signing with PASSPHRASE then running
    `commands`; (its process, the reader of its lines)."""
    mp = subprocess.Popen(
        [python, mavproxy, f"--master=udpin:127.0.0.1:{port}", *args, "--non-interactive", "--no-state",
         "--default-modules=link,signing,cmdlong,misc,mode,arm", f"--cmd=signing key {PASSPHRASE}; {commands}"],
        cwd=cwd, env={**os.environ, "HOME": str(cwd)}, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    out = Lines(mp.stdout)
    out.start()
    return mp, out


def _stop_mavproxy(mp: subprocess.Popen, out: Lines) -> None:
    if mp.poll() is None:
        mp.send_signal(signal.SIGTERM)
    try:
        mp.wait(timeout=30)
    except subprocess.TimeoutExpired:
        mp.kill()
    out.join(5)


@pytest.mark.skipif(FOUND is None, reason="MAVProxy is not installed: pip install -e '.[test]' (or set "
                                          "AMSTACK_MAVPROXY_PYTHON to the python of MAVProxy's own environment)")
def test_mavproxy_sees_both_vehicles_arms_signed_survives_unsigned_frames_and_aborts_by_name(tmp_path):
    python, mavproxy, own = FOUND
    if own:  # the documented install step into MAVProxy's environment
        r = subprocess.run([sys.executable, "-m", "amlink.dialect_export", python], capture_output=True, text=True,
                           timeout=300)
        assert r.returncode == 0, r.stderr
    key = tmp_path / "gcs.pass"
    key.write_text(PASSPHRASE + "\n")
    key.chmod(0o600)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    mp, out = _start_mavproxy(python, mavproxy, port, tmp_path,
                              "repeat add 1 arm throttle; repeat add 1 long AM_ABORT_MISSION", "--dialect=amstack")
    run_dir = tmp_path / "run"
    run = subprocess.Popen([script("am-run"), str(SCENARIOS / "two_am_short.toml"), "--run-dir", str(run_dir),
                            "--duration", "3", "--no-telemetry", "--gcs", f"udpout:127.0.0.1:{port}",
                            "--gcs-key-file", str(key)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out.wait_for("Detected vehicle 4:1", 300)
        seen_5 = out.wait_for("Detected vehicle 5:1", 60)
        _unsigned_heartbeats(port)
        injected = max(seen_5, len(out.lines))
        _, err = run.communicate(timeout=900)
        time.sleep(1.0)
        alive = mp.poll() is None
    finally:
        if run.poll() is None:
            run.send_signal(signal.SIGTERM)
        _stop_mavproxy(mp, out)
    text = "\n".join(out.lines)
    assert alive, text[-3000:]  # the unsigned frames did not stop it
    assert "Traceback" not in text and "AttributeError" not in text, text[-3000:]
    assert "Detected vehicle 4:1" in text and "Detected vehicle 5:1" in text
    after = out.lines[injected:]
    assert any("Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED" in line for line in after), text[-3000:]
    assert any("Got COMMAND_ACK: AM_ABORT_MISSION: ACCEPTED" in line for line in after), text[-3000:]
    assert "Unknown command long" not in text
    assert run.returncode == 4, err  # the mission was aborted: failed, and the verdict says by whom
    o = json.loads((run_dir / "outcome.json").read_text())
    assert o["verdict"]["failure_class"] == "commanded"
    assert o["verdict"]["failures"][0]["reason"].startswith("aborted by the GCS at t = ")
    assert o["gcs"]["commands"] > 0 and o["gcs"]["link"]["unsigned"] == 0  # every command it sent was signed
    assert not (run_dir / "keys" / "gcs.key").exists()  # the kept key, not a new one


@pytest.mark.skipif(FOUND is None, reason="MAVProxy is not installed: pip install -e '.[test]' (or set "
                                          "AMSTACK_MAVPROXY_PYTHON to the python of MAVProxy's own environment)")
def test_mavproxy_on_the_free_running_gcs_port_sees_both_px4s_and_arms_signed(tmp_path):
    """PX4's GCS instance of each vehicle (simulator.px4.port, role gcs) to one MAVProxy: both
    vehicles detected as PX4s, its signed arm command executed and acknowledged as PX4 does,
    and nothing it sent arrived unsigned."""
    python, mavproxy, _own = FOUND
    key = tmp_path / "gcs.pass"
    key.write_text(PASSPHRASE + "\n")
    key.chmod(0o600)
    p0, p1, pg = free_udp_ports(3)
    mp, out = _start_mavproxy(python, mavproxy, pg, tmp_path, "repeat add 1 arm throttle")
    sim = None
    try:
        sim = FreeSim(tmp_path, [p0, p1], gcs=("--gcs", f"udpout:127.0.0.1:{pg}", "--gcs-key-file", str(key),
                                               "--instance", "40"))
        out.wait_for("Detected vehicle 4:1", 120)
        out.wait_for("Detected vehicle 5:1", 60)
        out.wait_for("COMPONENT_ARM_DISARM: ACCEPTED", 30)
        alive = mp.poll() is None
    finally:
        code, err, outcome = sim.stop() if sim is not None else (None, "", {})
        _stop_mavproxy(mp, out)
    text = "\n".join(out.lines)
    assert alive and "Traceback" not in text, text[-3000:]
    assert outcome, f"no outcome.json; simulator stderr:\n{err}"
    armed = [s for s in ("4", "5") if outcome["vehicles"][s]["armed_at_end"]]
    assert armed, outcome["vehicles"]  # the vehicle MAVProxy targets was armed by its command
    for s in ("4", "5"):
        g = outcome["vehicles"][s]["gcs"]
        assert g["signing"] is True and g["link"]["unsigned"] == 0, g
    assert code == 130  # stopped by SIGINT, its outcome written
