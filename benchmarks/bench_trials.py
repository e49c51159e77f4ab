"""Trial campaign throughput: trials per minute of `am-trials` on this machine, for a local
pool of 1 and of 2 worker processes, on the same trials (default randomization).

    python -m benchmarks.bench_trials [--scenario configs/scenarios/two_am_comp.toml] [--trials 4]
        [--set TABLE.KEY=VALUE ...] [--screening]

Each row runs the same `--trials` trials (seed 1) through `trials.runner` and prints wall
time, trials per minute, the trials flown and flown per minute (a scenario with
`envelope_check` refuses some draws before flight, at the cost of the check alone), and
simulated seconds per wall second per worker. Worker start-up (spawning, importing pinocchio
and PyBullet) is inside the wall time, as in a campaign. It also prints the workers' CPU time
per flown trial (user + system of the pool's processes, start-up included) and the flown
trials per minute that CPU time allows with each worker on a core of its own (workers x 60 s
/ CPU per flown trial): on a machine shared with other work the wall-clock figure falls with
the load, this one does not (it is a bound, reached when the workers have their cores to
themselves). `--set` changes the scenario as am-trials' --set does, e.g. `--set
scenario.solver_iterations=25`; `--screening` applies am-trials' screening world
(`trials.cli.screening_for`, docs/trials.md) before them.
"""
from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

from amcore.config import read_scenario, scenario_from_dict
from trials.cli import DEFAULT_RANDOMIZE, apply_overrides, build_tasks, screening_for
from trials.randomize import load_randomize
from trials.runner import executor, run_all

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", type=Path, default=ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    ap.add_argument("--trials", type=int, default=4)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE", dest="overrides",
                    help="change a key of the scenario, as am-trials --set")
    ap.add_argument("--screening", action="store_true", help="am-trials' screening world")
    a = ap.parse_args()
    if a.screening:
        a.overrides = [*screening_for(a.scenario.resolve(), a.overrides), *a.overrides]
    data = apply_overrides(read_scenario(a.scenario), a.overrides)
    spec = scenario_from_dict(data, a.scenario.resolve())
    rand = load_randomize(DEFAULT_RANDOMIZE)
    print(f"{a.trials} trials of {a.scenario.name} ({spec.duration_s:g} s simulated each), default randomization"
          + (f"; {' '.join(a.overrides)}" if a.overrides else ""))
    print(f"load average before: {os.getloadavg()[0]:.2f}; {os.cpu_count()} cores")
    print(f"{'workers':>8} {'wall [s]':>9} {'trials/min':>11} {'flown':>6} {'flown/min':>10} "
          f"{'sim s per wall s per worker':>28} {'CPU per flown trial [s]':>24} {'flown/min, a core each':>23}")
    digests = None
    for w in a.workers:
        r = throughput(data, a.scenario.resolve(), rand, a.trials, w)
        assert digests is None or r["digests"] == digests, "the same trials gave other digests"
        digests = r["digests"]
        print(f"{w:>8} {r['wall_s']:9.1f} {r['trials_per_min']:11.2f} {r['flown']:6d} {r['flown_per_min']:10.2f} "
              f"{r['flown'] * spec.duration_s / r['wall_s'] / w:28.2f} {r['cpu_per_flown_s']:24.1f} "
              f"{w * 60.0 / r['cpu_per_flown_s']:23.2f}")


def throughput(data: dict, scenario: Path, rand, trials: int, workers: int, seed: int = 1) -> dict:
    """One campaign of `trials` draws of `rand` (campaign seed `seed`) on a local pool of
    `workers` processes: wall time, trials and flown trials per minute, the workers' CPU per
    flown trial (start-up included) and the trials' digests."""
    with tempfile.TemporaryDirectory() as tmp:
        tasks = build_tasks(data, scenario, rand, seed, trials, Path(tmp), None)
        t0, c0 = time.perf_counter(), _children_cpu_s()
        with executor(workers) as ex:
            rows = run_all(tasks, ex)
        wall, cpu = time.perf_counter() - t0, _children_cpu_s() - c0
    flown = sum(r["verdict"] != "refused" for r in rows)  # a refused trial costs the pre-flight check alone
    return {"wall_s": wall, "trials_per_min": 60.0 * len(rows) / wall, "flown": flown,
            "flown_per_min": 60.0 * flown / wall, "cpu_per_flown_s": cpu / flown if flown else float("nan"),
            "digests": [r["state_digest"] for r in rows]}


def _children_cpu_s() -> float:
    """User + system CPU time of this process's ended children (the pool's workers) [s]."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


if __name__ == "__main__":
    main()
