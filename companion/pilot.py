"""One AM's decentralized controller, fed sensor frames, answering setpoints (no I/O).

`Pilot(spec, sysid)` builds the AM's model, its own mission references from its [[am]]
entry, and the controller that [options].controller names: the paper's law
(`amcore.control`) or the baseline (`amcore.baseline`), which take and give the same
shapes. `pilot.step(frame)` returns the setpoint for that frame (torque mode: the torque
setpoint and, informational, the attitude target; attitude mode: the attitude setpoint,
`amcore.offboard`'s law), and keeps the per-phase error summary
(`companion.outcome`); `command` and `record` are its two halves, for a caller that sends
the setpoint before the bookkeeping. A pilot whose first frame comes after t = 0 (a
companion restarted during a run) starts its references at its vehicle's state and joins
the mission's over [mission].join_blend_s (`amcore.mission.JoinBlend`). The companion
process wraps it in the MAVLink link; the in-process runner (`sitl.inprocess`) calls
it directly.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from amcore import baseline, control
from amcore.allocation import Allocation
from amcore.adapt import (HeadingAdmittance, HeadingState, LateralAdmittance, LateralState, Trim, adapted,
                          heading_update, lateral_update, trim_update)
from amcore.config import ScenarioSpec
from amcore.control import StepResult
from amcore.mission import JoinBlend, ObjectPose, am_mission, join_blend
from amcore.model import AmState, build_model, create_data
from amcore.offboard import Applied, OffboardMemory, OffboardParams, offboard_step
from amcore.so3 import R_to_quat_wxyz, quat_wxyz_normalized, quat_wxyz_to_R, quat_xyzw_of_R
from amlink.types import (
    MAX_JOINTS,
    AttitudeSetpoint,
    AttitudeTarget,
    SensorFrame,
    TorqueSetpoint,
    attitude_setpoint_from_wire,
    attitude_target_from_wire,
    frame_values,
    sensor_frame_from_wire,
    torque_setpoint_from_wire,
)

from .outcome import Outcome

_NO_WRENCH = (0.0,) * 6


class Pilot:
    def __init__(self, spec: ScenarioSpec, sysid: int, model=None, object_pose: ObjectPose | None = None) -> None:
        """object_pose: the object's measured pose ([mission].object_pose = "mocap"); None: the config's."""
        self.spec = spec
        self.am = spec.am(sysid)
        self.model = model if model is not None else build_model(spec.vehicle)
        self.data = create_data(self.model)
        self.object_pose = object_pose
        self.mission = am_mission(spec, self.am, self.model, object_pose)
        self.attitude_mode = spec.vehicle.flight_controller.mode == "attitude"
        if spec.vehicle.options.controller == "baseline":
            self.law = baseline.step
            self.params = baseline.BaselineParams.from_vehicle(spec.vehicle, self.model, self.mission.frame)
            self.memory = baseline.BaselineMemory()
        else:
            self.law = control.step
            self.params = control.ControllerParams.from_vehicle(spec.vehicle, self.mission.frame)
            if spec.vehicle.options.discrete_damping:  # the damping held over this companion's period
                self.params = dataclasses.replace(self.params, damping_dt=spec.control_dt_s)
            self.memory = OffboardMemory() if self.attitude_mode else control.ControllerMemory()
        self.thrust_max_n = Allocation(spec.vehicle.rotors).thrust_scale_n  # thrust 1 of SET_ATTITUDE_TARGET [N]
        self.offboard = OffboardParams.from_vehicle(spec.vehicle)
        ms = spec.mission
        self.outcome = Outcome(sysid, ("approach", "grasp", "hover"), (ms.grasp_end_s + ms.lift_move_s + 1.0,
                                                                      ms.hover_end_s))
        self._snaps = sorted([("approach_end", ms.approach_end_s), ("grasp_end", ms.grasp_end_s),
                              ("settle_check", spec.duration_s - 2.0)], key=lambda x: x[1])
        self._snap_early_s = 0.5 * spec.control_dt_s  # a snapshot's step may come this much before its instant
        self.last: tuple[float, object] | None = None
        self.steps = 0
        o = spec.vehicle.options
        # The heading and lateral admittances are driven by the wrist sensor, which the baseline
        # ignores (amcore.baseline): under it they are off, whatever [options] says. The trim
        # reads only the CoM error, which both laws give: it flies with either.
        sensed = spec.vehicle.options.controller != "baseline"
        self.heading = (HeadingAdmittance(2.0 * math.pi * o.heading_admittance_hz, o.heading_admittance_zeta,
                                          spec.vehicle.pad.crown_radius_m) if sensed and o.heading_admittance_hz > 0.0 else None)
        self.heading_state = HeadingState()
        K_t = np.asarray(spec.vehicle.gains.K_t, dtype=float)
        y_W = self.mission.frame.R_WT[:, 1]
        self.lateral = (LateralAdmittance(2.0 * math.pi * o.lateral_admittance_hz, o.lateral_admittance_zeta,
                                          float(y_W @ (K_t * y_W))) if sensed and o.lateral_admittance_hz > 0.0 else None)
        self.lateral_state = LateralState()
        self.trim = Trim(2.0 * math.pi * o.trim_hz) if o.trim_hz > 0.0 else None
        self.trim_dr = np.zeros(3)
        self._adapts = self.trim is not None or self.heading is not None or self.lateral is not None
        self._r_c_err: np.ndarray | None = None  # the law's CoM error of the last step (trim)
        self._wrench_E_f = None  # the controller's filtered wrench of the last step (the admittances' input)
        self._t_last: float | None = None
        self._started = False
        self._blend: JoinBlend | None = None  # set when the first frame comes after t = 0 (a rejoin)

    def step(self, frame: SensorFrame) -> tuple[TorqueSetpoint | AttitudeSetpoint, AttitudeTarget | None, StepResult]:
        """`command`, then `record`: the setpoint answering `frame`, its errors summarized."""
        sp, att, res = self.command(frame)
        self.record(frame.time_s, res)
        return sp, att, res

    def warm_up(self) -> None:
        """Two steps of a throwaway pilot on frames of the mission's start, built as the wire
        builds them: the first calls into the compiled law (amcore.law), with the argument
        types a run passes (amruntime.jitcache holds the lock around it), and with the robust
        options their shaping's kernel, which the steps at rest do not reach. This pilot is untouched."""
        twin = Pilot(self.spec, self.am.sysid, model=self.model, object_pose=self.object_pose)
        x = self.mission.initial_state()
        values = [*x.p_WB, *R_to_quat_wxyz(x.R_WB), *x.v_B, *x.w_B, *x.q, *x.qdot, *_NO_WRENCH]
        for k in range(2):
            twin.step(sensor_frame_from_wire(k, k * self.spec.control_dt_s, values, self.model.n, 0))
        # a free-running flight's first step: the take-off's blend (join_blend's terms and profile)
        take = Pilot(self.spec, self.am.sysid, model=self.model, object_pose=self.object_pose)
        x_low = [*values]
        x_low[2] -= 0.5
        take.start_takeoff(x_low, -3.0)
        for k in range(2):
            take.command(sensor_frame_from_wire(k, -3.0 + k * self.spec.control_dt_s, x_low, self.model.n, 0))
        if twin._adapts:  # the options' compiled shaping acts from the first contact on (amcore.adapt.adapted)
            m = twin.mission
            adapted(m.reference(0.0), m.frame, twin.trim_dr, HeadingState(1e-3), m.contact_point_W, LateralState(1e-3))

    def start_takeoff(self, values, t: float) -> None:
        """Free-running flight: the first step comes at mission time t < 0, with the vehicle
        standing where it landed. Its references blend from there into the mission along the
        restart's blend (amcore.mission.JoinBlend), so that the first command holds the vehicle
        where it stands: until t = 0, or over [mission].join_blend_s when less take-off time is
        left (a companion that engaged late). `values`: the first frame's values."""
        if self._started:
            raise RuntimeError("start_takeoff must come before the pilot's first step")
        self._started = True
        state = state_from_frame(sensor_frame_from_wire(0, t, values, self.model.n, 0))
        duration = max(-t, self.spec.mission.join_blend_s)
        self._blend = join_blend(self.model, self.mission, self.params.components, state, t, duration)

    def command(self, frame: SensorFrame) -> tuple[TorqueSetpoint | AttitudeSetpoint, AttitudeTarget | None, StepResult]:
        """The controller's answer to `frame`, and nothing else: in lockstep the simulator is
        waiting for it, so the companion sends it before it does any bookkeeping (`record`)."""
        t = frame.time_s
        state = state_from_frame(frame)
        if not self._started:
            self._started = True
            if t > 0.0:  # joining a run in progress (a restart): from where the vehicle is
                resume = self.spec.mission.resume_contact_force
                self._blend = join_blend(self.model, self.mission, self.params.components, state, t,
                                         self.spec.mission.join_blend_s,
                                         frame.wrench_E if resume else None,
                                         self.spec.vehicle.gains.K_y if resume else None)
        ref = self.mission.reference(t)
        if self._blend is not None:
            ref = self._blend.apply(ref, t)
        phase = self.mission.phase(t)
        if self.trim is not None and self._r_c_err is not None and phase == "approach" and t >= 0.0:
            # (not in the take-off of a free-running flight, t < 0: the blend is no hover)
            self.trim_dr = trim_update(self.trim, self.trim_dr, self._r_c_err, float(np.linalg.norm(ref.r_c_d1)),
                                       t - self._t_last)
        if self._wrench_E_f is not None:
            # the heading follows the face, and the CoM gives way along the face to the force the
            # pad pushes with, while the pads squeeze the object on the table; from the lift on
            # both settle (damping only): the object then hangs between the pads, and its own
            # turning and swinging would drive them, not a misalignment or a disagreement
            w = self._wrench_E_f if phase == "grasp" else _NO_WRENCH
            if self.heading is not None:
                self.heading_state = heading_update(self.heading, self.heading_state, w, t - self._t_last)
            if self.lateral is not None:
                self.lateral_state = lateral_update(self.lateral, self.lateral_state, w, t - self._t_last)
        task_frame = None
        if self._adapts:  # trim, heading turn and lateral shift, in that order (amcore.adapt.adapted)
            ref, task_frame = adapted(ref, self.mission.frame, self.trim_dr,
                                      self.heading_state if self.heading is not None else None,
                                      self.mission.contact_point_W,
                                      self.lateral_state if self.lateral is not None else None)
        args = (self.model, self.data, self.params, state, ref, frame.wrench_E, self.memory, t)
        if self.attitude_mode:  # the autopilot flies the attitude; the arm law is amcore.offboard's
            out = offboard_step(*args, task_frame, self.offboard, self.applied(frame))
            self.memory, res = out.memory, out.result
        else:
            res = self.law(*args) if task_frame is None else self.law(*args, task_frame)
            self.memory = res.memory
        if self.heading is not None or self.lateral is not None:  # the admittances' input
            self._wrench_E_f = res.diagnostics.wrench_E_filtered
        self._t_last = t
        if self.trim is not None and phase == "approach":  # held from the grasp on
            self._r_c_err = np.array(res.diagnostics.r_c_err)
        if self.attitude_mode:
            return attitude_setpoint_from_result(frame.step, res, self.thrust_max_n), None, res
        sp, att = setpoint_from_result(frame.step, res, self.thrust_max_n)
        return sp, att, res

    def applied(self, frame: SensorFrame) -> Applied:
        """What the vehicle reports it applied over the last period (attitude mode): the thrust
        of the target its autopilot flies [N] and the servos' measured joint torques [N m]."""
        att = frame.attitude_target
        return Applied(None if att is None else att.thrust_normalized * self.thrust_max_n, frame.joint_effort_nm)

    def record(self, t: float, res: StepResult) -> None:
        """Adds the step answered at time t [s] to the per-phase error summary."""
        d = res.diagnostics
        self.outcome.add(t, self.mission.phase(t), d)
        while self._snaps and t >= self._snaps[0][1] - self._snap_early_s:
            self.outcome.snapshot(self._snaps.pop(0)[0], t, d)
        self.last = (t, d)
        self.steps += 1

    def summary(self, error: str | None = None) -> dict:
        if self.last is not None and "end" not in self.outcome.at:
            self.outcome.snapshot("end", *self.last)
        d = self.outcome.to_dict()
        d["error"] = error
        return d


# ------------------------------------------------------------------ the wire's types and the controller's
# Both run every step; they work on Python floats and build each array in one numpy call
# (numpy's cost is per call at these sizes).


def state_from_frame(frame: SensorFrame) -> AmState:
    """Measured state of the AM: base pose in W, base twist in B, joint state.

    The frame's quaternion, renormalized, gives R_WB and is handed on to pinocchio as is
    (AmState.quat_xyzw), so the controller need not recover it from R_WB. The vectors are
    views of one copy of the frame's values (`amlink.types.frame_values`).
    """
    a = np.array(frame_values(frame))  # one writable copy; the state's vectors are views of it
    w, x, y, z = quat_wxyz_normalized(a[3:7].tolist())
    n_q = frame.q.shape[0]
    j = 13 + n_q
    # positional (p_WB, R_WB, v_B, w_B, q, qdot, quat_xyzw): matching keywords costs more than the rest
    return AmState(a[0:3], quat_wxyz_to_R((w, x, y, z)), a[7:10], a[10:13], a[13:j], a[j:j + n_q], (x, y, z, w))


def setpoint_from_result(step: int, res: StepResult, thrust_max_n: float) -> tuple[TorqueSetpoint, AttitudeTarget]:
    """The torque-level setpoint the simulator applies, and the attitude target (R_b,d as a
    quaternion, w_b,d, thrust normalized by the vehicle's maximum) that goes with it."""
    c = res.command
    n = c.tau_q_nm.shape[0]
    att = attitude_target_from_result(step, res, thrust_max_n)
    if not (0 <= step < 1 << 64 and n <= MAX_JOINTS):  # the validating constructor says why
        return TorqueSetpoint(step=step, thrust_n=c.thrust_n, tau_B_nm=c.tau_B_nm, tau_q_nm=c.tau_q_nm), att
    # within the wire's bounds, the decoder's constructor builds the same immutable instance
    # without re-checking it
    return torque_setpoint_from_wire(step, c.thrust_n, [*c.tau_B_nm.tolist(), *c.tau_q_nm.tolist()], n, 0), att


def attitude_target_from_result(step: int, res: StepResult, thrust_max_n: float) -> AttitudeTarget:
    """The attitude target of a step: R_b,d as a quaternion with w >= 0, w_b,d, and the thrust
    normalized by the vehicle's maximum (PX4's offboard thrust), within [0, 1]."""
    c, d = res.command, res.diagnostics
    if d.q_d is not None:  # R_d as a quaternion with w >= 0, from the compiled law
        w, x, y, z = d.q_d.tolist()
    else:
        x, y, z, w = quat_xyzw_of_R(d.R_d)
        if w < 0.0:  # the representative with w >= 0 (so3.R_to_quat_wxyz)
            x, y, z, w = -x, -y, -z, -w
    thrust = c.thrust_n / thrust_max_n
    thrust = min(max(thrust, 0.0), 1.0)  # np.clip, which costs ~15x more on a float
    if not 0 <= step < 1 << 64:  # the validating constructor says why
        return AttitudeTarget(step=step, quat_wxyz=np.array([w, x, y, z]), rates_rad_s=d.w_bd, thrust_normalized=thrust)
    return attitude_target_from_wire(step, [w, x, y, z, *d.w_bd.tolist(), thrust])


def attitude_setpoint_from_result(step: int, res: StepResult, thrust_max_n: float) -> AttitudeSetpoint:
    """Attitude mode's setpoint: the attitude target of `setpoint_from_result` (R_b,d, w_b,d,
    the thrust normalized by the vehicle's maximum, PX4's offboard thrust) and the joint torques."""
    c = res.command
    att = attitude_target_from_result(step, res, thrust_max_n)
    n = c.tau_q_nm.shape[0]
    if not (0 <= step < 1 << 64 and n <= MAX_JOINTS):  # the validating constructor says why
        return AttitudeSetpoint(step=step, attitude=att, tau_q_nm=c.tau_q_nm)
    return attitude_setpoint_from_wire(step, att, c.tau_q_nm.tolist(), n, 0)
