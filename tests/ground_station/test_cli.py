"""ground-station CLI: bad input exits 2 with a message; review prints text or JSON."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ground_station.cli import main

from .conftest import write_mcap
from .test_review import synthetic_samples


@pytest.fixture(scope="module")
def good_log(tmp_path_factory):
    p = tmp_path_factory.mktemp("cli") / "good.mcap"
    write_mcap(p, synthetic_samples())
    return p


def test_review_of_missing_file_not_an_mcap_or_empty_log_exits_2(tmp_path, capsys):
    assert main(["review", str(tmp_path / "missing.mcap")]) == 2
    assert "no such file" in capsys.readouterr().err
    notmcap = tmp_path / "x.mcap"
    notmcap.write_bytes(b"PK\x03\x04 a zip, not a log" * 10)
    assert main(["review", str(notmcap)]) == 2
    assert "not an MCAP" in capsys.readouterr().err
    assert main(["review", str(tmp_path)]) == 2
    assert "directory" in capsys.readouterr().err
    header_only = tmp_path / "header_only.mcap"  # a recorder killed before its first flush
    from ground_station.mcap_io import McapLogWriter
    w = McapLogWriter(header_only)
    w.open()
    w._file.flush()
    assert main(["review", str(header_only)]) == 2
    assert "no controller" in capsys.readouterr().err
    w.close()


def test_review_of_a_log_whose_foxglove_channels_are_json_exits_2_saying_so(tmp_path, capsys):
    """An older recorder wrote /tf as JSON with a JSON Schema: the review says it reads them as
    protobuf only, rather than failing with a traceback."""
    from mcap.writer import Writer

    p = tmp_path / "old.mcap"
    with open(p, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("foxglove.FrameTransforms", "jsonschema", b'{"type": "object"}')
        cid = w.register_channel("/tf", "json", sid)
        w.add_message(cid, log_time=1000, data=b'{"transforms": []}', publish_time=1000)
        w.finish()
    assert main(["review", str(p)]) == 2
    assert "/tf: json messages, not protobuf" in capsys.readouterr().err


def test_review_text_json_and_plots(good_log, tmp_path, capsys):
    assert main(["review", str(good_log)]) == 0
    text = capsys.readouterr().out
    assert "== hover" in text and "ee slip" in text and "SALVAGED" not in text
    assert main(["review", str(good_log), "--json", "--plots", str(tmp_path / "plots")]) == 0
    s = json.loads(capsys.readouterr().out)
    assert set(s["phases"]) == {"approach", "grasp", "hover"} and s["log"]["salvaged"] is False
    assert sorted(p.split("/")[-1] for p in s["plots"]) == ["am4.png", "am5.png", "object.png"]


def test_console_script_entry_and_record_bad_output_dir(tmp_path):
    r = subprocess.run([sys.executable, "-m", "ground_station", "record", "--insecure", "--out", str(tmp_path / "no" / "dir.mcap"),
                        "--zenoh-listen", "none", "--duration", "0.1"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "no such directory" in r.stderr
    r = subprocess.run([sys.executable, "-m", "ground_station", "review"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2  # argparse: missing argument


def test_record_for_a_duration_writes_a_finished_empty_log(tmp_path):
    from tests.telemetry.zenoh_testing import free_endpoint
    out = tmp_path / "quiet.mcap"
    r = subprocess.run([sys.executable, "-m", "ground_station", "record", "--insecure", "--out", str(out), "--zenoh-listen",
                        free_endpoint(), "--duration", "0.3", "--summary-json"], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["stop_reason"] == "duration"
    from ground_station.mcap_io import read_log
    log = read_log(out)
    assert not log.truncated and "recorder_summary" in log.metadata


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_record_finishes_the_file_on_sigterm_and_sigint(tmp_path, sig):
    import signal

    from ground_station.mcap_io import read_log
    from tests.telemetry.zenoh_testing import free_endpoint

    from .proc import RecorderProcess

    out = tmp_path / "stopped.mcap"
    with RecorderProcess(out, free_endpoint()) as rec:
        rec.proc.send_signal(getattr(signal, sig))
        code, stdout = rec.wait(timeout_s=20.0)
    assert code == 0 and json.loads(stdout)["stop_reason"] == "signal"
    assert not read_log(out).truncated


def test_record_without_a_telemetry_key_exits_2_saying_how_to_pass_one(tmp_path, capsys):
    assert main(["record", "--out", str(tmp_path / "x.mcap"), "--zenoh-listen", "none"]) == 2
    err = capsys.readouterr().err
    assert "no telemetry key" in err and "--telemetry-key-file FILE" in err and "--insecure" in err
    assert not (tmp_path / "x.mcap").exists()


def test_keys_writes_a_runs_telemetry_keys_for_processes_by_hand(tmp_path, capsys):
    """The master key for the recorder and each publisher's own key derived from it, owner-only
    files; a second set into the same folder is refused (it would lock the first one's users out)."""
    import stat

    from telemetry.auth import publisher_key

    folder = tmp_path / "keys"
    short = Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_short.toml"
    assert main(["keys", str(folder), "--config", str(short)]) == 0
    out = capsys.readouterr().out
    files = {p.name: p for p in folder.iterdir()}
    assert sorted(files) == ["telemetry-am4.key", "telemetry-am5.key", "telemetry-simulator.key", "telemetry.key"]
    assert all(stat.S_IMODE(p.stat().st_mode) == 0o600 for p in files.values())
    master = bytes.fromhex(files["telemetry.key"].read_text().strip())
    for name in ("simulator", "am4", "am5"):
        assert bytes.fromhex(files[f"telemetry-{name}.key"].read_text().strip()) == publisher_key(master, name)
        assert f"{name}: --telemetry-key-file {folder / f'telemetry-{name}.key'}" in out
    assert main(["keys", str(folder), "--config", str(short)]) == 2
    assert "already holds telemetry.key" in capsys.readouterr().err
    assert bytes.fromhex(files["telemetry.key"].read_text().strip()) == master  # untouched


UNCREATABLE = "/proc/nope"  # its parent exists and, for root, passes os.access; mkdir still fails


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs Linux /proc")
def test_keys_and_plots_into_a_folder_that_cannot_be_created_exit_2_naming_it(good_log, capsys, monkeypatch):
    """The same mistake as `record --out` in a missing folder: one line naming the flag, exit 2, no traceback.
    Past the parse's own check (tests/amcore/test_cliargs.py), as a folder that goes away after it is."""
    from amcore import cliargs

    monkeypatch.setattr(cliargs, "_creatable", lambda path, text: None)
    short = Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_short.toml"
    assert main(["keys", UNCREATABLE, "--config", str(short)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ground-station: error: ") and UNCREATABLE in err and err.count("\n") == 1, err
    assert main(["review", str(good_log), "--plots", f"{UNCREATABLE}/plots"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ground-station: error: ") and f"{UNCREATABLE}/plots" in err and err.count("\n") == 1, err


def test_review_plots_that_cannot_be_written_exit_1_naming_the_file(good_log, tmp_path, capsys, monkeypatch):
    import errno

    from ground_station import plots

    def full_disk(run, out_dir):
        raise OSError(errno.ENOSPC, "No space left on device", str(out_dir / "am4.png"))

    monkeypatch.setattr(plots, "write_plots", full_disk)
    assert main(["review", str(good_log), "--plots", str(tmp_path / "plots")]) == 1
    err = capsys.readouterr().err
    assert f"--plots {tmp_path / 'plots'}: cannot write {tmp_path / 'plots' / 'am4.png'}: No space left" in err
