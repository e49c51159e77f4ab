"""Per-step cost of the world with 2 AMs (two_am_comp) and 10 AMs (the paper's Sec. V-C).

Run: python -m benchmarks.bench_world [--steps 2000]

"bare step" is `World.step()` alone (it re-applies the stored commands); "full loop" adds
what a lockstep server does per step: `apply`, `state` and `wrench_ee` for every AM;
"ground truth" is one `ground_truth()` call.

"per AM" times, back to back (hot caches; CPU time of this process), the lockstep simulator's own work for one AM and
step as `simulator.core` and `amlink.server` do it: read the sensors (`sensor_values`, the
frame's value type), frame and sign the sensor batch (4 MAVLink 2 frames), verify and decode
the answer (TorqueSetpoint + SET_ATTITUDE_TARGET, 2 signed frames), apply it (allocation, joint
limits) and re-apply it in the step (3 PyBullet setters); on its own line, with [devices] on
(the default randomization's levels), the devices and the estimator (`DeviceSuite.step`),
which run every physics step. "floor" is what the same work
costs in calls that no Python code around them can avoid: the PyBullet getters and setters
it makes and one SHA-256 per signed frame (hashlib), back to back. In a running SITL every
figure is ~3x this (the caches are cold after the other processes ran; see
docs/benchmarks.md). The 10-AM layout is the simulator tests' ring (`tests.simulator.sim_testing`):
cylinder of radius 0.6 m and 5 kg, AMs 36 deg apart, each facing the object (yaw = azimuth + 180 deg),
arm at q = [1.0472, -1.0472, 0], pad face 2 cm outside the surface, ee at the object's centre height.
"""
from __future__ import annotations

import argparse
import hashlib
import time
import timeit
from itertools import cycle

import numpy as np

from amcore.config import SCENARIOS_DIR, ScenarioSpec, load_scenario
from amlink import codec, wire
from amlink.protocol import SIM_COMPID, SIM_SYSID
from amlink.types import AttitudeTarget, TorqueSetpoint, sensor_frame_from_wire
from simulator.bullet import pb
from simulator.world import World
from tests.simulator.sim_testing import RING_GAP_M, RING_Q, ring_placement, ten_am_spec

SCENARIO = SCENARIOS_DIR / "two_am_comp.toml"
KEY = bytes(range(32))  # a signing key for the per-AM figures


def bench(spec: ScenarioSpec, steps: int) -> dict[str, float]:
    world = World(spec, ring_placement(spec, RING_Q, RING_GAP_M))
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


def _us(fn, number: int = 2000, repeat: int = 7) -> float:
    """Median over `repeat` rounds of fn's CPU time per call [us]: this process's CPU time
    (time.process_time), so that other processes taking the cores while it runs do not count."""
    return 1e6 * float(np.median(timeit.repeat(fn, number=number, repeat=repeat, timer=time.process_time))) / number


def per_am(spec: ScenarioSpec) -> dict[str, float]:
    """The lockstep simulator's per-AM work and its floor, [us] per AM and step (module doc)."""
    world = World(spec, ring_placement(spec, RING_Q, RING_GAP_M))
    world.connect()
    try:
        s = world.sysids[0]
        T = world.total_mass_kg(s) * spec.vehicle.gravity_mps2
        for _ in range(10):
            world.step()
        am, c, n = world._ams[s], world._client, spec.vehicle.n_joints
        enc = wire.Encoder(SIM_SYSID, SIM_COMPID, signing_key=KEY, link_id=1)
        frame = sensor_frame_from_wire(7, 0.007, world.sensor_values(s), n, 0)
        sp = TorqueSetpoint(step=7, thrust_n=T, tau_B_nm=np.zeros(3), tau_q_nm=np.zeros(n))
        att = AttitudeTarget(7, quat_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), rates_rad_s=np.zeros(3),
                             thrust_normalized=0.5)
        am_enc = wire.Encoder(s, 191, signing_key=KEY, link_id=2)
        answers = cycle([am_enc.pack_payloads(codec.setpoint_payloads(sp, att)) for _ in range(50000)])
        dec = wire.Decoder({s: KEY}, readers=codec.READERS)
        asm = codec.SetpointAssembler()

        def receive():
            for mid, _sysid, _compid, body in dec.feed_records(next(answers)):
                asm.push(mid, body)

        def reapply():  # the per-AM part of World.step
            pb.applyExternalForce(am.body_id, -1, [0.0, 0.0, T], [0.0, 0.0, 0.0], pb.LINK_FRAME, physicsClientId=c)
            pb.applyExternalTorque(am.body_id, -1, [0.0, 0.0, 0.0], pb.LINK_FRAME, physicsClientId=c)
            pb.setJointMotorControlArray(am.body_id, world._arm_ids[s], pb.TORQUE_CONTROL, forces=[0.0] * n,
                                         physicsClientId=c)

        links, arm = world._sensed_links[s], world._arm_ids[s]
        frames = [bytes(200)] * 6  # 4 sensor frames out, 2 setpoint frames in

        def floor():
            pb.getBasePositionAndOrientation(am.body_id, physicsClientId=c)
            pb.getBaseVelocity(am.body_id, physicsClientId=c)
            pb.getJointStates(am.body_id, arm, physicsClientId=c)
            pb.getJointState(am.body_id, am.ft_joint_id, physicsClientId=c)
            pb.getLinkStates(am.body_id, links, computeForwardKinematics=1, physicsClientId=c)
            for f in frames:
                hashlib.sha256(KEY + f).digest()
            reapply()

        out = {
            "sense": _us(lambda: sensor_frame_from_wire(7, 0.007, world.sensor_values(s), n, 0)),
            "frame and sign": _us(lambda: enc.pack_payloads(codec.sensor_frame_payloads(frame))),
            "verify and decode": _us(receive),
            "apply": _us(lambda: (world.apply(s, T, np.zeros(3), np.zeros(n)), reapply())),
        }
        out["sum"] = sum(out.values())
        out["floor"] = _us(floor)
        out["estimate"] = _us(_devices_step(spec, world.sensor_values(s)))
    finally:
        world.close()
    return out


def _devices_step(spec: ScenarioSpec, values: list[float]):
    """One AM's `DeviceSuite.step` at the default randomization's [devices] levels, as a callable."""
    import tomllib

    from amcore.config import devices_from_table
    from simulator.devices import DeviceSuite
    table = tomllib.loads((SCENARIO.parents[1] / "randomize" / "default.toml").read_text())["randomize"]["devices"]
    dev = DeviceSuite(devices_from_table(table, "default.toml"), spec.vehicle.n_joints, spec.dt_s,
                      spec.vehicle.gravity_mps2, spec.seed, spec.ams[0].sysid, values)
    t = [0.0]

    def step():
        t[0] += spec.dt_s
        dev.step(values, t[0])
    return step


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
    p = per_am(base)
    print("per AM and step, the lockstep simulator's own work [us, median, hot]: "
          + ", ".join(f"{k} {v:.1f}" for k, v in p.items() if k not in ("floor", "estimate")))
    print(f"floor of that work (its PyBullet calls and SHA-256s alone): {p['floor']:.1f} us")
    print(f"with [devices]: the devices and the estimator per AM and physics step {p['estimate']:.1f} us; "
          f"sum with them {p['sum'] + p['estimate']:.1f} us (target, issue 26: <= 15 us)")


if __name__ == "__main__":
    main()
