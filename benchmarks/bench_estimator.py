"""Benchmark of the flight controller's estimator (amcore.estimator) and of one AM's devices
(simulator.devices): median and p95 per physics step.

    python -m benchmarks.bench_estimator [--iters 20000]

Target (issue 23): the estimator compiled like the law, at most 10 us per AM step. Rows:
the compiled kernel alone (`estimator_step`, with and without a motion-capture pose that
step), the `Estimator.step` wrapper as the simulator calls it, and the whole
`DeviceSuite.step` (IMU, motion capture, F/T, encoders and the estimator, from the world's
values to the frame's), which is the simulator's added cost per AM step with [devices] on.
Rows are timed in interleaved rounds so that a change in machine load hits them alike.
"""
from __future__ import annotations

import argparse
import time
import tomllib
from pathlib import Path

import numpy as np

from amcore.config import devices_from_table
from amcore.estimator import Estimator, estimator_step
from simulator.devices import DeviceSuite

ROOT = Path(__file__).resolve().parents[1]

DT, G = 0.001, 9.81
VALUES = [0.1, 0.2, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, -1.0, 0.3, 0.0, 0.0, 0.0,
          0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


def _time(fn, n: int) -> list[float]:
    out = []
    for _ in range(n):
        t0 = time.perf_counter_ns()
        fn()
        out.append((time.perf_counter_ns() - t0) / 1e3)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=20000)
    a = ap.parse_args()
    with open(ROOT / "configs" / "randomize" / "default.toml", "rb") as fh:
        table = tomllib.load(fh)["randomize"]["devices"]
    spec = devices_from_table(table, "default.toml")
    e = spec.estimator
    est = Estimator(np.array(VALUES[0:3]), np.array(VALUES[3:7]), DT, 0.01, G, e.attitude_bandwidth_radps,
                    e.position_bandwidth_radps, e.gyro_cutoff_hz, e.history_steps)
    omega, f = np.array([0.01, -0.02, 0.03]), np.array([0.0, 0.1, G])
    pose = (np.array(VALUES[0:3]), np.array(VALUES[3:7]))
    suite = DeviceSuite(spec, 3, DT, G, 0, 4, VALUES)
    k = [0]

    def kernel_no_pose():
        k[0] += 1
        estimator_step(est.x, est.hist, est.lpf, est.coef, k[0], omega, f, DT, G, False, 0, pose[0], pose[1],
                       est.gains, est.out)

    def kernel_pose():
        k[0] += 1
        estimator_step(est.x, est.hist, est.lpf, est.coef, k[0], omega, f, DT, G, True, 10, pose[0], pose[1],
                       est.gains, est.out)

    def wrapper():
        k[0] += 1
        est.step(k[0], omega, f, pose if k[0] % 10 == 0 else None, 10)

    t = [0.0]

    def devices():
        t[0] += DT
        suite.step(VALUES, t[0])

    rows = {"estimator_step kernel, no pose": kernel_no_pose, "estimator_step kernel, with a pose": kernel_pose,
            "Estimator.step (1 pose in 10)": wrapper, "DeviceSuite.step (devices + estimator)": devices}
    for fn in rows.values():  # compile and warm up
        for _ in range(200):
            fn()
    times = {name: [] for name in rows}
    rounds = 20
    for _ in range(rounds):
        for name, fn in rows.items():
            times[name] += _time(fn, a.iters // rounds)
    print(f"{'row':42s} {'median us':>10s} {'p95 us':>8s}")
    for name, ts in times.items():
        print(f"{name:42s} {np.median(ts):10.2f} {np.percentile(ts, 95):8.2f}")


if __name__ == "__main__":
    main()
