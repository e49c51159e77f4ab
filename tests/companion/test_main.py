"""The companion process main's own messages (in-process: nothing is started)."""
from __future__ import annotations

from pathlib import Path

import pytest

from amcore import cliargs
from companion.main import main


def test_a_bad_sim_endpoint_lists_udp_as_a_send_form_as_the_companion_reads_it(capsys):
    """mavutil's udp: listens; the companion's --sim udp: has always sent: its error's list of
    forms says so, instead of calling udp: the same as udpin:."""
    assert main(["--sysid", "4", "--sim", "udp:1.2.3"]) == 2
    err = capsys.readouterr().err
    assert "--sim: endpoint 'udp:1.2.3'" in err
    assert "(udp:HOST:PORT is the same)" not in err
    assert "udpout:HOST:PORT   send UDP to HOST:PORT (udp:HOST:PORT is read as this here" in err


def test_without_a_telemetry_key_the_companion_exits_2_saying_how_to_pass_one(capsys):
    short = str(Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_short.toml")
    assert main(["--sysid", "4", "--config", short]) == 2
    err = capsys.readouterr().err
    assert "no telemetry key" in err and "--telemetry-key-file FILE" in err and "--insecure" in err
    assert "--no-telemetry" in err


SHORT = str(Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_short.toml")
UNCREATABLE = "/proc/nope"  # its parent exists and, for root, passes os.access; mkdir still fails


@pytest.fixture
def companion_args(monkeypatch):
    """The companion's arguments up to --sim, its signal handlers restored afterwards, and the
    control law's first call stubbed (these tests end before it flies)."""
    import signal

    from amruntime import jitcache

    handlers = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    monkeypatch.setattr(jitcache, "warm", lambda first_call: jitcache.CompileReport(compiled=0, seconds=0.0))
    yield ["--sysid", "4", "--config", SHORT, "--no-telemetry", "--connect-timeout", "2"]
    for s, h in handlers.items():
        signal.signal(s, h)


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs Linux /proc")
@pytest.mark.parametrize("flag, path", [("--outcome", f"{UNCREATABLE}/am4.json"), ("--tlog", f"{UNCREATABLE}/c.tlog")])
def test_an_output_file_that_cannot_be_written_exits_2_before_flying(companion_args, capsys, monkeypatch, flag, path):
    from amruntime import jitcache

    monkeypatch.setattr(jitcache, "warm", lambda first_call: pytest.fail("got past the argument checks"))
    # past the parse's own check (tests/amcore/test_cliargs.py), as a folder that goes away after it is
    monkeypatch.setattr(cliargs, "_creatable", lambda path, text: None)
    assert main(companion_args + ["--sim", "/dev/null_no_such_tty:115200", flag, path]) == 2
    err = capsys.readouterr().err
    assert f"companion[4]: error: {flag} {path}: cannot write there: No such file or directory" in err


def test_an_sim_endpoint_that_cannot_be_opened_says_so_without_the_heartbeat_or_signing_hint(companion_args, capsys):
    assert main(companion_args + ["--sim", "/dev/nonexistent_tty:115200"]) == 1  # a link failure, as documented
    err = capsys.readouterr().err
    assert "companion[4]: error: --sim: cannot open /dev/nonexistent_tty:115200: No such file or directory" in err
    assert "HEARTBEAT" not in err and "signing key" not in err and "within" not in err


def test_an_outcome_that_cannot_be_written_at_the_end_is_an_error_not_a_traceback(companion_args, tmp_path, capsys,
                                                                                   monkeypatch):
    from amruntime import jitcache

    folder = tmp_path / "run"
    outcome = folder / "am4.json"

    def folder_goes_away(first_call):  # after the start-up check, while the companion runs
        folder.rmdir()
        folder.write_text("now a file")
        return jitcache.CompileReport(compiled=0, seconds=0.0)

    monkeypatch.setattr(jitcache, "warm", folder_goes_away)
    assert main(companion_args + ["--sim", "/dev/nonexistent_tty:115200", "--outcome", str(outcome)]) == 1
    err = capsys.readouterr().err
    assert "error: --sim: cannot open /dev/nonexistent_tty:115200" in err
    assert f"companion[4]: error: --outcome {outcome}: cannot write it: " in err


def test_a_listening_companion_that_nobody_reaches_says_how_to_point_the_simulator_at_it(companion_args, capsys):
    assert main(companion_args + ["--sim", "udpin:127.0.0.1:0", "--connect-timeout", "0.3"]) == 1
    err = capsys.readouterr().err
    assert "companion[4]: error: no simulator reached udpin:127.0.0.1:0 within 0.3 s" in err
    assert "--bind udpout: or tcp: toward this host and port" in err and "HEARTBEAT" not in err
