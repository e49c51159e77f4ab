"""The SITL without processes or sockets: the same `SitlCore` (world, flight controllers,
failsafe, outcome) on the same schedule (`simulator.lockstep`), and the same
`companion.pilot.Pilot` per AM, called in-process where the UDP simulator exchanges datagrams.

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
from amlink import codec
from amlink.types import (
    AttitudeSetpoint,
    SensorFrame,
    SetpointLimits,
    TorqueSetpoint,
    frame_values,
    sensor_frame_of_array,
)
from amruntime import jitcache
from companion.pilot import Pilot
from simulator.core import SitlCore, kernel_group
from simulator.lockstep import Answers, Lockstep
from simulator.verdict import MISSION_FAILED


def as_on_the_wire(f: SensorFrame) -> SensorFrame:
    """The frame a companion decodes: base state through float32 (MAVLink ODOMETRY), time
    in microseconds, built as the companion's decoder builds it (one array, `sensor_frame_from_wire`);
    in attitude mode the flown target through ATTITUDE_TARGET (float32) and the measured
    joint torques (float64, exact)."""
    values = np.array(frame_values(f))  # a copy, which the new frame takes over
    values[:13] = values[:13].astype(np.float32)  # the base state: to float32 and back, exactly
    target = f.attitude_target
    if target is not None:  # ATTITUDE_TARGET: float32, NED/FRD and back, for the frame's step
        msgid, payload = codec.attitude_report_payload(target)
        target = codec.attitude_report_from_fields(codec.READERS[msgid](payload, 0, len(payload)), f.step)
    return sensor_frame_of_array(f.step, round(f.time_s * 1e6) / 1e6, values, f.q.shape[0], int(f.flags),
                                 f.joint_effort_nm, target)


def setpoint_as_on_the_wire(sp: TorqueSetpoint | AttitudeSetpoint) -> TorqueSetpoint | AttitudeSetpoint:
    """The setpoint the simulator decodes: AM_TORQUE_SETPOINT is float64 (exact); an attitude
    setpoint's target goes through SET_ATTITUDE_TARGET (float32, NED/FRD and back)."""
    if not isinstance(sp, AttitudeSetpoint):
        return sp
    (att_id, att), (joint_id, joints) = codec.attitude_setpoint_payloads(sp)
    read = codec.READERS
    return codec.attitude_setpoint_from_fields(read[att_id](att, 0, len(att)), read[joint_id](joints, 0, len(joints)))


class Companions:
    """`simulator.lockstep.Transport` by calling each AM's `Pilot` at once: a frame as its
    companion decodes it in, the setpoint as the simulator decodes it out, refused as the
    UDP simulator refuses it (`amlink.types`); a controller that raises is reported
    (`SitlCore.note_controller_error`) and its companion counts as lost for the rest of the run.
    `lost(t)`: sysids whose companion is silent at t, who get no frame (tests)."""

    def __init__(self, core: SitlCore, pilots: dict[int, Pilot], limits: SetpointLimits,
                 lost: Callable[[float], set[int]], on_frames: Callable[[float, dict, dict], None] | None) -> None:
        self.core, self.pilots, self.limits, self._silent, self.on_frames = core, pilots, limits, lost, on_frames
        self.gone: set[int] = set()  # silent at the last send (as the UDP simulator: lost until the next)
        self.crashed: set[int] = set()
        self._answers = Answers({})

    @property
    def lost(self) -> set[int]:
        return self.gone | self.crashed

    def exchange(self, frames, while_waiting, on_setpoint) -> Answers:
        self.send(dict(frames))
        while_waiting()
        return self.collect()

    def send(self, frames: dict[int, SensorFrame]) -> None:
        """Each companion's answer to its frame, computed now and kept for `collect`."""
        core = self.core
        if self.on_frames is not None:
            self.on_frames(core.time_s, core.exact_values, frames)
        self.gone = self._silent(core.time_s) | self.crashed
        setpoints, refused = {}, []
        for s, f in frames.items():
            if s in self.gone:
                continue
            try:
                sp = setpoint_as_on_the_wire(self.pilots[s].step(as_on_the_wire(f))[0])
                why = self.limits.violation(sp)
            except (ArithmeticError, ValueError) as exc:  # LinAlgError, non-finite setpoints
                core.note_controller_error(s, f"{type(exc).__name__}: {exc}")
                self.crashed.add(s)
                continue
            if why is None:
                setpoints[s] = sp
            else:
                refused.append((s, why))
        self._answers = Answers(setpoints, tuple(refused))

    def collect(self) -> Answers:
        out, self._answers = self._answers, Answers({})
        return out


def run(spec: ScenarioSpec, duration_s: float | None = None,
        lost: Callable[[float], set[int]] = lambda _t: set(),
        progress: Callable[[float], None] | None = None,
        failsafe_after_rejected: int | None = None,
        on_frames: Callable[[float, dict, dict], None] | None = None,
        on_truth: Callable[[object], None] | None = None) -> dict:  # fmt: skip
    """Run a scenario in-process, on the UDP simulator's schedule (`simulator.lockstep`);
    `lost(t)` -> sysids whose companion is silent at t (tests).

    As the UDP simulator does, a setpoint outside the plausibility bounds (`amlink.types`)
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
    lockstep = Lockstep(core, Companions(core, pilots, limits, lost, on_frames),
                        after_step=None if progress is None else
                        lambda k: progress(core.time_s) if k % every == 0 else None)
    core.connect()
    t0 = time.perf_counter()
    try:
        lockstep.run(n)
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
