"""The readable twin of the lockstep batch codec (amlink.codec), on pymavlink's message objects.

Each function builds or reads one batch with the message classes that pymavlink's mavgen
generates from the dialect, field by field, as a reader of the MAVLink definitions would:
tests/amlink/test_codec_twin.py checks that amlink.codec's struct packers and readers write the
same bytes and read them into the same values with the same errors, and other tests use these
builders to make traffic as a pymavlink-based peer would send it.
"""

from __future__ import annotations

import math

from amlink.codec import (
    ODOM_CHILD_FRAME_ID,
    ODOM_FRAME_ID,
    BatchMismatchError,
    CodecError,
    EncodeError,
    NonFiniteValueError,
    FrameConventionError,
    Shutdown,
    _usec,
    all_finite,
    attitude_setpoint_values,
    mav,
)
from amlink.px4 import q_enu_flu_to_ned_frd, q_ned_frd_to_enu_flu
from amlink.types import MAX_JOINTS, AttitudeSetpoint, AttitudeTarget, SensorFrame, StepFlag, TorqueSetpoint

_UNKNOWN_COV = [math.nan] + [0.0] * 20  # MAVLink: NaN first element = unknown
_ZEROS = [0.0] * MAX_JOINTS


def _check_finite(msgname: str, field: str, values) -> None:
    if not all_finite(values):
        raise NonFiniteValueError(msgname, field)


def _pad(values: list[float]) -> list[float]:
    return values + _ZEROS[len(values) :]



# -- message builders ---------------------------------------------------------


def sensor_frame_messages(frame: SensorFrame, scenario_id: int = 0) -> list:
    """The four messages of a sensor batch, AM_SIM_STEP last."""
    t_us = _usec(frame.time_s)
    p, qt = frame.p_WB.tolist(), frame.quat_WB_wxyz.tolist()
    v, w = frame.v_B.tolist(), frame.w_B.tolist()
    q, qdot, wr = frame.q.tolist(), frame.qdot.tolist(), frame.wrench_E.tolist()
    if not all_finite(p + qt + v + w + q + qdot + wr):
        raise EncodeError(f"non-finite value in SensorFrame step {frame.step}")
    odom = mav.MAVLink_odometry_message(
        t_us, ODOM_FRAME_ID, ODOM_CHILD_FRAME_ID, p[0], p[1], p[2], qt,
        v[0], v[1], v[2], w[0], w[1], w[2],
        _UNKNOWN_COV, _UNKNOWN_COV, 0, mav.MAV_ESTIMATOR_TYPE_NAIVE, 100,
    )  # fmt: skip
    effort = frame.joint_effort_nm
    if effort is None:
        joints = mav.MAVLink_am_joint_state_message(frame.step, len(q), _pad(q), _pad(qdot))
    else:
        e = effort.tolist()
        if not all_finite(e):
            raise EncodeError(f"non-finite value in SensorFrame step {frame.step}")
        joints = mav.MAVLink_am_joint_state_message(frame.step, len(q), _pad(q), _pad(qdot), _pad(e), 1)
    wrench = mav.MAVLink_am_wrench_message(frame.step, wr[:3], wr[3:])
    step = mav.MAVLink_am_sim_step_message(frame.step, t_us, scenario_id, int(frame.flags))
    if frame.attitude_target is None:
        return [odom, joints, wrench, step]
    return [odom, joints, wrench, attitude_report_message(frame.attitude_target, t_us // 1000), step]


def attitude_report_message(att: AttitudeTarget, time_boot_ms: int = 0) -> object:
    """ATTITUDE_TARGET: the target the autopilot flies (as PX4 reports it), NED/FRD, type_mask 0."""
    quat, r = att.quat_wxyz.tolist(), att.rates_rad_s.tolist()
    if not all_finite([*quat, *r, att.thrust_normalized]):
        raise EncodeError(f"non-finite value in AttitudeTarget step {att.step}")
    return mav.MAVLink_attitude_target_message(time_boot_ms & 0xFFFFFFFF, 0, list(q_enu_flu_to_ned_frd(quat)),
                                               r[0], -r[1], -r[2], att.thrust_normalized)  # FLU -> FRD rates


def setpoint_messages(
    sp: TorqueSetpoint, attitude: AttitudeTarget | None = None, time_boot_ms: int = 0,
    target_system: int = 1, target_component: int = 1,
) -> list:  # fmt: skip
    """The messages of a setpoint batch, AM_TORQUE_SETPOINT last."""
    tau_B, tau_q = sp.tau_B_nm.tolist(), sp.tau_q_nm.tolist()
    if not all_finite([sp.thrust_n, *tau_B, *tau_q]):
        raise EncodeError(f"non-finite value in TorqueSetpoint step {sp.step}")
    out = []
    if attitude is not None:
        quat, r = attitude.quat_wxyz.tolist(), attitude.rates_rad_s.tolist()
        if not all_finite([*quat, *r, attitude.thrust_normalized]):
            raise EncodeError(f"non-finite value in AttitudeTarget step {attitude.step}")
        # FLU -> FRD body rates: (p, q, r) -> (p, -q, -r)
        out.append(mav.MAVLink_set_attitude_target_message(
            time_boot_ms & 0xFFFFFFFF, target_system, target_component, 0,
            list(q_enu_flu_to_ned_frd(quat)), r[0], -r[1], -r[2], attitude.thrust_normalized,
        ))  # fmt: skip
    out.append(mav.MAVLink_am_torque_setpoint_message(
        sp.step, sp.thrust_n, tau_B, len(tau_q), _pad(tau_q), int(sp.flags),
    ))  # fmt: skip
    return out


def attitude_setpoint_messages(
    sp: AttitudeSetpoint, time_boot_ms: int = 0, target_system: int = 1, target_component: int = 1,
) -> list:  # fmt: skip
    """The messages of an attitude-mode setpoint batch: SET_ATTITUDE_TARGET, then
    AM_JOINT_TORQUE_SETPOINT (last: it carries the step)."""
    att = sp.attitude
    quat, r, tau_q = attitude_setpoint_values(sp)
    return [
        mav.MAVLink_set_attitude_target_message(
            time_boot_ms & 0xFFFFFFFF, target_system, target_component, 0,
            list(q_enu_flu_to_ned_frd(quat)), r[0], -r[1], -r[2], att.thrust_normalized,
        ),  # FLU -> FRD body rates
        mav.MAVLink_am_joint_torque_setpoint_message(sp.step, len(tau_q), _pad(tau_q), int(sp.flags)),
    ]  # fmt: skip


# -- decoders -------------------------------------------------------------------


def sensor_frame_from_messages(odom, joints, wrench, step_msg, target=None) -> SensorFrame:
    """Assemble a :class:`SensorFrame` from the four messages of one batch (and its
    ATTITUDE_TARGET in attitude mode, `target`).

    Raises BatchMismatchError if the steps (or ODOMETRY/AM_SIM_STEP times)
    disagree, FrameConventionError on unexpected ODOMETRY frames, and
    NonFiniteValueError on NaN/inf.
    """
    step = step_msg.step
    if joints.step != step or wrench.step != step:
        raise BatchMismatchError(
            f"batch steps disagree: AM_SIM_STEP {step}, AM_JOINT_STATE {joints.step}, AM_WRENCH {wrench.step}"
        )
    if odom.time_usec != step_msg.time_usec:
        raise BatchMismatchError(
            f"step {step}: ODOMETRY time_usec {odom.time_usec} != AM_SIM_STEP time_usec {step_msg.time_usec}"
        )
    if odom.frame_id != ODOM_FRAME_ID or odom.child_frame_id != ODOM_CHILD_FRAME_ID:
        raise FrameConventionError(
            f"ODOMETRY frames ({odom.frame_id}, {odom.child_frame_id}) != (LOCAL_ENU, BODY_FLU)"
            f" = ({ODOM_FRAME_ID}, {ODOM_CHILD_FRAME_ID})"
        )
    n = joints.n_joints
    if n > MAX_JOINTS:
        raise CodecError(f"AM_JOINT_STATE.n_joints={n} > {MAX_JOINTS}")
    base = (odom.x, odom.y, odom.z, *odom.q, odom.vx, odom.vy, odom.vz,
            odom.rollspeed, odom.pitchspeed, odom.yawspeed)  # fmt: skip
    _check_finite("ODOMETRY", "pose/twist", base)
    q, qdot = joints.position_rad[:n], joints.velocity_rad_s[:n]
    _check_finite("AM_JOINT_STATE", "position_rad", q)
    _check_finite("AM_JOINT_STATE", "velocity_rad_s", qdot)
    wr = (*wrench.force_n, *wrench.torque_nm)
    _check_finite("AM_WRENCH", "force_n/torque_nm", wr)
    effort = None
    if getattr(joints, "effort_valid", 0):
        effort = joints.effort_nm[:n]
        _check_finite("AM_JOINT_STATE", "effort_nm", effort)
    return SensorFrame(
        step=step, time_s=step_msg.time_usec / 1e6,
        p_WB=base[0:3], quat_WB_wxyz=base[3:7], v_B=base[7:10], w_B=base[10:13],
        q=q, qdot=qdot, wrench_E=wr, flags=step_msg.flags, joint_effort_nm=effort,
        attitude_target=None if target is None else attitude_report_from_message(target, step),
    )  # fmt: skip


def attitude_report_from_message(msg, step: int) -> AttitudeTarget:
    """The ATTITUDE_TARGET of a sensor batch, for the batch's step (the message carries none)."""
    vals = (*msg.q, msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate, msg.thrust)
    _check_finite("ATTITUDE_TARGET", "q/rates/thrust", vals)
    return AttitudeTarget(step, q_ned_frd_to_enu_flu(vals[0:4]), (vals[4], -vals[5], -vals[6]), vals[7])


def setpoint_from_message(msg) -> TorqueSetpoint:
    n = msg.n_joints
    if n > MAX_JOINTS:
        raise CodecError(f"AM_TORQUE_SETPOINT.n_joints={n} > {MAX_JOINTS}")
    if not math.isfinite(msg.thrust_n):
        raise NonFiniteValueError("AM_TORQUE_SETPOINT", "thrust_n")
    tau_B, tau_q = msg.body_torque_nm, msg.joint_torque_nm[:n]
    _check_finite("AM_TORQUE_SETPOINT", "body_torque_nm", tau_B)
    _check_finite("AM_TORQUE_SETPOINT", "joint_torque_nm", tau_q)
    return TorqueSetpoint(msg.step, msg.thrust_n, tau_B, tau_q, msg.flags)


def attitude_setpoint_from_messages(att_msg, joint_msg) -> AttitudeSetpoint:
    """An attitude-mode setpoint from its SET_ATTITUDE_TARGET and AM_JOINT_TORQUE_SETPOINT."""
    n = joint_msg.n_joints
    if n > MAX_JOINTS:
        raise CodecError(f"AM_JOINT_TORQUE_SETPOINT.n_joints={n} > {MAX_JOINTS}")
    tau_q = joint_msg.joint_torque_nm[:n]
    _check_finite("AM_JOINT_TORQUE_SETPOINT", "joint_torque_nm", tau_q)
    return AttitudeSetpoint(joint_msg.step, attitude_from_message(att_msg, joint_msg.step), tau_q, joint_msg.flags)


def attitude_from_message(msg, step: int) -> AttitudeTarget:
    vals = (*msg.q, msg.body_roll_rate, msg.body_pitch_rate, msg.body_yaw_rate, msg.thrust)
    _check_finite("SET_ATTITUDE_TARGET", "q/rates/thrust", vals)
    rates = (vals[4], -vals[5], -vals[6])  # FRD -> FLU
    return AttitudeTarget(step, q_ned_frd_to_enu_flu(vals[0:4]), rates, vals[7])


# -- stateful assemblers (one per connection) ---------------------------------


class SensorFrameAssembler:
    """Collects the parts of a sensor batch; emits when its AM_SIM_STEP arrives.

    Parts may arrive across several datagrams. A batch with missing parts raises
    BatchMismatchError; a SHUTDOWN step emits :class:`Shutdown` whatever came before.
    """

    def __init__(self) -> None:
        self._odom = self._joints = self._wrench = self._target = None

    def reset(self) -> None:
        """Forget parts received so far (a new datagram starts a new batch)."""
        self._odom = self._joints = self._wrench = self._target = None

    def push(self, msg) -> SensorFrame | Shutdown | None:
        mid = msg.get_msgId()  # not msg.id: STATUSTEXT has a field named "id"
        if mid == mav.MAVLINK_MSG_ID_ODOMETRY:
            self._odom = msg
        elif mid == mav.MAVLINK_MSG_ID_ATTITUDE_TARGET:
            self._target = msg
        elif mid == mav.MAVLINK_MSG_ID_AM_JOINT_STATE:
            self._joints = msg
        elif mid == mav.MAVLINK_MSG_ID_AM_WRENCH:
            self._wrench = msg
        elif mid == mav.MAVLINK_MSG_ID_AM_SIM_STEP:
            odom, joints, wrench, target = self._odom, self._joints, self._wrench, self._target
            self._odom = self._joints = self._wrench = self._target = None
            if msg.flags & StepFlag.SHUTDOWN:
                return Shutdown(msg.step, msg.time_usec / 1e6, StepFlag(msg.flags))
            if odom is None or joints is None or wrench is None:
                missing = [n for n, m in (("ODOMETRY", odom), ("AM_JOINT_STATE", joints), ("AM_WRENCH", wrench))
                           if m is None]  # fmt: skip
                raise BatchMismatchError(f"step {msg.step}: batch incomplete, missing {', '.join(missing)}")
            return sensor_frame_from_messages(odom, joints, wrench, msg, target)
        return None


class SetpointAssembler:
    """Pairs a SET_ATTITUDE_TARGET with the setpoint message that follows it: optional before
    AM_TORQUE_SETPOINT, required before AM_JOINT_TORQUE_SETPOINT (CodecError without)."""

    def __init__(self) -> None:
        self._attitude = None

    def reset(self) -> None:
        self._attitude = None

    def push(self, msg) -> tuple[TorqueSetpoint | AttitudeSetpoint, AttitudeTarget | None] | None:
        mid = msg.get_msgId()  # not msg.id: STATUSTEXT has a field named "id"
        if mid == mav.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET:
            self._attitude = msg
        elif mid == mav.MAVLINK_MSG_ID_AM_TORQUE_SETPOINT:
            att_msg, self._attitude = self._attitude, None
            sp = setpoint_from_message(msg)
            return sp, (attitude_from_message(att_msg, sp.step) if att_msg is not None else None)
        elif mid == mav.MAVLINK_MSG_ID_AM_JOINT_TORQUE_SETPOINT:
            att_msg, self._attitude = self._attitude, None
            if att_msg is None:
                raise BatchMismatchError(f"step {msg.step}: AM_JOINT_TORQUE_SETPOINT without SET_ATTITUDE_TARGET")
            asp = attitude_setpoint_from_messages(att_msg, msg)
            return asp, asp.attitude
        return None
