"""What compiling the simulator's hold step as a whole could save, at most: attitude mode with
`[devices]`, the steps between control steps (three of every four at 250 Hz setpoints).

    python -m benchmarks.bench_hold_ceiling [--n 2 10] [--steps 3000] [--rounds 3]

A hold step does, per AM: read the base from PyBullet, run the devices and the estimator,
hold the last setpoint (the link), run the emulated autopilot and its allocation, and set
the rotors' and the joints' commands; then PyBullet steps the world. Their arithmetic is
one compiled call over every AM (`simulator.fleet_kernels.hold`); what remains in Python is
each AM's PyBullet calls, its link and state machine, and the glue around the call. Three loops, each on its own `SitlCore` of the
same scenario (`bench_core.spec_for`: ten_am_attitude's object and quadrotor, N AMs,
`[devices]` on), after 3 s of hovering setpoints, CPU time of this process per physics step:

- "now": `SitlCore.hold` and `SitlCore.step` as a run calls them (the control steps between
  them run too, with hovering setpoints; they are timed apart, as "control step");
- "stripped": per AM the same five PyBullet calls a hold step needs (two getters and the
  rotation, two force setters and the joints' setter) and its base's values into its row,
  and the one compiled call over every AM between them (the motion capture inside it): no
  link, no effort sensor, no rotor lag, no result objects, no bookkeeping. It is a lower
  bound of what the step can cost with the kernels as they are: the glue a fused step would
  keep (the link's hold, the rotors) is left out, so "saved" overstates the gain;
- "floor": PyBullet's step with the three setters per AM alone.

"per AM above the floor" is (step - floor) / N: the simulator's own per-AM work on a hold step.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from amlink.types import AttitudeSetpoint, AttitudeTarget
from benchmarks.bench_core import spec_for
from simulator import fleet_kernels
from simulator.bullet import pb
from simulator.core import SitlCore

WARM_S = 3.0


def hover(core: SitlCore, s: int, k: int) -> AttitudeSetpoint:
    """A hovering attitude setpoint of AM s for step k (level, hover thrust, arm torques zero)."""
    m = core.model
    thrust = m.mass_kg * m.gravity_mps2 / core.vehicles[s].fc.allocation.thrust_scale_n
    att = AttitudeTarget(k, quat_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), rates_rad_s=np.zeros(3),
                         thrust_normalized=thrust)
    return AttitudeSetpoint(step=k, attitude=att, tau_q_nm=np.zeros(m.n))


def hovering(spec) -> tuple[SitlCore, int]:
    """A connected `SitlCore` after WARM_S of hovering setpoints, and its next step."""
    core = SitlCore(spec)
    core.connect()
    steps = round(WARM_S * spec.rate_hz)
    run_now(core, 0, steps)
    return core, steps


def run_now(core: SitlCore, k0: int, steps: int) -> tuple[float, float]:
    """Steps k0 .. k0 + steps as a run takes them: CPU [s] per hold step and per control step."""
    hold = control = 0.0
    n_hold = 0
    clock = time.process_time
    for k in range(k0, k0 + steps):
        c0 = clock()
        if core.is_control_step(k):
            core.frames(k)
            core.observe()
            core.actuate(k, {s: hover(core, s, k) for s in core.sysids}, ())
            core.step()
            control += clock() - c0
        else:
            core.hold(k, ())
            core.step()
            hold += clock() - c0
            n_hold += 1
    return hold / max(n_hold, 1), control / max(steps - n_hold, 1)


def run_stripped(core: SitlCore, steps: int) -> float:
    """CPU [s] per physics step of the hold step's PyBullet calls and its compiled call alone (module doc)."""
    w, c = core.world, core.world._client
    thrust_n = core.model.mass_kg * core.model.gravity_mps2
    dev, ap = core.device_arrays, core.autopilots
    ams = [(w._ams[s].body_id, w._arm_ids[s], core.vehicles[s].slot) for s in core.sysids]
    for s in core.sysids:
        ap.set_target(core.vehicles[s].slot, hover(core, s, 0).attitude)
    every = np.arange(len(ams), dtype=np.int64)
    dev.full[:] = False  # the base's values
    t = core.time_s
    c0 = time.process_time()
    for k in range(steps):
        for body, arm, i in ams:
            p, q = pb.getBasePositionAndOrientation(body, physicsClientId=c)
            v, om = pb.getBaseVelocity(body, physicsClientId=c)
            pb.getMatrixFromQuaternion(q)
            dev.values[i, :13] = (*p, q[3], q[0], q[1], q[2], *v, *om)
            dev.refill(i)
        fleet_kernels.hold(every, t, *dev.sense_arrays(), every, *ap.fly_arrays())
        for body, arm, i in ams:
            pb.applyExternalForce(body, -1, (0.0, 0.0, thrust_n), (0.0, 0.0, 0.0), pb.LINK_FRAME, physicsClientId=c)
            pb.applyExternalTorque(body, -1, (0.0, 0.0, 0.0), pb.LINK_FRAME, physicsClientId=c)
            pb.setJointMotorControlArray(body, arm, pb.TORQUE_CONTROL, forces=[0.0] * len(arm), physicsClientId=c)
        pb.stepSimulation(physicsClientId=c)
    return (time.process_time() - c0) / steps


def run_floor(core: SitlCore, steps: int) -> float:
    """CPU [s] per physics step of PyBullet's step with the three setters per AM."""
    w, c = core.world, core.world._client
    thrust_n = core.model.mass_kg * core.model.gravity_mps2
    ams = [(w._ams[s].body_id, w._arm_ids[s]) for s in core.sysids]
    c0 = time.process_time()
    for _ in range(steps):
        for body, arm in ams:
            pb.applyExternalForce(body, -1, (0.0, 0.0, thrust_n), (0.0, 0.0, 0.0), pb.LINK_FRAME, physicsClientId=c)
            pb.applyExternalTorque(body, -1, (0.0, 0.0, 0.0), pb.LINK_FRAME, physicsClientId=c)
            pb.setJointMotorControlArray(body, arm, pb.TORQUE_CONTROL, forces=[0.0] * len(arm), physicsClientId=c)
        pb.stepSimulation(physicsClientId=c)
    return (time.process_time() - c0) / steps


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--n", type=int, nargs="+", default=[2, 10])
    ap.add_argument("--steps", type=int, default=3000, help="physics steps per loop and round")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args(argv)
    print("[us per physics step, CPU time] attitude mode, [devices] on; setpoints every 4 physics steps")
    print(f"{'N':>3} {'round':>5} {'hold now':>9} {'control step':>13} {'stripped':>9} {'floor':>6} | "
          f"{'per AM above the floor: now':>28} {'stripped':>9} {'saved':>6} | {'control period now':>19} "
          f"{'with hold stripped':>19}")
    for n in a.n:
        spec = spec_for("attitude", n, True)
        now, k = hovering(spec)
        try:
            for r in range(a.rounds):
                core, _ = hovering(spec)
                try:
                    stripped = run_stripped(core, a.steps)
                finally:
                    core.close()
                core, _ = hovering(spec)
                try:
                    floor = run_floor(core, a.steps)
                finally:
                    core.close()
                hold, control = run_now(now, k, a.steps)
                k += a.steps
                per_now, per_stripped = (hold - floor) / n, (stripped - floor) / n
                every = now.control_every
                period_now = (every - 1) * hold + control
                period_stripped = (every - 1) * stripped + control
                print(f"{n:3d} {r + 1:5d} {1e6 * hold:9.0f} {1e6 * control:13.0f} {1e6 * stripped:9.0f} "
                      f"{1e6 * floor:6.0f} | {1e6 * per_now:28.1f} {1e6 * per_stripped:9.1f} "
                      f"{1e6 * (per_now - per_stripped):6.1f} | {1e6 * period_now:19.0f} "
                      f"{1e6 * period_stripped:12.0f} ({100.0 * (period_stripped / period_now - 1.0):+.0f} %)",
                      flush=True)
        finally:
            now.close()


if __name__ == "__main__":
    main()
