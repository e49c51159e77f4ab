"""The same campaign at two physics rates: what a lower [scenario].rate_hz buys in a campaign's
throughput, and what it changes in the verdicts and the grasp's figures.

    python experiments/physics_rate.py [configs/scenarios/two_am_robust_attitude.toml] --seed S
        [--rates 1000 500] [--substeps 1] [--iterations N] [--screening] [--trials 24] [--workers 2] [--randomize FILE]
        [--out runs/physics_rate-<time>]

For each rate, `am-trials` runs the base scenario with `[scenario].rate_hz` at that rate and
the emulated autopilot's loops (`[flight_controller].rate_hz`) at most as fast, on the same
seed: the drawn variations do not depend on the rate (checked here, column by column). The
companions' control rate stays the scenario's, so the rate must be a multiple of it (attitude
mode's 250 Hz; torque mode's companions run at the physics rate, so there a lower rate slows the law too).
`--substeps 2` runs the second rate with `[scenario].physics_substeps = 2`: PyBullet's contacts
and joints then integrate at twice that rate, with the step's forces held across its substeps.
`--iterations N` runs the second world with `[scenario].solver_iterations = N` (PyBullet's
constraint solver sweeps; `--rates 1000 1000 --iterations 25` compares that alone).
`--screening` runs the second world as `am-trials --screening` does (`trials.cli.screening_overrides`;
the rates, substeps and iterations given are then ignored for it).

Printed: per rate, the campaign's wall time, its flown trials per minute (refused trials cost
the pre-flight check alone) and the flown trials' median wall time; then, trial by trial, how
many verdicts agree, and for the trials flown at both rates the median and largest difference
of each figure of the grasp, with each rate's median beside it. Saturation is compared as a
share of the trial's physics steps, since a lower rate has fewer steps.

This measures a modelling choice, not a speed-up of the same computation: the runs are not
bit-identical across rates, and the digests differ.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

from amcore.config import load_scenario, read_scenario, scenario_from_dict
from trials import cli
from trials.report import read_csv

ROOT = Path(__file__).resolve().parents[1]

FIGURES = ("hover_min_lift_m", "final_lift_m", "max_slip_m", "force_share_error", "peak_com_err_m", "peak_e_R_rad",
           "peak_y_err_x_m")
SATURATION = ("rotor_saturated_steps", "joint_saturated_steps")
NOT_DRAWN = {"trial", "scenario_file", "verdict", "failure_class", "reason", "state_digest", "wall_s", *FIGURES,
             *SATURATION, "saturated_steps", "max_lift_m", "rejected_setpoints"}


def overrides(base: Path, rate_hz: float, substeps: int = 1, iterations: int | None = None) -> list[str]:
    """am-trials' --set arguments for physics at rate_hz in `substeps` substeps of PyBullet, its
    solver sweeping at most `iterations` times a step (None: the scenario's); none where these
    are the scenario's own."""
    spec = load_scenario(base)
    out = [] if substeps == spec.physics_substeps else ["--set", f"scenario.physics_substeps={int(substeps)}"]
    if iterations is not None and iterations != spec.solver_iterations:
        out += ["--set", f"scenario.solver_iterations={int(iterations)}"]
    if rate_hz == spec.rate_hz:
        return out
    fc = min(spec.vehicle.flight_controller.rate_hz, rate_hz)
    return ["--set", f"scenario.rate_hz={float(rate_hz)}", "--set", f"flight_controller.rate_hz={float(fc)}", *out]


def compare(a: list[dict], b: list[dict], steps_a: int, steps_b: int) -> dict:
    """Trial-by-trial comparison of two campaigns on the same draws (rows of trials.csv): the
    verdicts that agree, and per figure (flown at both rates) the differences |b - a| and each
    campaign's median. Saturation as a share of each trial's physics steps (steps_a, steps_b).
    ValueError if the draws differ."""
    if len(a) != len(b):
        raise ValueError(f"{len(a)} trials against {len(b)}")
    for ra, rb in zip(a, b):
        drawn = [k for k in ra if k not in NOT_DRAWN and not k.startswith(("peak_", "hover_"))]
        differ = [k for k in drawn if ra[k] != rb.get(k)]
        if differ:
            raise ValueError(f"trial {ra['trial']}: the draws differ in {', '.join(differ)}")
    both = [(ra, rb) for ra, rb in zip(a, b) if ra["verdict"] not in ("refused", "error")
            and rb["verdict"] not in ("refused", "error")]
    out = {"trials": len(a), "verdicts_agree": sum(ra["verdict"] == rb["verdict"] for ra, rb in zip(a, b)),
           "disagree": [(ra["trial"], ra["verdict"], rb["verdict"]) for ra, rb in zip(a, b)
                        if ra["verdict"] != rb["verdict"]],
           "flown_both": len(both), "figures": {}}
    for key, scale_a, scale_b in [*((k, 1.0, 1.0) for k in FIGURES), *((k, 1.0 / steps_a, 1.0 / steps_b) for k in SATURATION)]:
        pairs = [(scale_a * float(ra[key]), scale_b * float(rb[key])) for ra, rb in both
                 if ra.get(key) not in (None, "") and rb.get(key) not in (None, "")]
        if pairs:
            d = [abs(y - x) for x, y in pairs]
            out["figures"][key] = {"median_a": statistics.median(x for x, _ in pairs),
                                   "median_b": statistics.median(y for _, y in pairs),
                                   "median_diff": statistics.median(d), "max_diff": max(d), "n": len(pairs)}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario", nargs="?", type=Path, default=ROOT / "configs" / "scenarios" / "two_am_robust_attitude.toml")
    ap.add_argument("--seed", type=int, required=True, help="campaign seed (use one no setting was tuned on)")
    ap.add_argument("--rates", type=float, nargs=2, default=[1000.0, 500.0], metavar="HZ")
    ap.add_argument("--substeps", type=int, default=1, choices=(1, 2),
                    help="[scenario].physics_substeps of the second rate (default 1)")
    ap.add_argument("--iterations", type=int, default=None,
                    help="[scenario].solver_iterations of the second world (default: the scenario's)")
    ap.add_argument("--screening", action="store_true", help="the second world is am-trials' screening world")
    ap.add_argument("--trials", type=int, default=24)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--randomize", type=Path, default=None, help="am-trials' --randomize (default: its default)")
    ap.add_argument("--out", type=Path, default=None)
    a = ap.parse_args(argv)
    out = a.out or ROOT / "runs" / f"physics_rate-{time.strftime('%Y%m%d-%H%M%S')}"
    campaigns = []
    base = load_scenario(a.scenario)
    if a.screening:
        screened = scenario_from_dict(cli.apply_overrides(read_scenario(a.scenario), cli.screening_for(a.scenario)),
                                      a.scenario)
        a.rates = [a.rates[0], screened.rate_hz]  # a new list: argparse's default is shared
        a.substeps, a.iterations = screened.physics_substeps, screened.solver_iterations
    for i, rate in enumerate(a.rates):
        sub = a.substeps if i == 1 else 1
        its = a.iterations if i == 1 else None
        folder = out / (f"{'ab'[i]}-rate-{rate:g}" + (f"-substeps-{sub}" if sub > 1 else "")
                        + (f"-iterations-{its}" if its is not None else ""))
        code = cli.main([str(a.scenario), "--trials", str(a.trials), "--seed", str(a.seed), "--out", str(folder),
                         "--workers", str(a.workers), "--no-progress", "--no-plots",
                         *(["--screening"] if a.screening and i == 1 else overrides(a.scenario, rate, sub, its)),
                         *(["--randomize", str(a.randomize)] if a.randomize else [])])
        if code != 0:  # am-trials said why on stderr
            return code
        campaigns.append((rate, json.loads((folder / "summary.json").read_text()), read_csv(folder / "trials.csv")))
    duration = base.duration_s
    print(f"{a.scenario.name}, seed {a.seed}, {a.trials} trials, {a.workers} workers, randomization "
          f"{a.randomize or 'default'}; in {out}" + (f"; the second rate in {a.substeps} substeps" if a.substeps > 1 else "")
          + (f"; the second world's solver at most {a.iterations} sweeps" if a.iterations is not None else "")
          + ("; the second world is am-trials' --screening" if a.screening else ""))
    print(f"{'physics [Hz]':>12} {'wall [s]':>9} {'flown':>6} {'flown/min':>10} {'flown trial, median wall [s]':>29}")
    for rate, s, rows in campaigns:
        walls = [float(r["wall_s"]) for r in rows if r["verdict"] != "refused"]
        print(f"{rate:12g} {s['wall_s']:9.1f} {s['flown']:6d} {s['flown_per_minute']:10.1f} "
              f"{statistics.median(walls) if walls else float('nan'):29.2f}")
    (ra, _, a_rows), (rb, _, b_rows) = campaigns
    c = compare(a_rows, b_rows, int(round(duration * ra)), int(round(duration * rb)))
    print(f"verdicts: {c['verdicts_agree']} of {c['trials']} agree" + (f"; differ: {c['disagree']}" if c["disagree"] else ""))
    print(f"the {c['flown_both']} trials flown at both rates (saturation as a share of the physics steps):")
    print(f"{'figure':>24} {f'median at {ra:g} Hz':>18} {f'median at {rb:g} Hz':>18} {'median |diff|':>14} {'max |diff|':>11}")
    for key, f in c["figures"].items():
        print(f"{key:>24} {f['median_a']:18.4g} {f['median_b']:18.4g} {f['median_diff']:14.3g} {f['max_diff']:11.3g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
