"""Conversions between the wire types (amlink.types) and the controller's (amcore); no I/O."""
from __future__ import annotations

import numpy as np

from amcore.control import StepResult
from amcore.model import AmState
from amcore.so3 import R_to_quat_wxyz, quat_wxyz_to_R
from amlink.types import AttitudeTarget, SensorFrame, TorqueSetpoint


def state_from_frame(frame: SensorFrame) -> AmState:
    """Measured state of the AM: base pose in W, base twist in B, joint state."""
    q = np.asarray(frame.quat_WB_wxyz, dtype=float)
    return AmState(p_WB=np.array(frame.p_WB), R_WB=quat_wxyz_to_R(q / np.linalg.norm(q)), v_B=np.array(frame.v_B),
                   w_B=np.array(frame.w_B), q=np.array(frame.q), qdot=np.array(frame.qdot))


def setpoint_from_result(step: int, res: StepResult, thrust_max_n: float) -> tuple[TorqueSetpoint, AttitudeTarget]:
    """The torque-level setpoint the simulator applies, and the attitude target (R_b,d as a
    quaternion, w_b,d, thrust normalized by the vehicle's maximum) that goes with it."""
    c, d = res.command, res.diagnostics
    sp = TorqueSetpoint(step=step, thrust_n=c.thrust_n, tau_B_nm=c.tau_B_nm, tau_q_nm=c.tau_q_nm)
    att = AttitudeTarget(step=step, quat_wxyz=R_to_quat_wxyz(d.R_d), rates_rad_s=d.w_bd,
                         thrust_normalized=float(np.clip(c.thrust_n / thrust_max_n, 0.0, 1.0)))
    return sp, att
