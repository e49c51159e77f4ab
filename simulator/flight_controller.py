"""Emulated stock autopilot for attitude mode: PX4's multicopter attitude and rate loops and its
control allocation, fed SET_ATTITUDE_TARGET (pure: numpy for set-up here; per step the loops are
`simulator.fc_kernels`, compiled with numba; their readable reference, the same steps in plain
Python, is tests/simulator/reference_flight_controller.py).

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
torque u * S_axis [N m], S = `Allocation.torque_scale_nm` (for the X quad with arm L and
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


def lowpass2p(sample_hz: float, cutoff_hz: float) -> tuple[float, float, float, float, float, float]:
    """(active, b0, b1, b2, a1, a2) of a 2nd-order Butterworth low-pass by the bilinear transform
    (PX4's math::LowPassFilter2p::set_cutoff_frequency); cutoff 0 passes the input through
    (active 0). The filter starts at its first input, as PX4's reset(sample)."""
    if not cutoff_hz > 0.0:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if not cutoff_hz < 0.5 * sample_hz:
        raise ValueError(f"low-pass cutoff {cutoff_hz} Hz must be below half the loop rate {sample_hz} Hz")
    ohm = math.tan(math.pi * cutoff_hz / sample_hz)
    c = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
    b0 = ohm * ohm / c
    return (1.0, b0, 2.0 * b0, b0, 2.0 * (ohm * ohm - 1.0) / c, (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / c)


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

    Steps 1 and 2 run as `simulator.fc_kernels.rate_loops`, step 3 as `Allocation.allocate`
    (both numba)."""

    def __init__(self, fc: FlightControllerParams, rotors: RotorParams, physics_dt_s: float) -> None:
        self.params = fc
        self.every = max(1, round(1.0 / (fc.rate_hz * physics_dt_s)))
        self.dt_s = self.every * physics_dt_s
        rate_hz = 1.0 / self.dt_s
        self.allocation = Allocation(rotors)
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
        self.gyro_filter = lowpass2p(rate_hz, fc.IMU_GYRO_CUTOFF)  # the rate, then its derivative
        self.dgyro_filter = lowpass2p(rate_hz, fc.IMU_DGYRO_CUTOFF)
        self._k = 0
        self.output: FcOutput | None = None
        self._p, self._s, self._out = fc_kernels.constants(self), fc_kernels.new_state(), np.zeros(7)
        self._rate_loops = fc_kernels.rate_loops

    def step(self, quat_WB_wxyz, w_B, target) -> FcOutput | None:
        """The output for this physics step (None until a target has arrived)."""
        k, self._k = self._k, self._k + 1
        if target is None:
            return self.output
        if self.output is not None and k % self.every:
            return self.output
        self.output = self._update(tuple(quat_WB_wxyz), tuple(w_B), target)
        return self.output

    @property
    def rate_int(self) -> list[float]:
        """The rate loop's integral per axis (normalized torque)."""
        return self._s[0]["rate_int"].tolist()

    @rate_int.setter
    def rate_int(self, values) -> None:
        """Set the integral (the free-running autopilot keeps it while landed, as PX4's
        RateControl::update(..., landed) does not integrate on the ground)."""
        self._s[0]["rate_int"] = [float(x) for x in values]

    def _update(self, q, w, target) -> FcOutput:
        """Steps 1 and 2 (simulator.fc_kernels), taking the last allocation's saturation there
        (control_allocator_status); step 3, the allocation."""
        last = _NOT_SATURATED if self.output is None else self.output.allocation
        out = self._out
        self._rate_loops(self._p, self._s, q, w, target.quat_wxyz, target.rates_rad_s, float(target.thrust_normalized),
                         last.unallocated, last.saturated, out)
        v = out.tolist()
        a, thrusts = self.allocation.allocate_thrusts(v[3], v[4], v[5], v[6])
        return frozen_instance(FcOutput, rotor_thrusts_n=thrusts, allocation=a, rates_sp=tuple(v[0:3]),
                               torque_sp=tuple(v[3:6]), thrust_sp=v[6])
