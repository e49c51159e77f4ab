"""A short campaign end to end (am-trials on two_am_short): its table, summary, plots and
replayable scenario files agree with each other; a local process pool and a Dask cluster
give the same trials, bit for bit."""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from amcore.config import load_scenario, read_scenario, scenario_from_dict
from simulator.verdict import FAILURE_CLASSES
from sitl.inprocess import run
from trials import cli
from trials.report import read_csv, wilson_interval
from trials.runner import run_all
from trials.randomize import load_randomize

ROOT = Path(__file__).resolve().parents[2]
SHORT = ROOT / "configs" / "scenarios" / "two_am_short.toml"
SEED = 7


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    out = tmp_path_factory.mktemp("campaign")
    code = cli.main([str(SHORT), "--trials", "4", "--seed", str(SEED), "--out", str(out), "--workers", "2",
                     "--no-progress"])
    assert code == 0
    return out


def test_the_table_holds_every_trial_with_its_draws_and_verdict(campaign):
    rows = read_csv(campaign / "trials.csv")
    assert [r["trial"] for r in rows] == [0, 1, 2, 3]
    for r in rows:
        assert 0.5 <= r["object_mass_kg"] <= 2.0 and 0.5 <= r["pad_friction"] <= 1.2
        assert r["verdict"] in ("success", "failed")
        assert (r["failure_class"] == "") == (r["verdict"] == "success")
        assert r["failure_class"] in ("", *FAILURE_CLASSES)
        assert len(r["state_digest"]) == 64 and math.isfinite(r["max_slip_m"])
        assert r["reason"].startswith("mission success" if r["verdict"] == "success" else "mission FAILED: ")


def test_the_summary_counts_the_table(campaign):
    rows = read_csv(campaign / "trials.csv")
    s = json.loads((campaign / "summary.json").read_text())
    ok = sum(r["verdict"] == "success" for r in rows)
    assert s["trials"] == 4 and s["successes"] == ok and s["success_rate"] == ok / 4
    assert s["wilson95"] == pytest.approx(list(wilson_interval(ok, 4)))
    assert sum(s["failure_classes"].values()) == 4 - ok - s["incomplete"]
    for c in FAILURE_CLASSES:
        assert s["failure_classes"][c] == sum(r["failure_class"] == c for r in rows)
    assert s["trials_per_minute"] > 0
    assert s["flown_per_minute"] == pytest.approx(s["trials_per_minute"] * s["flown"] / s["trials"])


def test_plots_show_success_against_each_drawn_parameter(campaign):
    names = {p.name for p in (campaign / "plots").glob("*.png")}
    for param in ("object_mass_kg", "pad_friction", "setpoint_loss", "object_yaw_deg", "am4_start_heading_deg",
                  "max_start_offset_m"):
        assert f"success_vs_{param}.png" in names


def test_a_trial_replays_from_its_scenario_file(campaign):
    row = read_csv(campaign / "trials.csv")[1]
    spec = load_scenario(row["scenario_file"])
    assert spec.object.mass_kg == row["object_mass_kg"] and spec.seed == row["seed"]
    assert dict((a.sysid, a.start_heading_deg) for a in spec.ams)[5] == row["am5_start_heading_deg"]
    assert spec.object.yaw_deg == row["object_yaw_deg"] and spec.mission.object_pose == "mocap"
    again = run(spec)
    assert again["state_digest"] == row["state_digest"]
    assert again["verdict"]["status"] == row["verdict"]


def test_a_dask_cluster_runs_the_same_trials_as_the_local_pool(campaign, tmp_path):
    from dask.distributed import LocalCluster

    rows = read_csv(campaign / "trials.csv")
    tasks = cli.build_tasks(read_scenario(SHORT), SHORT, load_randomize(cli.DEFAULT_RANDOMIZE), SEED, 4, tmp_path, None)
    tasks = [t for t in tasks if t.index in (0, 3)]
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with cli.executor(2, cluster.scheduler_address) as ex:
            dask_rows = run_all(tasks, ex)
    for d in dask_rows:
        pool = rows[d["trial"]]
        for key in ("state_digest", "verdict", "failure_class", "object_mass_kg", "max_slip_m", "hover_min_lift_m"):
            assert d[key] == pool[key], key


@pytest.mark.parametrize("args,words", [
    (["--trials", "0"], "--trials: must be >= 1"),
    (["--seed", "-1"], "--seed: must be in 0..2**32-1"),
    (["--workers", "x"], "--workers: expected a whole number"),
])
def test_bad_arguments_exit_2_naming_the_flag(tmp_path, capsys, args, words):
    base = {"--trials": "2", "--seed": "1", "--out": str(tmp_path / "o")}
    for k, v in zip(args[::2], args[1::2]):
        base[k] = v
    with pytest.raises(SystemExit) as e:
        cli.main([str(SHORT), *[x for kv in base.items() for x in kv]] + args[len(args):])
    assert e.value.code == 2 and words in capsys.readouterr().err


def test_a_bad_randomize_file_or_output_folder_exits_2(tmp_path, capsys):
    bad = tmp_path / "r.toml"
    bad.write_text("[randomize]\nobject_mass = [1.0, 2.0]\n")
    assert cli.main([str(SHORT), "--trials", "1", "--seed", "1", "--out", str(tmp_path / "o"),
                     "--randomize", str(bad)]) == 2
    assert "unknown key 'object_mass'" in capsys.readouterr().err
    file = tmp_path / "f"
    file.write_text("")
    assert cli.main([str(SHORT), "--trials", "1", "--seed", "1", "--out", str(file)]) == 2
    assert "not a folder" in capsys.readouterr().err


def test_trials_read_the_campaigns_own_copy_of_the_vehicle(campaign):
    """Editing the project's vehicle files during or after a campaign changes none of its trials."""
    spec = load_scenario(read_csv(campaign / "trials.csv")[0]["scenario_file"])
    assert spec.vehicle.urdf.parent == (campaign / "scenarios" / "vehicle").resolve()
    assert spec.vehicle.urdf.read_bytes() == (ROOT / "configs" / "vehicles" / "am3dof.urdf").read_bytes()


def test_a_trial_that_raises_is_an_error_row_and_the_others_run_on():
    from concurrent.futures import ThreadPoolExecutor

    from trials.runner import TrialTask

    bad = [TrialTask(i, {"scenario": {"name": "x"}, "colour": {}}, str(SHORT), {"p": float(i)}) for i in range(3)]
    seen = []
    with ThreadPoolExecutor(2) as ex:
        rows = run_all(bad, ex, seen.append)
    assert [r["trial"] for r in rows] == [0, 1, 2] and len(seen) == 3
    assert all(r["verdict"] == "error" and "unknown table [colour]" in r["reason"] for r in rows)


def test_set_changes_the_base_scenario_of_every_trial_and_only_what_it_names(tmp_path):
    base = read_scenario(SHORT)
    data = cli.apply_overrides(base, ["mission.squeeze_sizing=true", "pad.shape=\"crowned\"",
                                      "am.misalignment_deg=1.5"])
    assert data["mission"]["squeeze_sizing"] is True and data["pad"]["shape"] == "crowned"
    assert [a["misalignment_deg"] for a in data["am"]] == [1.5] * len(base["am"])
    nested = cli.apply_overrides(base, ["devices.estimator.gyro_cutoff_hz=0.0", "devices.scale=2.0"])
    assert nested["devices"] == {"estimator": {"gyro_cutoff_hz": 0.0}, "scale": 2.0}
    assert data["object"] == base["object"] and "pad" not in base  # the base is left as it was
    rand = load_randomize(cli.DEFAULT_RANDOMIZE)
    plain = cli.build_tasks(base, SHORT, rand, 5, 2, tmp_path / "a", None)
    changed = cli.build_tasks(data, SHORT, rand, 5, 2, tmp_path / "b", None)
    for p, c in zip(plain, changed):  # the same draws, the option on
        assert p.params == c.params
        spec = load_scenario(c.path)
        assert spec.mission.squeeze_sizing and spec.vehicle.pad.shape == "crowned"
        assert not load_scenario(p.path).mission.squeeze_sizing


@pytest.mark.parametrize("override,words", [
    ("mission.squeeze_sizing", "expected TABLE.KEY=VALUE"),
    ("devices..scale=1.0", "expected TABLE.KEY=VALUE"),
    ("devices.estimator.gyro_cut=1.0", "[devices.estimator]: unknown key 'gyro_cut'"),
    ("squeeze_sizing=true", "expected TABLE.KEY=VALUE"),
    ("pad.shape=crowned", "VALUE is not a TOML value"),
    ("mission.squeeze_size=true", "[mission]: unknown key 'squeeze_size'"),
    ("pad.crown_radius_m=-1.0", "crown_radius_m"),
])
def test_a_bad_set_exits_2_naming_it(tmp_path, capsys, override, words):
    assert cli.main([str(SHORT), "--trials", "1", "--seed", "1", "--out", str(tmp_path / "o"),
                     "--set", override]) == 2
    err = capsys.readouterr().err
    assert words in err and override in err.splitlines()[0], err  # the --set it came from, named


@pytest.mark.parametrize("n", range(1, 120))
def test_the_wilson_interval_contains_the_observed_rate_exactly(n):
    for k in {0, 1, n // 2, n - 1, n}:
        if 0 <= k <= n:
            lo, hi = wilson_interval(k, n)
            assert 0.0 <= lo <= k / n <= hi <= 1.0


def test_plots_of_a_campaign_with_no_success_are_drawn(tmp_path):
    from trials.report import plot_parameters

    rows = [{"verdict": "failed", "object_mass_kg": 0.5 + 0.05 * i} for i in range(30)]
    paths = plot_parameters(rows, ["object_mass_kg"], tmp_path, "no success")
    assert [p.name for p in paths] == ["success_vs_object_mass_kg.png"] and paths[0].stat().st_size > 0


def test_redirected_output_has_no_progress_bar_and_no_worker_says_pybullets_build_time(tmp_path, capfd):
    """A campaign whose output goes to a file (here, pytest's): the summary lines only."""
    assert cli.main([str(SHORT), "--trials", "1", "--seed", "3", "--out", str(tmp_path / "o"), "--workers", "1",
                     "--no-plots"]) in (0, 4)
    err = capfd.readouterr().err
    assert "am-trials: 1 trials of" in err
    assert "trial/s" not in err and "succeeded]" not in err and "pybullet build time" not in err, err


@pytest.mark.parametrize("name,rate_hz,substeps,control_every", [
    ("two_am_robust_attitude", 500.0, 2, 2),  # attitude mode: the companions' 250 Hz divides 500 Hz
    ("two_am_comp_attitude", 500.0, 2, 2),
    ("two_am_comp", 1000.0, 1, 1),  # torque mode: the law runs at the physics rate, which stays
])
def test_the_screening_world_keeps_the_contact_step_and_the_companions_rate(name, rate_hz, substeps, control_every):
    """--screening: fewer solver sweeps; in attitude mode half the physics rate in two substeps,
    so that PyBullet's contacts still integrate every millisecond and the companions still run
    at their rate; the emulated autopilot at most at the new rate."""
    path = ROOT / "configs" / "scenarios" / f"{name}.toml"
    spec = load_scenario(path)
    screened = scenario_from_dict(cli.apply_overrides(read_scenario(path), cli.screening_overrides(spec)), path)
    assert screened.solver_iterations == cli.SCREENING_SWEEPS < spec.solver_iterations == 50
    assert (screened.rate_hz, screened.physics_substeps, screened.control_every) == (rate_hz, substeps, control_every)
    assert screened.dt_s / screened.physics_substeps == spec.dt_s
    assert screened.control_dt_s == spec.control_dt_s
    assert screened.vehicle.flight_controller.rate_hz == min(spec.vehicle.flight_controller.rate_hz, rate_hz)


@pytest.mark.parametrize("delay,rate_hz,screened_delay", [(2, 500.0, 1), (1, 1000.0, 1)])
def test_the_screening_world_keeps_an_actuation_delay_in_time(delay, rate_hz, screened_delay):
    """[flight_controller].actuation_delay_steps counts physics steps: two steps at 1 kHz are
    one at 500 Hz; one step has no half, so the world keeps its rate (the sweeps still change)."""
    path = ROOT / "configs" / "scenarios" / "two_am_robust_attitude.toml"
    data = cli.apply_overrides(read_scenario(path), [f"flight_controller.actuation_delay_steps={delay}"])
    spec = scenario_from_dict(data, path)
    screened = scenario_from_dict(cli.apply_overrides(data, cli.screening_overrides(spec)), path)
    assert (screened.rate_hz, screened.vehicle.flight_controller.actuation_delay_steps) == (rate_hz, screened_delay)
    assert screened_delay * screened.dt_s == pytest.approx(delay * spec.dt_s)  # the same delay in time
    assert screened.solver_iterations == cli.SCREENING_SWEEPS


def test_a_screening_campaign_records_its_world_and_set_applies_after_it(tmp_path, capsys):
    out = tmp_path / "o"
    assert cli.main([str(SHORT), "--trials", "1", "--seed", "3", "--out", str(out), "--workers", "1",
                     "--no-progress", "--no-plots", "--screening", "--set", "scenario.duration_s=1.0",
                     "--set", "scenario.solver_iterations=30"]) == 0
    assert "screening world: --set scenario.solver_iterations=25" in capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["overrides"] == ["scenario.solver_iterations=25", "scenario.duration_s=1.0",
                                    "scenario.solver_iterations=30"]
    trial = load_scenario(out / "scenarios" / "trial-0000.toml")
    assert (trial.solver_iterations, trial.duration_s, trial.rate_hz) == (30, 1.0, 1000.0)
