"""SET_ATTITUDE_TARGET as PX4 reads it, and what the emulated autopilot reports (pure: no I/O).

PX4 v1.14.3, src/modules/mavlink/mavlink_receiver.cpp:1510-1599
(MavlinkReceiver::handle_message_set_attitude_target), with A = ATTITUDE_IGNORE (128),
R/P/Y = BODY_ROLL/PITCH/YAW_RATE_IGNORE (1/2/4), T = THROTTLE_IGNORE (64),
B = THRUST_BODY_SET (32):

- attitude = not A; body_rates = not R and not P (the yaw-rate bit does not count).
- Either one keeps the offboard stream alive (it publishes offboard_control_mode with those
  two flags, :1530-1536); a message with neither does not.
- attitude: q_d is the message's q (NED <- FRD); yaw_sp_move_rate = body_yaw_rate unless Y,
  else NaN (:1550); thrust: not B and not T -> thrust_body = (0, 0, -thrust) (fill_thrust,
  multicopter); B -> thrust_body as sent; T without B -> zero thrust (the setpoint is
  zero-initialised).
- body_rates: roll/pitch/yaw rate each NaN where ignored; thrust = (0, 0, -thrust) unless T
  (B plays no part here, :1588-1590).
- Both are published only while the vehicle is in OFFBOARD (:1563, :1593); outside it the
  message keeps the stream alive and is otherwise dropped (`simulator.px4.commander`).

What the autopilot then flies (src/modules/commander/ModeUtil/control_mode.cpp:140-146): with
offboard_control_mode.attitude set, the attitude and rate loops (mc_att_control); with only
body_rate, the rate loop alone. With an attitude, the body rates are NOT feed-forward:
mc_att_control uses only yaw_sp_move_rate, as a rotation about the earth's z axis added to
its rate setpoint (AttitudeControl.cpp:94-102: rate_sp += q^-1.dcm_z() * yawspeed). The
vehicle_rates_setpoint the receiver also publishes when the roll and pitch rates are given
is overwritten by mc_att_control's next output (it runs at the gyro rate), so it is left out
here. `flown_target` turns a setpoint into the `amlink.types.AttitudeTarget` the emulated
loops (`simulator.flight_controller`, built with body-rate feed-forward on) take, once per
physics step, in ENU/FLU.

Deviation for the simulator's sake: a setpoint whose used fields are not finite, or whose
attitude quaternion is zero, is refused (counted by the port); PX4 v1.14.3 passes NaNs on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from amlink import px4
from amlink.types import AttitudeTarget


@dataclass(frozen=True)
class OffboardSetpoint:
    """One SET_ATTITUDE_TARGET as PX4 publishes it (module doc).

    attitude, body_rate: offboard_control_mode's flags. q_NED_FRD: the attitude (w, x, y, z),
    unit, or None; yaw_move_rate_rad_s: mc_att_control's feed-forward about the earth's z
    (down) axis, NaN if none; rates_FRD_rad_s: the rate setpoint (NaN where ignored), or None;
    thrust: collective thrust in [0, 1] along -z_FRD (what the loops take); t_s: when it
    arrived (autopilot time) [s]."""

    attitude: bool
    body_rate: bool
    q_NED_FRD: tuple[float, float, float, float] | None
    yaw_move_rate_rad_s: float
    rates_FRD_rad_s: tuple[float, float, float] | None
    thrust: float
    t_s: float

    @property
    def keeps_stream_alive(self) -> bool:
        return self.attitude or self.body_rate


class SetpointError(ValueError):
    """A SET_ATTITUDE_TARGET the emulation refuses (non-finite values, zero quaternion)."""


def from_set_attitude_target(type_mask: int, q, body_rates, thrust: float, thrust_body, t_s: float) -> OffboardSetpoint:
    """The setpoint of one SET_ATTITUDE_TARGET (module doc). q: (w, x, y, z) NED <- FRD;
    body_rates: (roll, pitch, yaw) [rad/s] FRD; thrust_body: the extension field (3,), zeros
    when the sender's dialect has none. SetpointError if a used value is not finite."""
    m = int(type_mask)
    attitude = not m & px4.IGNORE_ATTITUDE
    body_rate = not m & px4.IGNORE_ROLL_RATE and not m & px4.IGNORE_PITCH_RATE
    thrust_set = bool(m & px4.THRUST_BODY_SET)
    throttle_ignored = bool(m & px4.IGNORE_THROTTLE)
    q_d = None
    yaw_rate = math.nan
    rates = None
    if attitude:
        w, x, y, z = (float(v) for v in q)
        n = math.sqrt(w * w + x * x + y * y + z * z)
        if not math.isfinite(n) or n < 1e-6:
            raise SetpointError(f"attitude quaternion {tuple(q)} is not a finite, non-zero quaternion")
        q_d = (w / n, x / n, y / n, z / n)
        if not m & px4.IGNORE_YAW_RATE:
            yaw_rate = float(body_rates[2])
            if not math.isfinite(yaw_rate):
                raise SetpointError("body_yaw_rate is not finite")
        if thrust_set:
            f = -float(thrust_body[2])
        elif throttle_ignored:
            f = 0.0
        else:
            f = float(thrust)
    elif body_rate:
        given = [not m & bit for bit in (px4.IGNORE_ROLL_RATE, px4.IGNORE_PITCH_RATE, px4.IGNORE_YAW_RATE)]
        rates = tuple(float(r) if g else math.nan for g, r in zip(given, body_rates))
        if any(g and not math.isfinite(r) for g, r in zip(given, rates)):
            raise SetpointError(f"body rates {tuple(body_rates)} are not finite")
        f = 0.0 if throttle_ignored else float(thrust)
    else:
        f = 0.0
    if not math.isfinite(f):
        raise SetpointError("thrust is not finite")
    return OffboardSetpoint(attitude, body_rate, q_d, yaw_rate, rates, f, t_s)


_ZERO3 = np.zeros(3)


def flown_target(sp: OffboardSetpoint, quat_WB_wxyz, w_B=(0.0, 0.0, 0.0)) -> AttitudeTarget:
    """The target the emulated loops fly for `sp` now, in ENU/FLU, given the vehicle's
    attitude estimate quat_WB (w, x, y, z, ENU <- FLU) and body rate w_B [rad/s] (FLU). The
    loops add the target's rates as feed-forward (module doc):

    - attitude: q_d; rates = the yaw move rate about the earth's z axis in the body frame,
      w_B = -r R_WB^T e_z,up (r about NED down), zero without one;
    - body rates only: q_d = the vehicle's own attitude (the attitude loop adds nothing) and
      rates = the setpoint's (FRD -> FLU); an ignored (NaN) yaw rate is the vehicle's own, as
      MulticopterRateControl.cpp:178-181 takes the measured rate for a NaN setpoint.
    Thrust clipped to [0, 1] by the loops."""
    if sp.attitude:
        q_d = px4.q_ned_frd_to_enu_flu(sp.q_NED_FRD)
        r = sp.yaw_move_rate_rad_s
        if math.isnan(r) or r == 0.0:
            rates = _ZERO3
        else:
            w, x, y, z = quat_WB_wxyz
            # third row of R_WB (ENU <- FLU) = R_WB^T e_z
            ez_B = (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), w * w - x * x - y * y + z * z)
            rates = np.array([-r * c for c in ez_B])
        return AttitudeTarget(0, quat_wxyz=np.array(q_d), rates_rad_s=rates, thrust_normalized=sp.thrust)
    rx, ry, rz = sp.rates_FRD_rad_s
    rates = px4.frd_to_flu((rx, ry, -w_B[2] if math.isnan(rz) else rz))
    return AttitudeTarget(0, quat_wxyz=np.array(quat_WB_wxyz, dtype=float), rates_rad_s=np.array(rates),
                          thrust_normalized=sp.thrust)


class VehicleReport(NamedTuple):
    """What one vehicle's autopilot knows at one physics step, for its MAVLink streams
    (`simulator.px4.port`), in the stack's frames (ENU world, FLU body; the port converts):

    time_s: the sample's autopilot time (boot time) [s]; p_W [m], quat_WB (w, x, y, z),
    v_W [m/s] (world frame), w_B [rad/s]: the estimator's output (EKF2's vehicle_odometry);
    gyro_B [rad/s], accel_B [m/s^2] (specific force): the IMU's last sample;
    target: the attitude target flown (ENU/FLU AttitudeTarget) or None; rates_sp_B: the
    attitude loop's rate setpoint [rad/s] (FLU) or None; home_W [m] and home_yaw_rad (about
    ENU z) or None."""

    time_s: float
    p_W: tuple[float, float, float]
    quat_WB: tuple[float, float, float, float]
    v_W: tuple[float, float, float]
    w_B: tuple[float, float, float]
    gyro_B: tuple[float, float, float]
    accel_B: tuple[float, float, float]
    target: AttitudeTarget | None = None
    rates_sp_B: tuple[float, float, float] | None = None
    home_W: tuple[float, float, float] | None = None
    home_yaw_rad: float = 0.0
