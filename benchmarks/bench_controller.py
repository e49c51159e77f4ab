"""Benchmark of one full controller step (model terms included): median and p95, and where
the time goes. Targets (issue 2): median <= 150 us on the project's 2-core machines, goal 60 us.

    python benchmarks/bench_controller.py [--iters 3000]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from amcore.config import load_scenario
from amcore.control import ControllerMemory, ControllerParams, step
from amcore.mission import am_mission
from amcore.model import AmState, build_model, create_data, decoupled_terms
from amcore.so3 import exp_so3
from amcore.task import task_terms

ROOT = Path(__file__).resolve().parents[1]


def _time(fn, iters):
    ts = np.empty(iters)
    for i in range(iters):
        t0 = time.perf_counter_ns()
        fn(i)
        ts[i] = time.perf_counter_ns() - t0
    return np.median(ts) / 1e3, np.percentile(ts, 95) / 1e3


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=3000)
    a = ap.parse_args()
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    model = build_model(spec.vehicle)
    mission = am_mission(spec, spec.ams[0], model)
    params = ControllerParams.from_vehicle(spec.vehicle, mission.frame)
    data = create_data(model)
    rng = np.random.default_rng(0)
    x = mission.initial_state()
    sts = [AmState(x.p_WB + 0.01 * rng.normal(size=3), x.R_WB @ exp_so3(0.05 * rng.normal(size=3)),
                   0.1 * rng.normal(size=3), 0.1 * rng.normal(size=3), x.q + 0.05 * rng.normal(size=3),
                   0.1 * rng.normal(size=3)) for _ in range(64)]
    refs = [mission.reference(t) for t in np.linspace(0, 20, 64)]
    F = rng.normal(size=6)
    mem = ControllerMemory()
    for i in range(200):
        step(model, data, params, sts[i % 64], refs[i % 64], F, mem, 0.0)
    rows = []
    med, p95 = _time(lambda i: step(model, data, params, sts[i % 64], refs[i % 64], F, mem, 1e-3 * i), a.iters)
    rows.append(("full controller step", med, p95))
    rows.append(("  decoupled_terms (pinocchio + T, Tdot V, Lambda_xi)",
                 *_time(lambda i: decoupled_terms(model, data, sts[i % 64]), a.iters)))
    tm = decoupled_terms(model, data, sts[0])
    rows.append(("  task_terms (y, J, Jdot xi)",
                 *_time(lambda i: task_terms(model, data, tm, params.task_frame, params.components), a.iters)))
    rows.append(("  mission.reference (7th-order paths)", *_time(lambda i: mission.reference(0.01 * i), a.iters)))
    print(f"{'what':<55} {'median [us]':>12} {'p95 [us]':>10}")
    for name, m, p in rows:
        print(f"{name:<55} {m:12.1f} {p:10.1f}")
    rest = rows[0][1] - rows[1][1] - rows[2][1]
    print(f"{'  control laws (eqs. Com_controller, Rd, ori_controller, u3)':<55} {rest:12.1f} {'(by difference)':>10}")
    print(f"target: median <= 150 us (goal 60 us): {'met' if med <= 150 else 'NOT met'} at {med:.1f} us")


if __name__ == "__main__":
    main()
