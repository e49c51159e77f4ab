"""am-trials --realtime: each trial flown free-running by `am-run --realtime` (trials/freerun.py),
its verdict read from its own outcome.json and its timing in its row; what it cannot take
(a pool, a cluster, the screening world, a torque-mode scenario) exits 2 before anything is
written."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from trials import cli, freerun

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "configs" / "scenarios"


def _args(scenario: Path, out: Path, *more: str) -> list[str]:
    return [str(scenario), "--trials", "1", "--seed", "5", "--out", str(out), "--no-progress", "--no-plots", *more]


@pytest.mark.parametrize("scenario,more,words", [
    ("two_am_comp_attitude.toml", ["--realtime", "--workers", "2"], "--workers is not for --realtime"),
    ("two_am_comp_attitude.toml", ["--speed", "0.5", "--scheduler", "tcp://127.0.0.1:8786"],
     "--scheduler is not for --realtime"),
    ("two_am_comp_attitude.toml", ["--realtime", "--screening"], "--screening is not for --realtime"),
    ("two_am_comp_attitude.toml", ["--instance", "3"], "--instance is for --realtime"),
    ("two_am_short.toml", ["--realtime"], 'it needs [flight_controller].mode = "attitude"'),
])  # fmt: skip
def test_what_a_free_running_campaign_cannot_take_exits_2_naming_it(tmp_path, capsys, scenario, more, words):
    out = tmp_path / "o"
    assert cli.main(_args(SCENARIOS / scenario, out, *more)) == 2
    [line] = capsys.readouterr().err.strip().splitlines()  # one line, no traceback
    assert line.startswith("am-trials: error: ") and words in line
    assert not out.exists()


@pytest.mark.parametrize("speed", ["0", "-1", "nan", "11", "x"])
def test_a_speed_that_is_no_real_time_factor_exits_2(tmp_path, capsys, speed):
    with pytest.raises(SystemExit) as exc:
        cli.main(_args(SCENARIOS / "two_am_comp_attitude.toml", tmp_path / "o", "--speed", speed))
    assert exc.value.code == 2 and "--speed" in capsys.readouterr().err


def test_the_timing_figures_are_the_worst_companion_s(tmp_path):
    for s, (p99, mx, misses, lat) in {4: (9.0, 30.0, 12, 15.0), 5: (11.0, 20.0, 3, 18.0)}.items():
        (tmp_path / f"am{s}.json").write_text(json.dumps({"loop": {
            "period_ms": {"p50": 4.0, "p99": p99, "max": mx}, "deadline_misses": misses,
            "sample_to_setpoint_ms": {"p50": 5.0, "p99": lat}}}))
    row = freerun.timing_figures({"real_time_factor": 0.48, "timing": {"steps": 1000, "deadline_misses": 250}},
                                 tmp_path, [4, 5])
    assert row == {"real_time_factor": 0.48, "physics_miss_share": 0.25, "companion_period_p99_ms": 11.0,
                   "companion_period_max_ms": 30.0, "companion_deadline_misses": 12, "sample_to_setpoint_p99_ms": 18.0}
    rows = [{**row, "real_time_factor": f} for f in (0.3, 0.5, 0.45)] + [{"verdict": "refused"}]
    t = freerun.timing_summary(rows)
    assert (t["real_time_factor_median"], t["real_time_factor_min"], t["companion_deadline_misses_max"]) == (0.45, 0.3, 12)


@pytest.mark.sitl
def test_a_free_running_trial_flies_through_am_run_and_its_row_is_its_outcome(tmp_path):
    """One trial of the 10 % setpoint-loss draws, its mission cut to 1 s: it flies through the
    whole free-running stack, its onboard port loses about a tenth of what the companion sends,
    and its row carries its outcome's verdict and the run's timing."""
    out = tmp_path / "c"
    args = _args(SCENARIOS / "two_am_comp_attitude.toml", out, "--realtime", "--instance", "100", "--randomize",
                 str(ROOT / "configs" / "randomize" / "setpoint_loss.toml"), "--set", "scenario.duration_s=1.0")
    assert cli.main(args) == 0
    [row] = list(csv.DictReader(open(out / "trials.csv")))
    run = Path(row["run_dir"])
    o = json.loads((run / "outcome.json").read_text())
    assert o["mode"] == "free-running" and row["verdict"] == o["verdict"]["status"] == "incomplete"
    assert 0.1 < float(row["real_time_factor"]) <= 0.55 and float(row["companion_period_p99_ms"]) > 0.0
    for v in o["vehicles"].values():
        imp = v["impairment"]
        assert imp["sent"] > 1000 and 0.05 < imp["lost"] / imp["sent"] < 0.15
    summary = json.loads((out / "summary.json").read_text())
    assert summary["timing"]["real_time_factor_min"] == pytest.approx(float(row["real_time_factor"]))


def _outcome(status: str, failure_class: str | None) -> dict:
    am = {"hover_mean_ft_force_W_n": [0.0, 0.0, -5.9], "slip_max_m": 1e-4, "saturated_steps": 3}
    return {"verdict": {"status": status, "failure_class": failure_class, "text": f"mission {status}"},
            "object": {"hover_min_lift_m": 0.28, "max_lift_m": 0.284, "final_lift_m": 0.283},
            "ams": {"4": am, "5": am}, "real_time_factor": 0.49, "timing": {"steps": 100, "deadline_misses": 7}}


@pytest.mark.parametrize("rc,status,cls,verdict", [
    (0, "success", None, "success"),
    (4, "failed", "base contact", "failed"),
    (1, "failed", "failover", "failed"),  # a companion that handed its vehicle back exits 1: still a verdict
    (1, "success", None, "error"),  # a process failed under a flight that succeeded
    (1, "incomplete", None, "error"),  # cut short: a process did not start
    (0, "incomplete", None, "incomplete"),  # a mission shorter than its hover window
    (None, "success", None, "error"),  # past its time limit
    (1, None, None, "error"),  # no outcome at all
])  # fmt: skip
def test_a_flown_trial_s_row_is_its_verdict_unless_the_stack_failed(tmp_path, rc, status, cls, verdict):
    from amcore.config import load_scenario

    spec = load_scenario(SCENARIOS / "two_am_comp_attitude.toml")
    run, log = tmp_path / "trial-0000", tmp_path / "trial-0000.log"
    run.mkdir()
    log.write_text("am-run: starting\nam-run: FAILED: companion 5\n")
    if status is not None:
        (run / "outcome.json").write_text(json.dumps(_outcome(status, cls)))
    row = freerun.judged({"trial": 0}, rc, run, log, spec, 240.0)
    assert row["verdict"] == verdict and row["exit_code"] == rc
    if verdict == "error":
        assert "FAILED: companion 5" in row["reason"] and str(log) in row["reason"]
        assert ("timed out after 240 s" if rc is None else f"am-run exited {rc}") in row["reason"]
    else:
        assert row["failure_class"] == (cls or "") and row["physics_miss_share"] == 0.07
