"""Benchmark of attitude mode's per-step cost: the emulated autopilot and what the simulator
adds around it, per AM and physics step (median and p95), and the companion's extra work.

    python -m benchmarks.bench_flight_controller [--iters 5000]

Rows, each timed in interleaved rounds so that a change in machine load hits all alike:
- the flight controller's loop (simulator.flight_controller.FlightController.step at 1 kHz,
  the loop running every call), and its allocation alone (Allocation.allocate);
- the simulator's attitude-mode path for one AM and step: read attitude and rate, the
  autopilot, command the rotors (World.attitude_and_rate + step + World.apply_rotors), next
  to torque mode's (World.apply: the allocation), on a connected world;
- the rotors' lag for one AM and step (simulator.actuators.RotorLag.step);
- the companion's attitude-mode law on top of torque mode's step (amcore.offboard: the body
  torque estimate and the joint torques for it), next to torque mode's step alone.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from amcore.config import load_scenario
from amcore.control import ControllerMemory, ControllerParams, step
from amcore.mission import am_mission
from amcore.model import build_model, create_data
from amcore.offboard import OffboardMemory, offboard_step
from amcore.so3 import R_to_quat_wxyz, exp_so3
from amlink.types import AttitudeTarget
from amcore.allocation import Allocation
from simulator.flight_controller import FlightController
from simulator.actuators import RotorLag
from simulator.world import World

ROOT = Path(__file__).resolve().parents[1]


def _stats(samples: list[float]) -> str:
    a = np.array(samples) * 1e6
    return f"median {np.median(a):7.1f} us   p95 {np.percentile(a, 95):7.1f} us"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=5000)
    a = ap.parse_args()
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp_attitude.toml")
    v = spec.vehicle
    rng = np.random.default_rng(0)
    quats = [tuple(R_to_quat_wxyz(exp_so3(0.05 * rng.normal(size=3))).tolist()) for _ in range(64)]
    rates = [tuple((0.2 * rng.normal(size=3)).tolist()) for _ in range(64)]
    hover = 0.4
    target = AttitudeTarget(0, np.array(quats[0]), [0.01, -0.02, 0.0], hover)
    fc = FlightController(v.flight_controller, v.rotors, spec.dt_s)
    alloc = Allocation(v.rotors)
    lag = RotorLag(v.rotors.time_constant_s, spec.dt_s)

    model = build_model(v)
    mission = am_mission(spec, spec.ams[0], model)
    params = ControllerParams.from_vehicle(v, mission.frame)
    data = create_data(model)
    x = mission.initial_state()
    ref = mission.reference(6.0)
    F = rng.normal(size=6)

    world = World(spec, {am.sysid: mission.initial_state() for am in spec.ams})
    world.connect()
    s = spec.ams[0].sysid
    world.apply(s, 20.0, np.zeros(3), np.zeros(3))
    fc_world = FlightController(v.flight_controller, v.rotors, spec.dt_s)
    tau_q = np.zeros(v.n_joints)

    def fc_step(k):
        fc.step(quats[k % 64], rates[k % 64], target)

    def allocation(k):
        alloc.allocate(0.01 * (k % 7), -0.02, 0.05, hover)

    def attitude_path(k):
        quat, w = world.attitude_and_rate(s)
        out = fc_world.step(quat, w, target)
        world.apply_rotors(s, out.rotor_thrusts_n, tau_q)

    def torque_path(k):
        world.apply(s, 20.0 + 0.01 * (k % 5), [0.01, -0.02, 0.0], tau_q)

    def rotor_lag(k):
        lag.step((4.4, 4.5, 4.4, 4.3))

    mem_t, mem_o = [ControllerMemory()], [OffboardMemory()]

    def torque_law(k):
        mem_t[0] = step(model, data, params, x, ref, F, mem_t[0], 1e-3 * k).memory

    def offboard_law(k):
        mem_o[0] = offboard_step(model, data, params, x, ref, F, mem_o[0], 1e-3 * k).memory

    rows = {"flight controller loop (FlightController.step)": fc_step,
            "  of which the allocation (Allocation.allocate)": allocation,
            "simulator, attitude mode: read + autopilot + apply_rotors": attitude_path,
            "simulator, torque mode: World.apply (allocation)": torque_path,
            "rotor lag (RotorLag.step)": rotor_lag,
            "companion, torque mode: control.step": torque_law,
            "companion, attitude mode: offboard.offboard_step": offboard_law}
    times: dict[str, list[float]] = {name: [] for name in rows}
    rounds = 10
    for r in range(rounds):
        for name, fn in rows.items():
            n = a.iters // rounds
            for k in range(n):
                t0 = time.perf_counter()
                fn(k)
                times[name].append(time.perf_counter() - t0)
    world.close()
    print(f"per call, {a.iters} calls each ({spec.name}, {v.flight_controller.rate_hz:g} Hz autopilot):")
    for name, ts in times.items():
        print(f"  {name:58s} {_stats(ts)}")


if __name__ == "__main__":
    main()
