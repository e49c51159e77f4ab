"""ground-station CLI: bad input exits 2 with a message; review prints text or JSON."""
from __future__ import annotations

import json
import subprocess
import sys

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


def test_review_text_json_and_plots(good_log, tmp_path, capsys):
    assert main(["review", str(good_log)]) == 0
    text = capsys.readouterr().out
    assert "== hover" in text and "ee slip" in text and "SALVAGED" not in text
    assert main(["review", str(good_log), "--json", "--plots", str(tmp_path / "plots")]) == 0
    s = json.loads(capsys.readouterr().out)
    assert set(s["phases"]) == {"approach", "grasp", "hover"} and s["log"]["salvaged"] is False
    assert sorted(p.split("/")[-1] for p in s["plots"]) == ["am4.png", "am5.png", "object.png"]


def test_console_script_entry_and_record_bad_output_dir(tmp_path):
    r = subprocess.run([sys.executable, "-m", "ground_station", "record", "--out", str(tmp_path / "no" / "dir.mcap"),
                        "--zenoh-listen", "none", "--duration", "0.1"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "no such directory" in r.stderr
    r = subprocess.run([sys.executable, "-m", "ground_station", "review"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2  # argparse: missing argument


def test_record_for_a_duration_writes_a_finished_empty_log(tmp_path):
    from tests.telemetry.zenoh_testing import free_endpoint
    out = tmp_path / "quiet.mcap"
    r = subprocess.run([sys.executable, "-m", "ground_station", "record", "--out", str(out), "--zenoh-listen",
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
