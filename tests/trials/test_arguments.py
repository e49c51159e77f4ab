"""am-trials checks what it is given before it writes or runs anything: a malformed
--scheduler address and a --controller that is unknown, or that the scenario's flight
controller mode cannot fly, exit 2 naming the argument and its value; a scheduler that
cannot be reached exits 1 naming its address. None of them leaves anything in --out."""
from __future__ import annotations

import re
import socket
import time
from pathlib import Path

import pytest

from amcore.config import read_scenario
from trials import cli, runner

ROOT = Path(__file__).resolve().parents[2]
SHORT = ROOT / "configs" / "scenarios" / "two_am_short.toml"
ATTITUDE = ROOT / "configs" / "scenarios" / "two_am_comp_attitude.toml"


def _campaign(scenario: Path, out: Path, *args: str) -> list[str]:
    # a short flight, should a check be missed and a trial fly
    return [str(scenario), "--trials", "1", "--seed", "1", "--out", str(out), "--workers", "1", "--no-progress",
            "--no-plots", "--set", "scenario.duration_s=1.0", *args]


@pytest.mark.parametrize("address,words", [
    ("localhost:8786x", "PORT '8786x' is not a whole number"),
    ("tcp://127.0.0.1:99999", "PORT must be 1-65535, got 99999"),
    ("tcp://:8786", "no HOST"),
    ("tcp://sched", "no PORT"),
    ("tcp://::1:8786", "IPv6 HOST needs brackets"),
    ("inproc://x", "scheme 'inproc'"),
    ("http://sched:8786", "scheme 'http'"),
    ("", "no HOST"),
])
def test_a_malformed_scheduler_address_exits_2_naming_it_before_anything_is_written(tmp_path, capsys, address,
                                                                                    words):
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:
        cli.main(_campaign(SHORT, out, "--scheduler", address))
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert "--scheduler" in lines[0] and repr(address) in lines[0] and words in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("address,expected,host,port", [
    ("tcp://sched.lab:8786", "tcp://sched.lab:8786", "sched.lab", 8786),
    ("sched.lab:8786", "tcp://sched.lab:8786", "sched.lab", 8786),
    ("  10.0.0.2:1 ", "tcp://10.0.0.2:1", "10.0.0.2", 1),
    ("tcp://[::1]:65535", "tcp://[::1]:65535", "::1", 65535),
    ("tls://sched.lab:8786", "tls://sched.lab:8786", "sched.lab", 8786),
])
def test_a_scheduler_address_is_read_as_dask_reads_it(address, expected, host, port):
    from distributed.comm.addressing import parse_address, parse_host_port

    got = runner.parse_scheduler_address(address)
    assert got == expected
    scheme, loc = parse_address(got, strict=True)
    assert (scheme, *parse_host_port(loc)) == (expected.split("://")[0], host, port)


def test_tls_without_dasks_tls_settings_exits_2_naming_it_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli.main(_campaign(SHORT, out, "--scheduler", "tls://127.0.0.1:1")) == 2
    [line] = capsys.readouterr().err.strip().splitlines()  # one line, no traceback
    assert line.startswith("am-trials: error: --scheduler: scheduler address 'tls://127.0.0.1:1': ") and "TLS" in line
    assert not out.exists()


def test_an_unreachable_scheduler_exits_1_naming_it_before_anything_is_written(tmp_path, capsys, monkeypatch):
    with socket.socket() as s:  # a port that was free a moment ago: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setattr(runner, "SCHEDULER_CONNECT_TIMEOUT_S", 1.0)
    out = tmp_path / "o"
    t0 = time.perf_counter()
    code = cli.main(_campaign(SHORT, out, "--scheduler", f"127.0.0.1:{port}"))
    err = capsys.readouterr().err
    assert code == 1, err
    assert time.perf_counter() - t0 < 10.0  # the timeout it was given, not the default
    [line] = err.strip().splitlines()  # one line, no traceback
    # the OS's reason when dask's last attempt was refused; none when the timeout cut an attempt short
    # (a loaded machine), as it may within dask's retry loop
    assert re.fullmatch(rf"am-trials: error: --scheduler tcp://127\.0\.0\.1:{port}: no Dask scheduler reached "
                        rf"within 1 s( \(Connection refused\))?; nothing was written to {re.escape(str(out))}", line), line
    assert not out.exists()


@pytest.mark.parametrize("scenario,controllers,bad,words", [
    (SHORT, ["passivity", "pasivity"], "pasivity", "unknown controller (known: passivity, baseline)"),
    (ATTITUDE, ["passivity", "baseline"], "baseline", "[flight_controller].mode = 'torque' only"),
])
def test_every_controller_is_checked_before_any_trial_runs(tmp_path, capsys, scenario, controllers, bad, words):
    out = tmp_path / "o"
    args = [x for c in controllers for x in ("--controller", c)]
    assert cli.main(_campaign(scenario, out, *args)) == 2
    [line] = capsys.readouterr().err.strip().splitlines()  # one line, no traceback
    assert line.startswith(f"am-trials: error: --controller {bad!r}: ")
    assert words in line
    assert not out.exists()  # no trial drawn, none flown


def test_controllers_the_scenario_can_fly_pass_the_check():
    base = read_scenario(SHORT)
    cli.check_controllers(base, SHORT, ["passivity", "baseline"])  # torque mode, with a [baseline] table
    cli.check_controllers(read_scenario(ATTITUDE), ATTITUDE, ["passivity"])
    with pytest.raises(cli.ConfigError, match="--controller 'baseline'"):
        cli.check_controllers(read_scenario(ATTITUDE), ATTITUDE, ["passivity", "baseline"])
    with pytest.raises(cli.ConfigError, match="--controller 'baseline' given twice"):
        cli.check_controllers(base, SHORT, ["baseline", "passivity", "baseline"])


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_a_campaign_stopped_by_a_signal_exits_130_within_seconds_and_leaves_no_worker(tmp_path, sig):
    """A supervisor's SIGTERM, or a SIGINT to am-trials alone (its workers not signalled), ends
    the campaign as Ctrl-C does: exit 130, the running trials stopped rather than waited for,
    no pool worker left behind."""
    import os
    import signal
    import subprocess

    from tests.sitl.runner import script

    out = tmp_path / "o"
    p = subprocess.Popen([script("am-trials"), str(ROOT / "configs" / "scenarios" / "two_am_robust_attitude.toml"),
                          "--trials", "4", "--seed", "1", "--out", str(out), "--workers", "2", "--no-plots",
                          "--no-progress"], stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not (out / "trials.partial.jsonl").exists():  # the pool is flying trials (20 s each)
            assert p.poll() is None and time.monotonic() < deadline, p.stderr.read() if p.poll() is not None else ""
            time.sleep(0.2)
        time.sleep(3.0)
        workers = subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True, text=True).stdout.split()
        assert workers  # the pool's processes
        t0 = time.monotonic()
        p.send_signal(getattr(signal, sig))
        _, err = p.communicate(timeout=60)
        took = time.monotonic() - t0
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 130, err
    assert "am-trials: interrupted" in err and "Traceback" not in err
    assert took < 15.0  # not the 20 s trials run to their end
    deadline = time.monotonic() + 5.0  # the pool's workers are stopped; its resource tracker ends on their heels
    while [w for w in workers if os.path.exists(f"/proc/{w}")] and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not [w for w in workers if os.path.exists(f"/proc/{w}")]
