"""Benchmark of one full controller step (model terms included): median and p95, and where
the time goes. Targets (issue 2): median <= 150 us on the project's 2-core machines, goal 60 us.

    python benchmarks/bench_controller.py [--iters 3000]

The step is fed back its own memory every call, as the companion does at 1 kHz. Where the
time goes is measured inside the step (its calls to decoupled_terms and task_terms are
timed in place, the control laws are the remainder: eqs. Com_controller, Rd, ori_controller,
u3, the wrench filter and the result objects), and also for the model and task terms
called on their own in a tight loop, where caches stay warm. The rows are timed in
interleaved rounds so that a change in machine load hits all of them alike.
The companion calls, every step besides, mission.reference and the wire conversions of
companion/adapter.py (state_from_frame, setpoint_from_result); each has its own line, and
the last line times the companion's whole step from a sensor frame to its setpoint (the
state then carries the frame's quaternion, AmState.quat_xyzw).
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from amcore.config import load_scenario
from amcore import control
from amcore.control import ControllerMemory, ControllerParams, step
from amcore.mission import am_mission
from amcore.model import AmState, build_model, create_data, decoupled_terms
from amcore.so3 import R_to_quat_wxyz, exp_so3
from amcore.task import task_terms
from amlink.types import SensorFrame
from companion.adapter import setpoint_from_result, state_from_frame

ROOT = Path(__file__).resolve().parents[1]


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
    # the same states as sensor frames (the wire carries the quaternion as float32)
    frames = [SensorFrame(step=k, time_s=0.0, p_WB=s.p_WB, quat_WB_wxyz=R_to_quat_wxyz(s.R_WB).astype(np.float32),
                          v_B=s.v_B, w_B=s.w_B, q=s.q, qdot=s.qdot, wrench_E=F) for k, s in enumerate(sts)]
    thrust_max = spec.vehicle.rotors.thrust_max_n * spec.vehicle.rotors.count
    mem = [ControllerMemory(), ControllerMemory()]
    inside = {"model": [], "task": []}
    clock = time.perf_counter_ns

    def timed(fn, key):
        def wrapper(*args, **kwargs):
            t0 = clock()
            out = fn(*args, **kwargs)
            inside[key].append(clock() - t0)
            return out
        return wrapper

    def run_step(i):
        mem[0] = step(model, data, params, sts[i % 64], refs[i % 64], F, mem[0], 1e-3 * i).memory

    def run_companion(i):  # companion.pilot's per-frame work, without its outcome bookkeeping
        frame, t = frames[i % 64], 0.0067 * i
        res = step(model, data, params, state_from_frame(frame), mission.reference(t), frame.wrench_E, mem[1], t)
        mem[1] = res.memory
        setpoint_from_result(i, res, thrust_max)

    def run_step_split(i):
        control.decoupled_terms, control.task_terms = timed_model, timed_task
        try:
            run_step(i)
        finally:
            control.decoupled_terms, control.task_terms = decoupled_terms, task_terms

    timed_model, timed_task = timed(decoupled_terms, "model"), timed(task_terms, "task")
    tm = decoupled_terms(model, data, sts[0])
    res0 = step(model, data, params, sts[0], refs[0], F, ControllerMemory(), 0.0)
    parts = {
        "step": run_step,
        "step, split": run_step_split,
        "model": lambda i: decoupled_terms(model, data, sts[i % 64]),
        "task": lambda i: task_terms(model, data, tm, params.task_frame, params.components),
        "reference": lambda i: mission.reference(0.0067 * i),
        "state_from_frame": lambda i: state_from_frame(frames[i % 64]),
        "setpoint_from_result": lambda i: setpoint_from_result(i, res0, thrust_max),
        "companion": run_companion,
    }
    for i in range(300):
        for fn in parts.values():
            fn(i)
    samples = {name: [] for name in parts}
    inside["model"].clear()
    inside["task"].clear()
    load_before = os.getloadavg()
    for r in range(max(1, a.iters // 100)):
        for name, fn in parts.items():
            ts = samples[name]
            for i in range(r * 100, r * 100 + 100):
                t0 = clock()
                fn(i)
                ts.append(clock() - t0)
    load_after = os.getloadavg()

    def row(name, ts):
        print(f"{name:<58} {np.median(ts) / 1e3:12.1f} {np.percentile(ts, 95) / 1e3:10.1f}")

    split = np.array(samples["step, split"])
    laws = split - np.array(inside["model"]) - np.array(inside["task"])
    print(f"{'what':<58} {'median [us]':>12} {'p95 [us]':>10}")
    row("full controller step", samples["step"])
    print("  inside the step:")
    row("    decoupled_terms (pinocchio + T, T^-1, Tdot V, Lambda_w)", inside["model"])
    row("    task_terms (y, J_y, J_e T^-1, Jdot xi)", inside["task"])
    row("    control laws (eqs. Com_controller, Rd, ori_controller, u3)", laws)
    print("  called on their own (warm caches):")
    row("    decoupled_terms", samples["model"])
    row("    task_terms", samples["task"])
    print("  called by the companion every step besides:")
    row("    mission.reference (7th-order paths)", samples["reference"])
    row("    adapter.state_from_frame", samples["state_from_frame"])
    row("    adapter.setpoint_from_result", samples["setpoint_from_result"])
    row("companion step: frame -> state, reference, step, setpoint", samples["companion"])
    med = np.median(samples["step"]) / 1e3
    print(f"load average (1 min) {load_before[0]:.2f} before, {load_after[0]:.2f} after; {os.cpu_count()} CPUs")
    print(f"target: median <= 150 us (goal 60 us): {'met' if med <= 150 else 'NOT met'} at {med:.1f} us")


if __name__ == "__main__":
    main()
