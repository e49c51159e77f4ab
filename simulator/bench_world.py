"""Per-step cost of the world with 2 AMs (two_am_comp) and 10 AMs (the paper's Sec. V-C).

Run: python -m simulator.bench_world [--steps 2000]

"bare step" is `World.step()` alone (it re-applies the stored commands); "full loop" adds
what a lockstep server does per step: `apply`, `state` and `wrench_ee` for every AM;
"ground truth" is one `ground_truth()` call. The 10-AM layout: cylinder of radius 0.6 m
and 5 kg, AMs 36 deg apart, each facing the object (yaw = azimuth + 180 deg), arm at
q = [1.0472, -1.0472, 0], pad face 2 cm outside the surface, ee at the object's centre height.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from amcore.config import AmSpec, ObjectSpec, ScenarioSpec, load_scenario
from amcore.model import AmState, build_model
from amcore.so3 import Rz

from .world import World

SCENARIO = Path(__file__).resolve().parents[1] / "configs" / "scenarios" / "two_am_comp.toml"
Q_BENCH = np.array([1.0472, -1.0472, 0.0])
GAP_M = 0.02


def ee_offset_B(spec: ScenarioSpec, q: np.ndarray) -> np.ndarray:
    """End-effector origin in the base frame at joint angles q [m] (pinocchio)."""
    model = build_model(spec.vehicle)
    data = model.pin_model.createData()
    pin.framesForwardKinematics(model.pin_model, data, np.concatenate([np.zeros(3), [0, 0, 0, 1], q]))
    return data.oMf[model.ee_frame_id].translation.copy()


def ring_placement(spec: ScenarioSpec, q: np.ndarray, gap_m: float) -> dict[int, AmState]:
    """Each AM on its azimuth, facing the object, pad face gap_m outside the surface."""
    obj = spec.object
    reach = ee_offset_B(spec, q)
    half_width = obj.radius_m if obj.shape == "cylinder" else 0.5 * obj.size_m[0]
    c = np.array(obj.position_m)
    states = {}
    for a in spec.ams:
        az = np.deg2rad(a.azimuth_deg)
        R = Rz(az + np.pi)
        p_ee = c + (half_width + gap_m) * np.array([np.cos(az), np.sin(az), 0.0])
        states[a.sysid] = AmState(p_WB=p_ee - R @ reach, R_WB=R, v_B=np.zeros(3), w_B=np.zeros(3), q=q.copy(),
                                  qdot=np.zeros(len(q)))
    return states


def ten_am_spec(base: ScenarioSpec) -> ScenarioSpec:
    obj = ObjectSpec(shape="cylinder", mass_kg=5.0, position_m=(0.0, 0.0, 0.6), radius_m=0.6, height_m=0.3,
                     lateral_friction=base.object.lateral_friction)
    ams = tuple(AmSpec(sysid=2 + i, azimuth_deg=36.0 * i) for i in range(10))
    return dataclasses.replace(base, name="ten_am_bench", object=obj, ams=ams)


def bench(spec: ScenarioSpec, steps: int) -> dict[str, float]:
    world = World(spec, ring_placement(spec, Q_BENCH, GAP_M))
    world.connect()
    try:
        T = world.total_mass_kg(spec.ams[0].sysid) * spec.vehicle.gravity_mps2
        for s in world.sysids:
            world.apply(s, T, np.zeros(3), np.zeros(3))
        t0 = time.perf_counter()
        for _ in range(steps):
            world.step()
        bare = (time.perf_counter() - t0) / steps
        t0 = time.perf_counter()
        for _ in range(steps):
            for s in world.sysids:
                world.apply(s, T, np.zeros(3), np.zeros(3))
            world.step()
            for s in world.sysids:
                world.state(s)
                world.wrench_ee(s)
        full = (time.perf_counter() - t0) / steps
        n_truth = max(1, steps // 10)
        t0 = time.perf_counter()
        for _ in range(n_truth):
            world.ground_truth()
        truth = (time.perf_counter() - t0) / n_truth
    finally:
        world.close()
    return {"bare": bare, "full": full, "truth": truth}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args(argv)
    base = load_scenario(SCENARIO)
    for label, spec in (("2 AMs (two_am_comp)", base), ("10 AMs (cylinder r 0.6 m)", ten_am_spec(base))):
        r = bench(spec, args.steps)
        rt = spec.dt_s / r["full"]
        print(f"{label:28s} bare step {1e3 * r['bare']:.3f} ms | full loop {1e3 * r['full']:.3f} ms "
              f"({rt:.2f}x real time at {spec.rate_hz:.0f} Hz) | ground_truth {1e3 * r['truth']:.3f} ms")


if __name__ == "__main__":
    main()
