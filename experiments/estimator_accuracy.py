"""The estimator's accuracy against ground truth in closed loop: a scenario run in-process with
the default device levels ([randomize.devices] of configs/randomize/default.toml, the scenario's
own [devices] keys on top), every control step's odometry frame compared with the truth.

    python experiments/estimator_accuracy.py [SCENARIO] [--duration S] [--seeds 1 2 ...]
                                             [--set devices.KEY=VALUE ...]

Prints, per state, the RMS and the 99th percentile of the error over all AMs and steps after
the first second (the filter's start-up): position [mm] and velocity [mm/s] per world axis,
attitude as tilt (roll/pitch) and yaw [mrad], body rate per body axis [rad/s]. Attitude
errors are the rotation vector of R_true^T R_est, split into its body-z part (yaw) and the
rest (tilt); they include the motion capture's fixed attitude bias, which no estimator can
see.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from amcore.config import read_scenario, scenario_from_dict
from amcore.quat_kernels import quat_log, quat_mul, rotation
from trials.cli import apply_overrides
from trials.randomize import _merged, load_randomize

ROOT = Path(__file__).resolve().parents[1]

STATES = ("p_x mm", "p_y mm", "p_z mm", "tilt mrad", "yaw mrad", "v_x mm/s", "v_y mm/s", "v_z mm/s",
          "w_x rad/s", "w_y rad/s", "w_z rad/s")
SCALE = np.array([1e3, 1e3, 1e3, 1e3, 1e3, 1e3, 1e3, 1e3, 1.0, 1.0, 1.0])


def frame_errors(exact: list[float], f) -> np.ndarray:
    """One frame's errors in STATES order (SI units): estimate minus truth."""
    p, q = np.array(exact[0:3]), np.array(exact[3:7])
    d = quat_log(quat_mul(np.array([q[0], -q[1], -q[2], -q[3]]), np.asarray(f.quat_WB_wxyz, dtype=float)))
    tilt = float(np.hypot(d[0], d[1]))
    R, R_est = rotation(q), rotation(np.asarray(f.quat_WB_wxyz, dtype=float))
    v_err = R_est @ np.asarray(f.v_B) - R @ np.array(exact[7:10])
    return np.concatenate([np.asarray(f.p_WB) - p, [tilt, d[2]], v_err, np.asarray(f.w_B) - np.array(exact[10:13])])


def measure(data: dict, path: Path, duration_s: float, settle_s: float = 1.0) -> np.ndarray:
    """(steps x AMs, len(STATES)) errors of one run of scenario data `data`."""
    from sitl.inprocess import run
    rows: list[np.ndarray] = []

    def on_frames(t, exact, frames):
        if t >= settle_s:
            rows.extend(frame_errors(exact[s], f) for s, f in frames.items())

    run(scenario_from_dict(data, path), duration_s, on_frames=on_frames)
    return np.array(rows)


def with_default_devices(base: dict) -> dict:
    levels = load_randomize(ROOT / "configs" / "randomize" / "default.toml").devices
    out = dict(base)
    out["devices"] = _merged(levels, base.get("devices", {}))
    return out


def summary(err: np.ndarray) -> list[tuple[str, float, float]]:
    a = np.abs(err) * SCALE
    return [(name, float(np.sqrt((a[:, i] ** 2).mean())), float(np.percentile(a[:, i], 99)))
            for i, name in enumerate(STATES)]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario", nargs="?", default=str(ROOT / "configs" / "scenarios" / "two_am_comp.toml"))
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--seeds", type=int, nargs="*", default=None, help="[scenario].seed of each run")
    ap.add_argument("--set", action="append", default=[], dest="overrides")
    a = ap.parse_args()
    path = Path(a.scenario).resolve()
    base = with_default_devices(apply_overrides(read_scenario(path), a.overrides))
    errs = []
    for seed in a.seeds or [base.get("scenario", {}).get("seed", 0)]:
        data = apply_overrides(base, [f"scenario.seed={seed}"])
        errs.append(measure(data, path, a.duration))
    err = np.concatenate(errs)
    print(f"{len(err)} frames ({len(errs)} runs of {a.duration:g} s, all AMs, after the first second)")
    print(f"{'state':12s} {'RMS':>9s} {'p99':>9s}")
    for name, rms, p99 in summary(err):
        print(f"{name:12s} {rms:9.4f} {p99:9.4f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
