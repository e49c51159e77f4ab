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

from amcore import allocation_kernels
from amcore.allocation import SATURATION_TOL, Allocation, AllocationResult, frozen_instance
from amcore.config import FlightControllerParams
from amcore.rotors import RotorParams

from . import fc_kernels, fleet_kernels


def lowpass2p(sample_hz: float, cutoff_hz: float) -> tuple[float, float, float, float, float, float]:
    """(active, b0, b1, b2, a1, a2) of a 2nd-order Butterworth low-pass by the bilinear transform
    (PX4's math::LowPassFilter2p::set_cutoff_frequency; the fields of `fc_kernels.LOWPASS2P`,
    which `fc_kernels.constants` fills from it by name); cutoff 0 passes the input through
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


class AutopilotArrays:
    """The emulated autopilots of `count` AMs of one vehicle type, stacked (one row per AM, its
    slot), so that one compiled call (`simulator.fleet_kernels.fly`) steps every AM's loops and
    allocation; each `FlightController` keeps views of its row. Besides each loop's constants,
    state and output: the attitude and rates each flies on this step, its target, and its
    allocation's result (`amcore.allocation_kernels.allocate`'s)."""

    def __init__(self, count: int, rotors: RotorParams) -> None:
        self.count = count
        self.allocation = Allocation(rotors)
        self.alloc_c = self.allocation.kernel_constants()
        n = self.allocation.count
        self.params, self.state = np.zeros(count, fc_kernels.PARAMS), np.zeros(count, fc_kernels.STATE)
        self.ap = np.zeros(count, fc_kernels.AUTOPILOT)
        self.attitude, self.rate = np.zeros((count, 4)), np.zeros((count, 3))  # quat_WB (w, x, y, z), w_B [rad/s]
        self.target_q, self.target_w, self.target_thrust = np.zeros((count, 4)), np.zeros((count, 3)), np.zeros(count)
        self.result = np.zeros(count, allocation_kernels.result_dtype(n))  # each AM's allocation record
        self._thrusts = self.result["thrusts_n"]  # a view: per AM, its rotor thrusts [N]
        self._results = [self.result[i:i + 1] for i in range(count)]  # each AM's, as `Allocation.read_result` takes it
        self.saturated = self.ap["saturated"]  # a view: per AM, whether its last allocation fell short (1 or 0)
        out = self.ap["out"]  # views: per AM, whether it has an output and that output's fields (`output`)
        self._has_output, self._rates_sp, self._torque, self._thrust = (
            self.ap["has_output"], out["rates_sp"], out["torque"], out["thrust"])
        self._fly_args = (self.params, self.state, self.ap, self.attitude, self.rate, self.target_q, self.target_w,
                          self.target_thrust, self.alloc_c, SATURATION_TOL, self.result)

    def set_target(self, slot: int, target) -> None:
        """The held SET_ATTITUDE_TARGET AM `slot` flies (`amlink.types.AttitudeTarget`)."""
        self.target_q[slot] = target.quat_wxyz
        self.target_w[slot] = target.rates_rad_s
        self.target_thrust[slot] = target.thrust_normalized

    def fly_arrays(self) -> tuple:
        """The arrays `simulator.fleet_kernels.fly` takes after the devices' (made once: the
        arrays are filled in place, never replaced)."""
        return self._fly_args

    def step(self, slots: np.ndarray) -> None:
        """One physics step of the autopilots in `slots`, on the attitude and rates in their rows
        (`attitude`, `rate`) and their targets."""
        fleet_kernels.fly_on(slots, *self._fly_args)

    def saturated_axes_of(self, slot: int) -> tuple[bool, bool, bool, bool]:
        """Per axis (roll, pitch, yaw, thrust), whether AM `slot`'s last allocation fell short."""
        return tuple([x != 0.0 for x in self.ap[slot]["saturated_axes"].tolist()])

    def thrusts(self, slot: int) -> list[float]:
        """AM `slot`'s rotor thrusts [N] of its last allocation."""
        return self._thrusts[slot].tolist()

    def all_thrusts(self) -> list[list[float]]:
        """Every AM's rotor thrusts [N] of its last allocation, by slot (one conversion for all)."""
        return self._thrusts.tolist()

    def output(self, slot: int) -> FcOutput | None:
        """AM `slot`'s output (None before its first)."""
        if self._has_output[slot] == 0.0:
            return None
        rates_sp, torque = tuple(self._rates_sp[slot].tolist()), tuple(self._torque[slot].tolist())
        thrust = self._thrust[slot].item()
        allocation, thrusts = self.allocation.read_result(self._results[slot], *torque, thrust)
        return frozen_instance(FcOutput, rotor_thrusts_n=thrusts, allocation=allocation, rates_sp=rates_sp,
                               torque_sp=torque, thrust_sp=thrust)


class FlightController:
    """One vehicle's emulated PX4 (see module doc). `step(quat_WB_wxyz, w_B, target)` once per
    physics step; it runs its loops every `physics rate / rate_hz` steps and holds its output
    between. `target` is the held SET_ATTITUDE_TARGET (`amlink.types.AttitudeTarget`, ENU/FLU).

    Its constants, state and output are a row (`slot`) of an `AutopilotArrays` (its own, of one
    row, unless a fleet's is given): steps 1 and 2 run as `simulator.fc_kernels.rate_loops`,
    step 3 as `amcore.allocation_kernels.allocate`, both in `fc_kernels.autopilot_step`, which
    `simulator.fleet_kernels.fly` calls for every AM of the arrays at once."""

    def __init__(self, fc: FlightControllerParams, rotors: RotorParams, physics_dt_s: float,
                 arrays: AutopilotArrays | None = None, slot: int = 0) -> None:
        self.params = fc
        self.every = max(1, round(1.0 / (fc.rate_hz * physics_dt_s)))
        self.dt_s = self.every * physics_dt_s
        rate_hz = 1.0 / self.dt_s
        self.arrays = a = AutopilotArrays(1, rotors) if arrays is None else arrays
        self.slot = slot
        self.allocation = a.allocation
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
        a.params[slot] = fc_kernels.constants(self)[0]
        self._s = a.state[slot:slot + 1]  # views of the row
        self._slots = np.array([slot], np.int64)
        self.reset()

    def reset(self) -> None:
        """The loops afresh (not started, no output), as PX4's after a mode change or arming."""
        a, i = self.arrays, self.slot
        a.state[i] = np.zeros((), fc_kernels.STATE)
        a.ap[i] = np.zeros((), fc_kernels.AUTOPILOT)
        a.ap[i]["every"] = self.every
        self._output: FcOutput | None = None
        self._read = 0  # outputs made when `_output` was read

    @property
    def output(self) -> FcOutput | None:
        """The output the autopilot holds (None before its first): read from the arrays when
        they hold a newer one (a held output stays the same object)."""
        made = int(self.arrays.ap[self.slot]["outputs"])
        if made != self._read:
            self._output, self._read = self.arrays.output(self.slot), made
        return self._output

    def step(self, quat_WB_wxyz, w_B, target) -> FcOutput | None:
        """The output for this physics step (None until a target has arrived)."""
        if target is None:
            self.arrays.ap[self.slot]["k"] += 1
            return self.output
        a, i = self.arrays, self.slot
        a.attitude[i], a.rate[i] = quat_WB_wxyz, w_B
        a.set_target(i, target)
        a.step(self._slots)
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
