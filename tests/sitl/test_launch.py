"""am-run's own checks and wiring (in-process: nothing is started)."""
from __future__ import annotations

from pathlib import Path

import pytest

from amcore.config import load_scenario
from sitl.launch import _gcs_key, main

SCENARIOS = Path(__file__).resolve().parents[2] / "configs" / "scenarios"


@pytest.mark.parametrize("content,words", [
    (None, "cannot read GCS key file"),
    ("gr\u00fcn\n", "cannot read GCS key file"),
    ("\n", "non-empty ASCII"),
])
def test_a_bad_gcs_key_file_exits_2_before_anything_starts(tmp_path, capsys, content, words):
    key = tmp_path / "gcs.key"
    if content is not None:
        key.write_text(content, encoding="utf-8")
    run = tmp_path / "run"
    assert main([str(SCENARIOS / "two_am_short.toml"), "--gcs-key-file", str(key), "--run-dir", str(run)]) == 2
    err = capsys.readouterr().err
    assert str(key) in err and words in err, err
    assert not run.exists()


def test_a_gcs_key_file_with_signing_off_is_refused(tmp_path, capsys):
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'base = "{SCENARIOS / "two_am_short.toml"}"\n\n[link]\nsigning = false\n')
    key = tmp_path / "gcs.key"
    key.write_text("a passphrase\n")
    assert main([str(scenario), "--gcs-key-file", str(key), "--run-dir", str(tmp_path / "run")]) == 2
    assert "turns signing off" in capsys.readouterr().err


def test_the_simulator_gets_the_kept_gcs_key_or_a_new_one_per_run(tmp_path):
    """--gcs-key-file: that file, the same for every run; without it a new random passphrase in
    each run folder (mode 0600)."""
    spec = load_scenario(SCENARIOS / "two_am_short.toml")
    key = tmp_path / "kept.key"
    key.write_text("kept-passphrase\n")
    assert _gcs_key(spec, tmp_path / "run1", key) == ["--gcs-key-file", str(key.resolve())]
    assert not (tmp_path / "run1").exists()
    drawn = []
    for run in ("run2", "run3"):
        (tmp_path / run).mkdir()
        flag, path = _gcs_key(spec, tmp_path / run)
        assert flag == "--gcs-key-file" and Path(path) == tmp_path / run / "keys" / "gcs.key"
        assert Path(path).stat().st_mode & 0o777 == 0o600
        drawn.append(Path(path).read_text())
    assert drawn[0] != drawn[1]
