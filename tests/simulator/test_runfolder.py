"""What am-run writes into a run folder before anything flies (the manifest, the scenario as
flown, the keys/ folder), `am-run --list`, and the summary's criteria judged from the figures."""
from __future__ import annotations

import json
import stat
import sys
import tomllib

import pytest

from amcore.config import SCENARIOS_DIR, SuccessCriteria, load_scenario
from simulator import runfolder
from simulator.verdict import criteria_rows, format_criteria
from sitl.launch import _fresh_key, _gcs_key, _telemetry_keys, main

SHORT = SCENARIOS_DIR / "two_am_short.toml"


def test_the_keys_go_into_keys_which_only_the_owner_may_open(tmp_path):
    spec = load_scenario(SHORT)
    run = tmp_path / "run"
    run.mkdir()
    files = [_fresh_key(spec, run)[1], _gcs_key(spec, run)[1], *_telemetry_keys(spec, run).values()]
    keys = run / "keys"
    assert stat.S_IMODE(keys.stat().st_mode) == 0o700
    assert sorted(p.name for p in keys.iterdir()) == sorted(f.rsplit("/", 1)[1] for f in files)
    for f in keys.iterdir():
        assert stat.S_IMODE(f.stat().st_mode) == 0o600
    assert not list(run.glob("*.key"))  # none beside the results


def test_the_scenario_as_flown_replays_with_its_own_vehicle_files(tmp_path):
    out = runfolder.write_scenario_as_flown(tmp_path, SHORT, duration_s=1.5)
    flown, source = load_scenario(out), load_scenario(SHORT)
    assert flown.duration_s == 1.5 and source.duration_s != 1.5
    assert flown.vehicle.urdf.parent == tmp_path / "vehicle"
    assert (tmp_path / "vehicle" / "am3dof.toml").read_bytes() == (SCENARIOS_DIR.parent / "vehicles" /
                                                                   "am3dof.toml").read_bytes()
    assert flown.ams == source.ams and flown.object == source.object and flown.mission == source.mission
    assert "base = " in SHORT.read_text() and "base" not in tomllib.loads(out.read_text())  # resolved: stands alone


def test_the_manifest_names_what_was_flown_how_where_and_when(tmp_path):
    import datetime
    t0 = datetime.datetime(2026, 1, 2, 3, 4, 5, tzinfo=datetime.timezone.utc)
    path = runfolder.write_manifest(tmp_path, SHORT, "two_am_short", ["two_am_short", "--duration", "2"], t0)
    m = json.loads(path.read_text())
    assert m["scenario"] == "two_am_short" and m["scenario_source"] == str(SHORT)
    assert m["command_line"] == ["am-run", "two_am_short", "--duration", "2"]
    assert m["started_utc"] == "2026-01-02T03:04:05+00:00"
    assert m["host"] and m["version"] and m["python"] == ".".join(map(str, sys.version_info[:3]))
    assert m["commit"] is None or len(m["commit"].split("-")[0]) == 40


def test_am_run_list_names_every_shipped_scenario(capsys):
    assert main(["--list"]) == 0
    text = capsys.readouterr().out
    for p in SCENARIOS_DIR.glob("*.toml"):
        assert any(line.split()[0] == p.stem for line in text.splitlines()[1:] if line.strip()), p.stem
    assert "two_am_comp_attitude" in text.splitlines()[-1]  # the default, named


def test_a_scenario_name_that_is_not_shipped_exits_2_naming_it(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["no_such_scenario", "--run-dir", str(tmp_path / "r")]) == 2
    assert "no_such_scenario" in capsys.readouterr().err


def _outcome(slip_m=0.0005, lift_m=0.28, saturated=0, steps=8000, failsafe=(), rejected=0):
    return {"steps": steps, "object": {"hover_min_lift_m": lift_m, "touching_in_hover": []},
            "ams": {"4": {"slip_max_m": slip_m, "saturated_steps": saturated, "base_contacts": []},
                    "5": {"slip_max_m": 0.0, "saturated_steps": 0, "base_contacts": []}},
            "failsafe_at_end": list(failsafe), "rejected_setpoints": rejected, "verdict": {"failures": []}}


@pytest.mark.parametrize("change,row", [
    ({"slip_m": 0.003}, "pad slip, worst pad"),
    ({"lift_m": 0.15}, "object lift, lowest in the hover window"),
    ({"saturated": 500}, "actuator saturation, worst AM"),
    ({"failsafe": [5]}, "vehicles in failsafe at the end"),
    ({"rejected": 2}, "setpoints rejected as implausible"),
])
def test_each_criterion_is_judged_from_its_figure(change, row):
    c = SuccessCriteria()
    good = {r.what: r.met for r in criteria_rows(_outcome(), c)}
    assert all(good.values()), good
    bad = {r.what: r for r in criteria_rows(_outcome(**change), c)}
    assert bad[row].met is False and all(r.met for w, r in bad.items() if w != row)
    assert "MISSED" in format_criteria(list(bad.values()))


def test_the_criteria_carry_their_units():
    text = format_criteria(criteria_rows(_outcome(slip_m=0.00123, lift_m=0.2841), SuccessCriteria()))
    assert "28.4 cm" in text and ">= 20 cm" in text and "1.23 mm" in text and "<= 2 mm" in text
    assert "<= 5 % of steps" in text
