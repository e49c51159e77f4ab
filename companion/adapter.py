"""Conversions between the wire types (amlink.types) and the controller's (amcore); no I/O.

Both run every step; they work on Python floats and build each array in one numpy call
(numpy's cost is per call at these sizes).
"""
from __future__ import annotations

import numpy as np

from amcore.control import StepResult
from amcore.model import AmState
from amcore.so3 import quat_wxyz_normalized, quat_wxyz_to_R, quat_xyzw_of_R
from amlink.types import (MAX_JOINTS, AttitudeSetpoint, AttitudeTarget, SensorFrame, TorqueSetpoint,
                          attitude_setpoint_from_wire, frame_values, attitude_target_from_wire, torque_setpoint_from_wire)


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
