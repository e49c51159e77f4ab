"""The speed issue's six targets (issue 26), measured one after another in one invocation.

    python -m benchmarks.bench_targets [--rounds 1] [--duration 3] [--trials 8] [--iters 3000]

Each figure comes from the benchmark that docs/benchmarks.md cites for it, called here as a
function, each measurement alone on the machine (one after another, never side by side):
- ten AMs and two AMs in attitude mode: `bench_sitl` (am-run of `--duration` simulated seconds
  of the approach, telemetry on; ten_am_robust_attitude's hexarotor and law options, the
  default randomization's devices and the estimator on), as `python -m benchmarks.bench_sitl
  --n 2 10 --attitude --robust --devices --sitl-only`;
- two AMs in torque mode at 1 kHz: `bench_sitl` on its torque-mode scenario (the paper's law,
  no devices), as `python -m benchmarks.bench_sitl --n 2 --sitl-only`;
- the simulator's lockstep work per AM and physics step: `bench_core.run` with two AMs and the
  devices on, in attitude mode and in torque mode, as `python -m benchmarks.bench_core --n 2 --devices`;
- campaign throughput: `bench_trials.throughput`, `--trials` draws of the default
  randomization (seed 1) of two_am_robust_attitude on two workers, flown trials a minute, as
  `python -m benchmarks.bench_trials --scenario configs/scenarios/two_am_robust_attitude.toml
  --trials 8 --workers 2`;
- the controller step, pinocchio's terms included: `bench_controller.main` (median), as
  `python -m benchmarks.bench_controller --iters 3000`.

With --rounds R every figure is measured R times, round by round, so that a change in the
machine's load shows as a spread within a row rather than between rows. The table gives each
round's value, their median and whether the median meets the target; beside the SITL rows,
each round's CPU cap (the real-time factor at which the processes' CPU per step fills every
core, `bench_sitl.cpu_cap`). A SITL run whose approach failed its verdict is named under the
table: its speed is that of the failed run. The exit status is 0 whether or not a target is
met (this is a measurement, not a check).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import os
import tempfile
from pathlib import Path

import numpy as np

from amcore.config import read_scenario
from benchmarks import bench_controller, bench_core, bench_sitl, bench_trials
from trials.cli import DEFAULT_RANDOMIZE
from trials.randomize import load_randomize

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGN = ROOT / "configs" / "scenarios" / "two_am_robust_attitude.toml"

# (key, figure, target, unit, the target is an upper bound)
TARGETS = (
    ("sitl_attitude_10", "ten AMs, attitude mode, devices and estimator on [x real time]", 1.0, "x", False),
    ("sitl_attitude_2", "two AMs, attitude mode, devices and estimator on [x real time]", 4.0, "x", False),
    ("sitl_torque_2", "two AMs, torque mode at 1 kHz [x real time]", 2.0, "x", False),
    ("lockstep_attitude", "simulator's lockstep work per AM and physics step, attitude mode [us]", 15.0, "us", True),
    ("lockstep_torque", "simulator's lockstep work per AM and physics step, torque mode [us]", 15.0, "us", True),
    ("campaign", "campaign, flown trials a minute, two workers", 20.0, "/min", False),
    ("controller", "controller step, pinocchio's terms included [us]", 20.0, "us", True),
)


def sitl(n: int, attitude: bool, duration: float, folder: Path) -> dict:
    """One am-run of the approach with n AMs as bench_sitl runs it: x real time, CPU cap, verdict."""
    folder.mkdir(parents=True)
    path = bench_sitl.scenario_with(n, folder, bench_sitl.base_scenario(attitude, robust=attitude), devices=attitude)
    rtf, _wall, proc = bench_sitl.sitl_rtf(path, duration, folder / "run")
    failed = proc["verdict"].get("status") == "failed"
    return {"value": rtf, "cap": bench_sitl.run_cap(path, proc, n), "failed": proc["verdict"].get("text", "mission FAILED") if failed else None}


def one_round(a, folder: Path) -> dict[str, dict]:
    """Every figure once, in the order of TARGETS."""
    out = {}
    for key, n, attitude in (("sitl_attitude_10", 10, True), ("sitl_attitude_2", 2, True), ("sitl_torque_2", 2, False)):
        out[key] = sitl(n, attitude, a.duration, folder / key)
    for mode in ("attitude", "torque"):
        out[f"lockstep_{mode}"] = {"value": bench_core.run(mode, 2, 2.0, True)["lockstep work"]}
    r = bench_trials.throughput(read_scenario(CAMPAIGN), CAMPAIGN, load_randomize(DEFAULT_RANDOMIZE), a.trials, 2)
    out["campaign"] = {"value": r["flown_per_min"], "cpu_per_flown_s": r["cpu_per_flown_s"]}
    with contextlib.redirect_stdout(io.StringIO()):  # its own table is not this one's
        out["controller"] = {"value": bench_controller.main(["--iters", str(a.iters)])["step"]}
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=1, help="measure every figure this many times, round by round")
    ap.add_argument("--duration", type=float, default=3.0, help="simulated seconds of each SITL run")
    ap.add_argument("--trials", type=int, default=8, help="the campaign's trials")
    ap.add_argument("--iters", type=int, default=3000, help="bench_controller.py's --iters")
    a = ap.parse_args(argv)
    if a.rounds < 1 or a.duration <= 0 or a.trials < 1 or a.iters < 100:
        ap.error("--rounds and --trials must be >= 1, --duration > 0 and --iters >= 100")
    rounds = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(a.rounds):
            load = os.getloadavg()[0]
            rounds.append(one_round(a, Path(tmp) / f"round{r}"))
            print(f"round {r + 1} of {a.rounds} measured (load average before it {load:.2f})", flush=True)
    print(f"{os.cpu_count()} cores; SITL runs of {a.duration:g} simulated s; campaign of {a.trials} trials")
    heads = " ".join(f"{'round ' + str(r + 1):>9}" for r in range(a.rounds))
    print(f"{'figure':<74} {'target':>9} {heads} {'median':>9}  met")
    for key, figure, target, unit, upper in TARGETS:
        values = [rd[key]["value"] for rd in rounds]
        med = float(np.median(values))
        met = med <= target if upper else med >= target
        bound = f"{'<=' if upper else '>='} {target:g}{unit}"
        print(f"{figure:<74} {bound:>9} " + " ".join(f"{v:9.2f}" for v in values) + f" {med:9.2f}  "
              + ("yes" if met else "no"))
        if "cap" in rounds[0][key]:
            print(f"{'  CPU cap [x real time]':<74} {'':>9} " + " ".join(f"{rd[key]['cap']:9.2f}" for rd in rounds))
        if key == "campaign":
            label = "  the workers' CPU per flown trial [s]"
            print(f"{label:<74} {'':>9} "
                  + " ".join(f"{rd[key]['cpu_per_flown_s']:9.2f}" for rd in rounds))
    for r, rd in enumerate(rounds):
        for key, figure, *_ in TARGETS:
            if rd[key].get("failed"):
                print(f"round {r + 1}, {figure}: the SITL run's {rd[key]['failed']}")


if __name__ == "__main__":
    main()
