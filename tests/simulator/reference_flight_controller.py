"""The emulated autopilot's loops in plain Python: the readable reference of
simulator.fc_kernels (steps 1 and 2 of simulator.flight_controller's module doc: PX4's
AttitudeControl::update and RateControl::update with LowPassFilter2p gyro filters), over a
`FlightController`'s set-up, with the reference allocation (tests/amcore/reference_allocation.py)
as step 3."""
from __future__ import annotations

import math

from simulator.flight_controller import FcOutput, FlightController

from tests.amcore.reference_allocation import allocate

_I_ATTENUATION_RAD_S = math.radians(400.0)  # RateControl::updateIntegral's i_factor scale


# ----------------------------------------------------------------------------- quaternions
Quat = tuple[float, float, float, float]  # (w, x, y, z)


def quat_mul(a: Quat, b: Quat) -> Quat:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def quat_inv(q: Quat) -> Quat:
    """Inverse of a unit quaternion (its conjugate)."""
    return (q[0], -q[1], -q[2], -q[3])


def quat_normalized(q) -> Quat:
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return (w / n, x / n, y / n, z / n)


def quat_canonical(q: Quat) -> Quat:
    """The representative with w >= 0 (matrix::Quaternion::canonical)."""
    return q if q[0] >= 0.0 else (-q[0], -q[1], -q[2], -q[3])


def quat_z_axis(q: Quat) -> tuple[float, float, float]:
    """Third column of R(q): the body z axis in the world (matrix::Quaternion::dcm_z)."""
    w, x, y, z = q
    return (2.0 * (w * y + x * z), 2.0 * (y * z - w * x), w * w - x * x - y * y + z * z)


def quat_between(src, dst, eps: float = 1e-5) -> Quat:
    """Shortest rotation taking unit vector src onto dst (matrix::Quaternion(src, dst))."""
    s0, s1, s2 = src
    d0, d1, d2 = dst
    c = (s1 * d2 - s2 * d1, s2 * d0 - s0 * d2, s0 * d1 - s1 * d0)
    dot = s0 * d0 + s1 * d1 + s2 * d2
    if math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) < eps and dot < 0.0:  # opposite: any normal axis
        a = (abs(s0), abs(s1), abs(s2))
        axis = (1.0, 0.0, 0.0) if a[0] < a[1] and a[0] < a[2] else (0.0, 1.0, 0.0) if a[1] < a[2] else (0.0, 0.0, 1.0)
        c = (s1 * axis[2] - s2 * axis[1], s2 * axis[0] - s0 * axis[2], s0 * axis[1] - s1 * axis[0])
        w = 0.0
    else:
        w = dot + math.sqrt((s0 * s0 + s1 * s1 + s2 * s2) * (d0 * d0 + d1 * d1 + d2 * d2))
    return quat_normalized((w, *c))


def attitude_error(q: Quat, q_d: Quat, yaw_weight: float) -> tuple[float, float, float]:
    """2 vec(q_e) of AttitudeControl::update: the rotation from q to the yaw-weighted target,
    in the body frame, as sin(angle / 2) times the axis, doubled."""
    e_z, e_z_d = quat_z_axis(q), quat_z_axis(q_d)
    q_red = quat_between(e_z, e_z_d)
    if abs(q_red[1]) > 1.0 - 1e-5 or abs(q_red[2]) > 1.0 - 1e-5:  # thrust axes opposite: full attitude
        q_red = q_d
    else:
        q_red = quat_mul(q_red, q)  # the vehicle tilted onto the target's thrust axis, in the world
    w, _, _, z = quat_canonical(quat_mul(quat_inv(q_red), q_d))  # the yaw left about e_z,d
    w, z = min(max(w, -1.0), 1.0), min(max(z, -1.0), 1.0)
    q_target = quat_mul(q_red, (math.cos(yaw_weight * math.acos(w)), 0.0, 0.0, math.sin(yaw_weight * math.asin(z))))
    _, ex, ey, ez = quat_canonical(quat_mul(quat_inv(q), q_target))
    return (2.0 * ex, 2.0 * ey, 2.0 * ez)


# ----------------------------------------------------------------------------- filters
class LowPass2p:
    """PX4's math::LowPassFilter2p with the coefficients `simulator.flight_controller.lowpass2p`
    gives; it starts at its first input, as PX4's reset(sample)."""

    def __init__(self, coefficients) -> None:
        active, self.b0, self.b1, self.b2, self.a1, self.a2 = coefficients
        self.active = active != 0.0
        self.d1 = self.d2 = None

    def apply(self, x: float) -> float:
        if not self.active:
            return x
        if self.d1 is None:  # reset to a steady state at x
            self.d1 = self.d2 = x / (self.b0 + self.b1 + self.b2)
        d0 = x - self.d1 * self.a1 - self.d2 * self.a2
        y = d0 * self.b0 + self.d1 * self.b1 + self.d2 * self.b2
        self.d2, self.d1 = self.d1, d0
        return y


# ----------------------------------------------------------------------------- the loops
class ReferenceFlightController:
    """`FlightController.step` in plain Python, over that controller's constants."""

    def __init__(self, fc: FlightController) -> None:
        self.fc = fc
        self.allocation = fc.allocation
        self._gyro = [LowPass2p(fc.gyro_filter) for _ in range(3)]
        self._dgyro = [LowPass2p(fc.dgyro_filter) for _ in range(3)]
        self.rate_int = [0.0, 0.0, 0.0]
        self._w_prev: tuple[float, float, float] | None = None
        self._sat_pos = self._sat_neg = (False, False, False)
        self._k = 0
        self.output: FcOutput | None = None

    def step(self, quat_WB_wxyz, w_B, target) -> FcOutput | None:
        k, self._k = self._k, self._k + 1
        if target is None:
            return self.output
        if self.output is not None and k % self.fc.every:
            return self.output
        self.output = self._update(quat_normalized(quat_WB_wxyz), tuple(w_B), target)
        return self.output

    def _update(self, q: Quat, w, target) -> FcOutput:
        fc = self.fc
        # gyro and its derivative (VehicleAngularVelocity): differentiate the raw rate, then filter
        w_prev = self._w_prev if self._w_prev is not None else w
        self._w_prev = w
        rate = [f.apply(x) for f, x in zip(self._gyro, w)]
        accel = [f.apply((x - x0) / fc.dt_s) for f, x, x0 in zip(self._dgyro, w, w_prev)]

        # 1. attitude P loop
        q_d = quat_normalized(target.quat_wxyz.tolist())
        e = attitude_error(q, q_d, fc.yaw_weight)
        ff = target.rates_rad_s.tolist() if fc.feedforward else (0.0, 0.0, 0.0)
        rates_sp = tuple(min(max(p * ei + f, -m), m) for p, ei, f, m in zip(fc.att_p, e, ff, fc.rate_max))

        # 2. rate PID, the integral updated after the output (RateControl::update)
        err = [s - r for s, r in zip(rates_sp, rate)]
        torque = tuple(p * ei + i - d * a + f * s for p, ei, i, d, a, f, s in
                       zip(fc.gain_p, err, self.rate_int, fc.gain_d, accel, fc.gain_ff, rates_sp))
        for ax in range(3):
            ei = err[ax]
            if self._sat_pos[ax]:
                ei = min(ei, 0.0)
            if self._sat_neg[ax]:
                ei = max(ei, 0.0)
            i_factor = max(0.0, 1.0 - (ei / _I_ATTENUATION_RAD_S) ** 2)
            r_i = self.rate_int[ax] + i_factor * fc.gain_i[ax] * ei * fc.dt_s
            if math.isfinite(r_i):
                self.rate_int[ax] = min(max(r_i, -fc.int_lim[ax]), fc.int_lim[ax])

        # 3. allocation; its saturation steers the next integration (control_allocator_status)
        thrust = min(max(float(target.thrust_normalized), 0.0), 1.0)
        a = allocate(self.allocation, *torque, thrust)
        achieved = not a.saturated
        self._sat_pos = tuple(not achieved and u > 1.2e-7 for u in a.unallocated[:3])
        self._sat_neg = tuple(not achieved and u < -1.2e-7 for u in a.unallocated[:3])
        return FcOutput(tuple(f * x for f, x in zip(self.allocation.rotor_thrust_max_n, a.outputs)), a, rates_sp, torque, thrust)
