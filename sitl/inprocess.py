"""The SITL without processes or sockets: the same `SitlCore` (world, flight controllers,
failsafe, outcome) and the same `companion.pilot.Pilot` per AM, called in one loop.

For experiments that need many runs (link-impairment sweeps, parameter studies) and for
checking that the multi-process SITL adds nothing but transport: frames are rounded as the
wire rounds them (ODOMETRY carries the base state as float32, time in microseconds;
everything else is float64), so with an ideal link both produce the same `state_digest`.

    python -m sitl.inprocess configs/scenarios/two_am_comp.toml [--duration S]

Exit codes: 0 mission success, 4 mission failed (the verdict on stderr), 2 bad configuration.
"""
from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable

import numpy as np

from amcore import cliargs, preflight
from amcore.config import ConfigError, ScenarioSpec, check_duration, load_scenario
from amlink import fastcodec
from amlink.limits import SetpointLimits
from amlink.types import (AttitudeSetpoint, SensorFrame, TorqueSetpoint, frame_values, sensor_frame_of_array,
                          with_autopilot_reports)
from amruntime import jitcache
from companion.pilot import Pilot
from simulator.core import SitlCore, kernel_group
from simulator.verdict import MISSION_FAILED


def as_on_the_wire(f: SensorFrame) -> SensorFrame:
    """The frame a companion decodes: base state through float32 (MAVLink ODOMETRY), time
    in microseconds, built as the companion's decoder builds it (one array, `sensor_frame_from_wire`);
    in attitude mode the flown target through ATTITUDE_TARGET (float32) and the measured
    joint torques (float64, exact)."""
    values = np.array(frame_values(f))  # a copy, which the new frame takes over
    values[:13] = values[:13].astype(np.float32)  # the base state: to float32 and back, exactly
    out = sensor_frame_of_array(f.step, round(f.time_s * 1e6) / 1e6, values, f.q.shape[0], int(f.flags))
    if f.joint_effort_nm is None and f.attitude_target is None:
        return out
    target = f.attitude_target
    if target is not None:  # ATTITUDE_TARGET: float32, NED/FRD and back, for the frame's step
        msgid, payload = fastcodec.attitude_report_payload(target)
        target = fastcodec.attitude_report_from_fields(fastcodec.READERS[msgid](payload, 0, len(payload)), f.step)
    return with_autopilot_reports(out, f.joint_effort_nm, target)


def setpoint_as_on_the_wire(sp: TorqueSetpoint | AttitudeSetpoint) -> TorqueSetpoint | AttitudeSetpoint:
    """The setpoint the simulator decodes: AM_TORQUE_SETPOINT is float64 (exact); an attitude
    setpoint's target goes through SET_ATTITUDE_TARGET (float32, NED/FRD and back)."""
    if not isinstance(sp, AttitudeSetpoint):
        return sp
    (att_id, att), (joint_id, joints) = fastcodec.attitude_setpoint_payloads(sp)
    read = fastcodec.READERS
    return fastcodec.attitude_setpoint_from_fields(read[att_id](att, 0, len(att)), read[joint_id](joints, 0, len(joints)))


def run(spec: ScenarioSpec, duration_s: float | None = None,
        lost: Callable[[float], set[int]] = lambda _t: set(),
        progress: Callable[[float], None] | None = None,
        failsafe_after_rejected: int | None = None,
        on_frames: Callable[[float, dict, dict], None] | None = None,
        on_truth: Callable[[object], None] | None = None) -> dict:  # fmt: skip
    """Run a scenario in-process; `lost(t)` -> sysids whose companion is silent at t (tests).

    As the UDP simulator does, a setpoint outside the plausibility bounds (`amlink.limits`)
    is refused at once (its flight controller holds the last command) and counted, and
    `failsafe_after_rejected` (None: the scenario's) refusals in a row send that vehicle to
    failsafe for good (`simulator.core`); a controller
    that raises is treated as a companion that died (failsafe) and reported. The result's
    "verdict" judges the mission (`simulator.verdict`). `progress(t)`, if given, is called
    about every simulated second. `on_frames(t, exact, frames)`, if given, sees every control
    step's exact values (`World.sensor_values` per sysid) beside the frames sent (estimator
    accuracy, `experiments/estimator_accuracy.py`). `on_truth(gt)`, if given, sees every
    ground-truth sample (`simulator.world.GroundTruth`, every 10 ms; `experiments/grasp_trace.py`)."""
    core = SitlCore(spec, failsafe_after_rejected=failsafe_after_rejected, on_truth=on_truth)
    pilots = {s: Pilot(spec, s, model=core.model, object_pose=core.object_pose) for s in core.sysids}
    # the law and the simulator's kernels: compiled once per machine (each group under its own lock, so
    # that a campaign's workers starting together compile the two groups side by side, not the same
    # one twice), else loaded from the cache
    jitcache.warm_groups([jitcache.law_group(pilots[core.sysids[0]].warm_up), kernel_group(spec)])
    v = spec.vehicle
    limits = SetpointLimits.for_vehicle(v.rotors.thrust_max_total_n, max(v.joint_torque_max_nm), v.n_joints)
    n = int(round((spec.duration_s if duration_s is None else duration_s) * spec.rate_hz))
    every = max(1, int(round(spec.rate_hz)))
    crashed: set[int] = set()
    core.connect()
    t0 = time.perf_counter()
    gone: set[int] = set()
    late = core.actuation_delay > 0  # [flight_controller].actuation_delay_steps: answers act d steps later
    pending: dict[int, TorqueSetpoint | AttitudeSetpoint] = {}  # such answers, not yet acting
    refused: list[tuple[int, str]] = []  # answers refused as implausible, noted when they would act

    def answer(frames: dict[int, SensorFrame]) -> dict[int, TorqueSetpoint | AttitudeSetpoint]:
        """Each companion's setpoint for its frame; a refused one goes to `refused`."""
        setpoints = {}
        for s, f in frames.items():
            if s in gone:
                continue
            try:
                sp = setpoint_as_on_the_wire(pilots[s].step(as_on_the_wire(f))[0])
                why = limits.violation(sp)
            except (ArithmeticError, ValueError) as exc:  # LinAlgError, non-finite setpoints
                core.note_controller_error(s, f"{type(exc).__name__}: {exc}")
                crashed.add(s)
                continue
            if why is None:
                setpoints[s] = sp
            else:
                refused.append((s, why))
        return setpoints

    def acting() -> dict[int, TorqueSetpoint | AttitudeSetpoint]:
        """The answers that act now, their refusals noted (as the UDP simulator's lockstep)."""
        nonlocal pending
        for s, why in refused:
            core.note_rejected(s, why)
        refused.clear()
        out, pending = pending, {}
        return out

    try:
        for k in range(n):
            if core.is_control_step(k):
                frames = core.frames(k)
                if on_frames is not None:
                    on_frames(core.time_s, core.exact_values, frames)
                if late and k > 0:  # what acts now, then this step's answers, which act d steps later
                    core.actuate(k, acting() if core.due(k) else {}, gone | crashed)
                    gone = lost(core.time_s) | crashed
                    pending = answer(frames)
                else:
                    gone = lost(core.time_s) | crashed
                    pending = answer(frames)
                    core.actuate(k, acting(), gone | crashed)
            else:  # as the UDP simulator: who was lost at the last exchange stays lost until the next
                core.hold(k, gone | crashed, acting() if core.due(k) else None)
            core.step()
            if progress is not None and k % every == 0:
                progress(core.time_s)
        result = core.finish()
    finally:
        core.close()
    wall = time.perf_counter() - t0
    return {"scenario": spec.name, "steps": n, "sim_time_s": n * spec.dt_s, "wall_s": wall,
            "real_time_factor": n * spec.dt_s / wall, **result,
            "companions": {s: p.summary() for s, p in pilots.items()}}


def main(argv: list[str] | None = None) -> int:
    ap = cliargs.ArgumentParser(prog="python -m sitl.inprocess", description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("scenario")
    ap.add_argument("--duration", type=cliargs.seconds, default=None)
    ap.add_argument("--failsafe-after-rejected", type=cliargs.count, default=None, metavar="K",
                    help="failsafe after K setpoints in a row rejected as implausible (default: the scenario's "
                         "[flight_controller].failsafe_after_rejected)")
    a = ap.parse_args(argv)
    try:
        spec = load_scenario(a.scenario)
        preflight.check(spec)  # [mission].envelope_check: nothing flies outside the team's envelope
        if a.duration is not None:
            check_duration(spec, a.duration, "--duration")
    except ConfigError as exc:
        return cliargs.fail(ap.prog, str(exc))
    result = run(spec, a.duration, failsafe_after_rejected=a.failsafe_after_rejected)
    print(json.dumps(result, indent=1, default=str))
    print(result["verdict"]["text"], file=sys.stderr)
    return MISSION_FAILED if result["verdict"]["status"] == "failed" else 0


if __name__ == "__main__":
    sys.exit(main())
