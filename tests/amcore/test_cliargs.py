"""Bad flags, flag by flag, through every process main: exit code 2 and one line naming the
flag, at once (no traceback, no hang, nothing started)."""
from __future__ import annotations

import argparse
import importlib
import signal
import time
from pathlib import Path

import pytest

from amcore import cliargs

ROOT = Path(__file__).resolve().parents[2]
SHORT = str(ROOT / "configs" / "scenarios" / "two_am_short.toml")


@pytest.fixture
def paths(tmp_path):
    f = tmp_path / "a_file"
    f.write_text("x")
    return {"FILE": str(f), "DIR": str(tmp_path), "UNDER_FILE": str(f / "sub" / "out.json"),
            "RUN": str(tmp_path / "run"), "NO_NEW_FILES": "/proc/amstack-test/out"}  # /proc: even root cannot


SIM = ("simulator.main", ["--config", SHORT, "--run-dir", "RUN"])
COMP = ("companion.main", ["--sysid", "4", "--config", SHORT])
AMRUN = ("sitl.launch", [SHORT, "--run-dir", "RUN", "--no-telemetry"])
REC = ("ground_station.cli", ["record", "--out", "RUN.mcap"])
INPROC = ("sitl.inprocess", [SHORT])

# (main, its valid arguments, the bad flag and value, the words naming it)
CASES = [
    (SIM, ["--peer-timeout", "nan"], "--peer-timeout"),
    (SIM, ["--step-timeout", "nan"], "--step-timeout"),
    (SIM, ["--step-timeout", "-1"], "--step-timeout"),
    (SIM, ["--duration", "inf"], "--duration"),
    (SIM, ["--duration", "-1"], "--duration"),
    (SIM, ["--duration", "1e-9"], "--duration"),
    (SIM, ["--failsafe-after-rejected", "0"], "--failsafe-after-rejected"),
    (SIM, ["--run-dir", "FILE"], "--run-dir"),
    (SIM, ["--run-dir", "UNDER_FILE"], "--run-dir"),
    (SIM, ["--telemetry-wait", "nan"], "--telemetry-wait"),
    (SIM, ["--bind", "udpout:127.0.0.1:0"], "--bind"),
    (SIM, ["--gcs", "udpout:255.255.255.255:14551"], "--gcs"),
    (SIM, ["--config", "DIR"], "is a directory"),
    (COMP, ["--connect-timeout", "nan"], "--connect-timeout"),
    (COMP, ["--frame-timeout", "inf"], "--frame-timeout"),
    (COMP, ["--sim", "udp:127.0.0.1:0"], "--sim"),
    (COMP, ["--sim", "udpout:255.255.255.255:14550"], "--sim"),
    (COMP, ["--sim", "udpout:0.0.0.0:14550"], "--sim"),
    (COMP, ["--sysid", "1"], "--sysid"),
    (COMP, ["--telemetry-every", "0"], "--telemetry-every"),
    (COMP, ["--outcome", "DIR"], "--outcome"),
    (COMP, ["--tlog", "UNDER_FILE"], "--tlog"),
    (COMP, ["--outcome", "NO_NEW_FILES"], "--outcome"),
    (COMP, ["--tlog", "NO_NEW_FILES"], "--tlog"),
    (SIM, ["--run-dir", "NO_NEW_FILES"], "--run-dir"),
    (AMRUN, ["--run-dir", "NO_NEW_FILES"], "--run-dir"),
    (REC, ["--out", "NO_NEW_FILES"], "--out"),
    (("ground_station.cli", ["keys"]), ["NO_NEW_FILES"], "/proc/amstack-test/out: cannot create it"),
    (("ground_station.cli", ["review", "FILE"]), ["--plots", "NO_NEW_FILES"], "--plots"),
    (AMRUN, ["--duration", "-1"], "--duration"),
    (AMRUN, ["--duration", "nan"], "--duration"),
    (AMRUN, ["--startup-timeout", "nan"], "--startup-timeout"),
    (AMRUN, ["--run-dir", "FILE"], "--run-dir"),
    (REC, ["--duration", "nan"], "--duration"),
    (REC, ["--linger", "-1"], "--linger"),
    (REC, ["--flush-period", "0"], "--flush-period"),
    (REC, ["--scene-rate", "nan"], "--scene-rate"),
    (REC, ["--out", "DIR"], "--out"),
    (REC, ["--zenoh-listen", "garbage"], "--zenoh-listen"),
    (REC, ["--zenoh-config", "DIR"], "--zenoh-config"),
    (SIM, ["--zenoh-config", "FILE"], "zenoh config"),  # not JSON5
    (SIM, ["--zenoh-connect", "garbage"], "--zenoh-connect"),
    (COMP, ["--zenoh-connect", "tcp/127.0.0.1"], "--zenoh-connect"),
    (("ground_station.cli", ["review", "FILE"]), ["--plots", "FILE"], "--plots"),
    (INPROC, ["--duration", "inf"], "--duration"),
    (INPROC, ["--failsafe-after-rejected", "-1"], "--failsafe-after-rejected"),
]


def _argv(args, paths):
    out = []
    for a in args:
        for name, value in paths.items():
            if a == name or a.startswith(name + "."):
                a = value + a[len(name):]
        out.append(a)
    return out


@pytest.mark.parametrize("main,bad,words", CASES, ids=[f"{c[0][0]} {' '.join(c[1])}" for c in CASES])
def test_a_bad_flag_exits_2_with_one_line_naming_it(main, bad, words, paths, capsys, monkeypatch):
    monkeypatch.setattr(signal, "signal", lambda *_a: None)  # a main that got as far must not take the test's
    module, base = main
    argv = _argv(base, paths)
    flag = bad[0]
    if flag in argv:  # replace the base's value of this flag
        i = argv.index(flag)
        argv[i:i + 2] = _argv(bad, paths)
    else:
        argv += _argv(bad, paths)
    t0 = time.monotonic()
    try:
        code = importlib.import_module(module).main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2, err
    assert time.monotonic() - t0 < 10.0
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if "error:" in line]  # warnings may come first
    assert len(errors) == 1 and words in errors[0], err


def test_zenoh_connect_garbage_is_refused_naming_the_flag():
    from telemetry.session import TelemetryConfigError, ZenohOptions

    for bad in ("garbage", "tcp/", "tcp/127.0.0.1", "tcp/127.0.0.1:0", "tcp/127.0.0.1:99999", "http/x:1"):
        with pytest.raises(TelemetryConfigError, match="--zenoh-connect"):
            ZenohOptions(connect=(bad,))
    assert ZenohOptions(connect=("tcp/127.0.0.1:7447", "tls/[::1]:7447"), listen=("tcp/127.0.0.1:0",))


@pytest.mark.parametrize("text,ok", [("1", True), ("0.5", True), ("0", False), ("-1", False), ("nan", False),
                                     ("inf", False), ("-inf", False), ("x", False), ("1e400", False)])
def test_seconds_are_finite_and_positive(text, ok):
    import argparse

    if ok:
        assert cliargs.seconds(text) == float(text)
    else:
        with pytest.raises(argparse.ArgumentTypeError, match="finite number > 0"):
            cliargs.seconds(text)


def test_am_run_refuses_a_run_that_does_not_fit_in_memory(monkeypatch, capsys, tmp_path):
    """200 AMs need about 37 GiB: refused up front with the estimate, naming [[am]]."""
    from amcore.config import load_scenario
    from sitl import launch

    spec = load_scenario(SHORT)
    with pytest.raises(Exception, match=r"\[\[am\]\]: 2 AMs need about 0\.\d GiB"):
        launch.check_memory(spec, available=100.0)
    launch.check_memory(spec, available=4096.0)  # fits
    assert launch.memory_needed_mib(200) > 200 * launch.COMPANION_MIB
    monkeypatch.setattr(launch, "available_mib", lambda: 100.0)
    assert launch.main([SHORT, "--run-dir", str(tmp_path / "r"), "--no-telemetry"]) == 2
    assert "AMs need about" in capsys.readouterr().err and not (tmp_path / "r").exists()


@pytest.mark.parametrize("module,defaults", [
    ("companion.main", ["--connect-timeout CONNECT_TIMEOUT seconds to wait for the simulator (default: 30.0)",
                        "(default: 10.0)", "two_am_comp_attitude.toml)"]),
    ("simulator.main", ["(default: 60.0)", "(default: 5.0)", "two_am_comp_attitude.toml)"]),
    ("sitl.launch", ["(default: 120.0)", "two_am_comp_attitude.toml)"]),
])
def test_help_gives_every_default(module, defaults, capsys, monkeypatch):
    """The timeouts and the scenario, as --help shows them: every option with a value says its
    default."""
    monkeypatch.setenv("COLUMNS", "400")  # argparse breaks a path longer than the line inside a word
    main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as ex:
        main(["--help"])
    assert ex.value.code == 0
    text = " ".join(capsys.readouterr().out.split()).replace("- ", "-")  # argparse wraps paths at '-'
    for d in defaults:
        assert d in text, (d, text)


def test_the_help_formatter_leaves_flags_and_unset_options_alone(capsys):
    ap = cliargs.ArgumentParser(prog="p")
    ap.add_argument("--flag", action="store_true", help="a flag")
    ap.add_argument("--unset", default=None, help="not given: none")
    ap.add_argument("--said", default=3, help="n (default 3, as the text says)")
    ap.add_argument("--n", type=int, default=7, help="a count")
    ap.add_argument("where", nargs="?", default="here", help="a place")
    ap.print_help()
    text = " ".join(capsys.readouterr().out.split())
    assert "a flag (default" not in text and "not given: none (default" not in text
    assert text.count("default 3") == 1 and "a count (default: 7)" in text and "a place (default: here)" in text


@pytest.mark.parametrize("kind", [cliargs.output_dir, cliargs.output_file])
def test_an_output_path_where_no_file_can_be_made_is_refused_when_parsed(kind, tmp_path):
    """os.access grants root every folder, /proc among them; the parse tries a nameless file."""
    with pytest.raises(argparse.ArgumentTypeError, match="cannot create it"):
        kind("/proc/amstack-test/out")
    assert kind(str(tmp_path / "new" / "out")) == tmp_path / "new" / "out"
    assert list(tmp_path.iterdir()) == []  # the probe leaves nothing behind
