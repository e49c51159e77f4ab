"""Emulated stock autopilot for attitude mode: PX4's multicopter attitude and rate loops and its
control allocation, fed SET_ATTITUDE_TARGET (pure: numpy for set-up; per step the loops compiled with numba,
`simulator.fc_kernels`, which the Python loops below define and the tests compare them with).

What runs, at [flight_controller].rate_hz, each named after the PX4 code it follows:

1. Attitude P loop (mc_att_control, AttitudeControl::update). With q the vehicle's attitude
   and q_d the target: the reduced target q_red turns the thrust axis e_z onto e_z,d by the
   shortest rotation; q_d's remaining yaw about e_z,d is scaled by MC_YAW_WEIGHT (roll and
   pitch come first); with q_e = q^-1 q_d (w >= 0), the rate setpoint is
       Omega_sp = sat(P (.) 2 vec(q_e) + Omega_ff),   P = (MC_ROLL_P, MC_PITCH_P, MC_YAW_P / MC_YAW_WEIGHT),
   saturated at MC_*RATE_MAX; Omega_ff the target's body rates (body_rate_feedforward).
2. Rate PID (mc_rate_control, RateControl::update), normalized torque per axis:
       u = K P e + I + K D (-d/dt Omega) + FF Omega_sp,   e = Omega_sp - Omega,
   Omega through a 2nd-order Butterworth at IMU_GYRO_CUTOFF, its derivative through one at
   IMU_DGYRO_CUTOFF (PX4's LowPassFilter2p). Anti-windup as PX4: the integral stops growing
   on an axis the allocation saturated in that direction, is attenuated for large errors
   (factor 1 - (e / 400 deg/s)^2) and is clamped at MC_*_INT_LIM.
3. Control allocation (`amcore.allocation`, which torque mode uses too; control_allocator,
   ControlAllocationPseudoInverse with ControlAllocationSequentialDesaturation, MC_AIRMODE = 0):
   the pseudo-inverse of the
   rotors' effectiveness, normalized as PX4 normalizes it (roll and pitch together so that
   a unit command moves the rotors by +-0.707 on an X quad, yaw by its largest entry,
   thrust by the mean), then desaturated in PX4's order: thrust (only downwards), roll,
   pitch; yaw is added last with a 15 % margin above full thrust and desaturated, then
   thrust again (only downwards). Rotor outputs in [thrust_min/thrust_max, 1] become
   rotor thrusts with the linear thrust curve f = thrust_max_n * output (PX4 THR_MDL_FAC = 0).

Units and the gain mapping to this vehicle: a normalized torque u on an axis is the physical
torque u * S_axis [N m], S = `Px4Allocation.torque_scale_nm` (for the X quad with arm L and
rotor thrust f_max: S_roll = S_pitch = 2 L f_max, S_yaw = 4 k f_max, k the rotors' moment
ratio); thrust 1 is count * f_max (for canted rotors, their thrust along z_B). So MC_ROLLRATE_P is S_roll * MC_ROLLRATE_P N m s/rad
of physical rate damping (docs/flight_controller.md).

Frames: PX4 works in NED/FRD, this module in the simulator's ENU/FLU. The laws are the same
vectors in other coordinates (the gains are per axis and sign-free), so nothing else changes.
It flies on the attitude and rates its caller hands it: the simulator's exact ones, or with
[devices] the estimator's attitude (amcore.estimator, run by simulator.core from the emulated
IMU and motion capture, as PX4 flies on EKF2's output) and the IMU's rate less the estimator's
gyro bias, which step 2 filters once (PX4's VehicleAngularVelocity).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amcore.allocation import Allocation, AllocationResult, frozen_instance
from amcore.config import FlightControllerParams
from amcore.rotors import RotorParams

from . import fc_kernels

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
    """2nd-order Butterworth low-pass by the bilinear transform (PX4's math::LowPassFilter2p);
    cutoff 0 passes the input through. Starts at its first input, as PX4's reset(sample)."""

    def __init__(self, sample_hz: float, cutoff_hz: float) -> None:
        self.active = cutoff_hz > 0.0
        if not self.active:
            return
        if not cutoff_hz < 0.5 * sample_hz:
            raise ValueError(f"low-pass cutoff {cutoff_hz} Hz must be below half the loop rate {sample_hz} Hz")
        ohm = math.tan(math.pi * cutoff_hz / sample_hz)
        c = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
        self.b0 = ohm * ohm / c
        self.b1, self.b2 = 2.0 * self.b0, self.b0
        self.a1 = 2.0 * (ohm * ohm - 1.0) / c
        self.a2 = (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / c
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


# ----------------------------------------------------------------------------- allocation
# PX4's allocation is amcore.allocation's, the one torque mode uses too (kept under its old name).
Px4Allocation = Allocation


# ----------------------------------------------------------------------------- the loops
@dataclass(frozen=True)
class FcOutput:
    """One flight-controller period: rotor thrust commands [N], the allocation, and the loops'
    setpoints (body rates [rad/s], normalized torque) for logging and tests."""

    rotor_thrusts_n: tuple[float, ...]
    allocation: AllocationResult
    rates_sp: tuple[float, float, float]
    torque_sp: tuple[float, float, float]
    thrust_sp: float


# what the rate loop takes for the allocation before the first (nothing unallocated)
_NOT_SATURATED = AllocationResult(outputs=(), allocated=(0.0, 0.0, 0.0, 0.0), unallocated=(0.0, 0.0, 0.0, 0.0),
                                  saturated=False)


class FlightController:
    """One vehicle's emulated PX4 (see module doc). `step(quat_WB_wxyz, w_B, target)` once per
    physics step; it runs its loops every `physics rate / rate_hz` steps and holds its output
    between. `target` is the held SET_ATTITUDE_TARGET (`amlink.types.AttitudeTarget`, ENU/FLU).

    compiled: steps 1 and 2 run as `simulator.fc_kernels.rate_loops` and step 3 as
    `amcore.allocation_kernels.allocate` (numba; the same numbers bit for bit), else as the
    Python below (`_update`, the literal form the tests compare it with)."""

    def __init__(self, fc: FlightControllerParams, rotors: RotorParams, physics_dt_s: float,
                 compiled: bool = True) -> None:
        self.params = fc
        self.every = max(1, round(1.0 / (fc.rate_hz * physics_dt_s)))
        self.dt_s = self.every * physics_dt_s
        rate_hz = 1.0 / self.dt_s
        self.allocation = Allocation(rotors, compiled=compiled)
        self.yaw_weight = fc.MC_YAW_WEIGHT
        w = fc.MC_YAW_WEIGHT
        # AttitudeControl::setProportionalGain: the yaw gain compensates the yaw weight's scaling
        self.att_p = (fc.MC_ROLL_P, fc.MC_PITCH_P, fc.MC_YAW_P / w if w > 1e-4 else fc.MC_YAW_P)
        self.rate_max = tuple(math.radians(x) for x in (fc.MC_ROLLRATE_MAX, fc.MC_PITCHRATE_MAX, fc.MC_YAWRATE_MAX))
        k = (fc.MC_ROLLRATE_K, fc.MC_PITCHRATE_K, fc.MC_YAWRATE_K)
        self.gain_p = tuple(a * b for a, b in zip(k, (fc.MC_ROLLRATE_P, fc.MC_PITCHRATE_P, fc.MC_YAWRATE_P)))
        self.gain_i = tuple(a * b for a, b in zip(k, (fc.MC_ROLLRATE_I, fc.MC_PITCHRATE_I, fc.MC_YAWRATE_I)))
        self.gain_d = tuple(a * b for a, b in zip(k, (fc.MC_ROLLRATE_D, fc.MC_PITCHRATE_D, fc.MC_YAWRATE_D)))
        self.gain_ff = (fc.MC_ROLLRATE_FF, fc.MC_PITCHRATE_FF, fc.MC_YAWRATE_FF)
        self.int_lim = (fc.MC_RR_INT_LIM, fc.MC_PR_INT_LIM, fc.MC_YR_INT_LIM)
        self.feedforward = fc.body_rate_feedforward
        self._gyro = [LowPass2p(rate_hz, fc.IMU_GYRO_CUTOFF) for _ in range(3)]
        self._dgyro = [LowPass2p(rate_hz, fc.IMU_DGYRO_CUTOFF) for _ in range(3)]
        self._rate_int = [0.0, 0.0, 0.0]  # the Python loops' integral (compiled: in _s)
        self._w_prev: tuple[float, float, float] | None = None
        self._sat_pos = self._sat_neg = (False, False, False)
        self._k = 0
        self.output: FcOutput | None = None
        self.compiled = compiled
        if compiled:
            self._p, self._s, self._out = fc_kernels.constants(self), np.zeros(fc_kernels.N_S), np.zeros(7)
            self._rate_loops = fc_kernels.rate_loops

    def step(self, quat_WB_wxyz, w_B, target) -> FcOutput | None:
        """The output for this physics step (None until a target has arrived)."""
        k, self._k = self._k, self._k + 1
        if target is None:
            return self.output
        if self.output is not None and k % self.every:
            return self.output
        if self.compiled:
            self.output = self._update_compiled(tuple(quat_WB_wxyz), tuple(w_B), target)
        else:
            self.output = self._update(quat_normalized(quat_WB_wxyz), tuple(w_B), target)
        return self.output

    @property
    def rate_int(self) -> list[float]:
        """The rate loop's integral per axis (normalized torque)."""
        if self.compiled:
            return self._s[fc_kernels.S_RATE_INT:fc_kernels.S_RATE_INT + 3].tolist()
        return self._rate_int

    @rate_int.setter
    def rate_int(self, values) -> None:
        """Set the integral (the free-running autopilot keeps it while landed, as PX4's
        RateControl::update(..., landed) does not integrate on the ground)."""
        v = [float(x) for x in values]
        if self.compiled:
            self._s[fc_kernels.S_RATE_INT:fc_kernels.S_RATE_INT + 3] = v
        else:
            self._rate_int = v

    def _update_compiled(self, q, w, target) -> FcOutput:
        """`_update` with steps 1 and 2 compiled (simulator.fc_kernels), taking the last
        allocation's saturation there; step 3 compiled in `amcore.allocation_kernels`."""
        last = _NOT_SATURATED if self.output is None else self.output.allocation
        out = self._out
        self._rate_loops(self._p, self._s, q, w, target.quat_wxyz, target.rates_rad_s, float(target.thrust_normalized),
                         last.unallocated, last.saturated, out)
        v = out.tolist()
        a, thrusts = self.allocation.allocate_thrusts(v[3], v[4], v[5], v[6])
        return frozen_instance(FcOutput, rotor_thrusts_n=thrusts, allocation=a, rates_sp=tuple(v[0:3]),
                               torque_sp=tuple(v[3:6]), thrust_sp=v[6])

    def _update(self, q: Quat, w, target) -> FcOutput:
        # gyro and its derivative (VehicleAngularVelocity): differentiate the raw rate, then filter
        w_prev = self._w_prev if self._w_prev is not None else w
        self._w_prev = w
        rate = [f.apply(x) for f, x in zip(self._gyro, w)]
        accel = [f.apply((x - x0) / self.dt_s) for f, x, x0 in zip(self._dgyro, w, w_prev)]

        # 1. attitude P loop
        q_d = quat_normalized(target.quat_wxyz.tolist())
        e = attitude_error(q, q_d, self.yaw_weight)
        ff = target.rates_rad_s.tolist() if self.feedforward else (0.0, 0.0, 0.0)
        rates_sp = tuple(min(max(p * ei + f, -m), m) for p, ei, f, m in zip(self.att_p, e, ff, self.rate_max))

        # 2. rate PID, the integral updated after the output (RateControl::update)
        err = [s - r for s, r in zip(rates_sp, rate)]
        torque = tuple(p * ei + i - d * a + f * s for p, ei, i, d, a, f, s in
                       zip(self.gain_p, err, self._rate_int, self.gain_d, accel, self.gain_ff, rates_sp))
        for ax in range(3):
            ei = err[ax]
            if self._sat_pos[ax]:
                ei = min(ei, 0.0)
            if self._sat_neg[ax]:
                ei = max(ei, 0.0)
            i_factor = max(0.0, 1.0 - (ei / _I_ATTENUATION_RAD_S) ** 2)
            r_i = self._rate_int[ax] + i_factor * self.gain_i[ax] * ei * self.dt_s
            if math.isfinite(r_i):
                self._rate_int[ax] = min(max(r_i, -self.int_lim[ax]), self.int_lim[ax])

        # 3. allocation; its saturation steers the next integration (control_allocator_status)
        thrust = min(max(float(target.thrust_normalized), 0.0), 1.0)
        a = self.allocation.allocate(*torque, thrust)
        achieved = not a.saturated
        self._sat_pos = tuple(not achieved and u > 1.2e-7 for u in a.unallocated[:3])
        self._sat_neg = tuple(not achieved and u < -1.2e-7 for u in a.unallocated[:3])
        return FcOutput(tuple(f * x for f, x in zip(self.allocation.rotor_thrust_max_n, a.outputs)), a, rates_sp, torque, thrust)
