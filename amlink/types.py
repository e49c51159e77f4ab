"""Value types exchanged between the simulator and a companion, and the plausibility limits a
value must keep to cross the link (numpy only, no I/O).

Frames (Drake-style names, see STYLE.md):

* ``W`` -- world frame, earth fixed, z up (x "east", y "north": ENU by convention).
* ``B`` -- base (quadrotor body) frame, FLU: x forward, y left, z up.
* ``E`` -- end-effector frame of the arm.

Quaternions are scalar-first ``(w, x, y, z)``; ``quat_WB_wxyz`` rotates vectors
expressed in B into W (``v_W = R(quat_WB) v_B``).

All arrays are stored as read-only ``float64`` copies, so instances are truly
immutable and can be shared between threads.  (Decoders build instances with
:func:`sensor_frame_from_wire` and friends: one read-only array per instance,
the fields read-only views of it -- the same values, cheaper at 1 kHz.)  Note that the wire carries the base
state (``p_WB``, ``quat_WB_wxyz``, ``v_B``, ``w_B``) as float32 because the
standard ODOMETRY message does; the controller therefore sees float32-rounded
base state.  Joint state, wrench and all setpoints travel as float64, exactly.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

MAX_JOINTS = 8
"""Size of the fixed joint arrays in the amstack dialect."""

SCENARIO_NAME_MAX_BYTES = 32
"""Size of the AM_SCENARIO name field (ASCII, NUL padded)."""


class StepFlag(enum.IntFlag):
    """Flags of a sensor frame (AM_SIM_STEP.flags; mirrors enum AM_STEP_FLAG)."""

    NONE = 0
    SHUTDOWN = 1  # the run is ending; last message of the run
    FAILSAFE = 2  # the simulator put this vehicle in failsafe


class SetpointFlag(enum.IntFlag):
    """Flags of a setpoint (AM_TORQUE_SETPOINT.flags, AM_JOINT_TORQUE_SETPOINT.flags; mirrors AM_SETPOINT_FLAG)."""

    NONE = 0
    FAULT = 1  # controller detected a fault; this is its safe fallback
    SATURATED = 2  # thrust or a torque was clipped to its limit


def _vec(name: str, value, size: int | None) -> np.ndarray:
    """Read-only float64 copy of ``value``; ``size`` None means any length <= MAX_JOINTS."""
    arr = np.array(value, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    if size is None:
        if arr.shape[0] > MAX_JOINTS:
            raise ValueError(f"{name} has {arr.shape[0]} joints, at most {MAX_JOINTS} fit the wire")
    elif arr.shape[0] != size:
        raise ValueError(f"{name} must have shape ({size},), got {arr.shape}")
    arr.setflags(write=False)
    return arr


_STEP_FLAGS = tuple(StepFlag(i) for i in range(256))  # enum construction is slow; 1 kHz path
_SETPOINT_FLAGS = tuple(SetpointFlag(i) for i in range(256))


def _uint(name: str, value: int, bits: int) -> int:
    value = int(value)
    if not 0 <= value < (1 << bits):
        raise ValueError(f"{name}={value} does not fit uint{bits}")
    return value


@dataclass(frozen=True, eq=False)
class SensorFrame:
    """Everything a companion receives for one lockstep step.

    Attributes:
        step: step index (uint64), 0 at the start of the run.
        time_s: simulation time [s]; carried on the wire in whole microseconds.
        p_WB: (3,) base position in W [m].
        quat_WB_wxyz: (4,) base attitude, W <- B, scalar first.
        v_B: (3,) base linear velocity expressed in B [m/s].
        w_B: (3,) base angular velocity expressed in B [rad/s].
        q: (n,) joint positions [rad], n <= 8.
        qdot: (n,) joint velocities [rad/s].
        wrench_E: (6,) [force [N]; torque [N m]] the environment applies on the
            end-effector, expressed in E.
        flags: :class:`StepFlag` bits.
        joint_effort_nm: (n,) the joint torques the arm's servos measure [N m]
            (AM_JOINT_STATE.effort_nm, as Dynamixel-class servos report present current),
            or None where the flight controller does not report them (torque mode).
        attitude_target: the target the autopilot is flying (its ATTITUDE_TARGET report,
            step = that of the setpoint it came with), or None (torque mode, none flown yet).
    """

    step: int
    time_s: float
    p_WB: np.ndarray
    quat_WB_wxyz: np.ndarray
    v_B: np.ndarray
    w_B: np.ndarray
    q: np.ndarray
    qdot: np.ndarray
    wrench_E: np.ndarray
    flags: StepFlag = StepFlag.NONE
    joint_effort_nm: np.ndarray | None = None
    attitude_target: AttitudeTarget | None = None

    def __post_init__(self) -> None:
        s = object.__setattr__
        s(self, "step", _uint("step", self.step, 64))
        s(self, "time_s", float(self.time_s))
        s(self, "p_WB", _vec("p_WB", self.p_WB, 3))
        s(self, "quat_WB_wxyz", _vec("quat_WB_wxyz", self.quat_WB_wxyz, 4))
        s(self, "v_B", _vec("v_B", self.v_B, 3))
        s(self, "w_B", _vec("w_B", self.w_B, 3))
        s(self, "q", _vec("q", self.q, None))
        s(self, "qdot", _vec("qdot", self.qdot, self.q.shape[0]))
        s(self, "wrench_E", _vec("wrench_E", self.wrench_E, 6))
        s(self, "flags", _STEP_FLAGS[_uint("flags", self.flags, 8)])
        if self.joint_effort_nm is not None:
            s(self, "joint_effort_nm", _vec("joint_effort_nm", self.joint_effort_nm, self.q.shape[0]))
        if self.attitude_target is not None and not isinstance(self.attitude_target, AttitudeTarget):
            raise TypeError(f"attitude_target must be an AttitudeTarget, got {type(self.attitude_target).__name__}")

    @property
    def n_joints(self) -> int:
        return int(self.q.shape[0])

    @property
    def shutdown(self) -> bool:
        return bool(self.flags & StepFlag.SHUTDOWN)


@dataclass(frozen=True, eq=False)
class TorqueSetpoint:
    """A companion's actuation answer to one step.

    Attributes:
        step: the step of the :class:`SensorFrame` this answers.
        thrust_n: collective rotor thrust along +z of B [N].
        tau_B_nm: (3,) rotor torque on the base, expressed in B [N m].
        tau_q_nm: (n,) joint torques [N m], n <= 8.
        flags: :class:`SetpointFlag` bits.
    """

    step: int
    thrust_n: float
    tau_B_nm: np.ndarray
    tau_q_nm: np.ndarray
    flags: SetpointFlag = SetpointFlag.NONE

    def __post_init__(self) -> None:
        s = object.__setattr__
        s(self, "step", _uint("step", self.step, 64))
        s(self, "thrust_n", float(self.thrust_n))
        s(self, "tau_B_nm", _vec("tau_B_nm", self.tau_B_nm, 3))
        s(self, "tau_q_nm", _vec("tau_q_nm", self.tau_q_nm, None))
        s(self, "flags", _SETPOINT_FLAGS[_uint("flags", self.flags, 8)])

    @property
    def n_joints(self) -> int:
        return int(self.tau_q_nm.shape[0])


@dataclass(frozen=True, eq=False)
class AttitudeTarget:
    """Attitude target: the flight controller's setpoint in attitude mode (part of an
    :class:`AttitudeSetpoint`), informational next to a :class:`TorqueSetpoint` in torque mode.

    Attributes:
        step: step of the setpoint it accompanies.
        quat_wxyz: (4,) desired base attitude, W <- B (ENU <- FLU), scalar first.
        rates_rad_s: (3,) desired body rates, expressed in B (FLU) [rad/s].
        thrust_normalized: desired collective thrust in [0, 1] (1 = max thrust).

    On the wire this travels as SET_ATTITUDE_TARGET, converted to that message's
    NED <- FRD convention (float32).
    """

    step: int
    quat_wxyz: np.ndarray
    rates_rad_s: np.ndarray
    thrust_normalized: float

    def __post_init__(self) -> None:
        s = object.__setattr__
        s(self, "step", _uint("step", self.step, 64))
        s(self, "quat_wxyz", _vec("quat_wxyz", self.quat_wxyz, 4))
        s(self, "rates_rad_s", _vec("rates_rad_s", self.rates_rad_s, 3))
        s(self, "thrust_normalized", float(self.thrust_normalized))


@dataclass(frozen=True, eq=False)
class AttitudeSetpoint:
    """A companion's actuation answer in attitude mode (what a stock autopilot takes).

    Attributes:
        step: the step of the :class:`SensorFrame` this answers.
        attitude: the flight controller's target (SET_ATTITUDE_TARGET); ``attitude.step == step``.
        tau_q_nm: (n,) joint torques [N m], n <= 8, for the arm's servo driver
            (AM_JOINT_TORQUE_SETPOINT).
        flags: :class:`SetpointFlag` bits.
    """

    step: int
    attitude: AttitudeTarget
    tau_q_nm: np.ndarray
    flags: SetpointFlag = SetpointFlag.NONE

    def __post_init__(self) -> None:
        s = object.__setattr__
        s(self, "step", _uint("step", self.step, 64))
        if not isinstance(self.attitude, AttitudeTarget):
            raise TypeError(f"attitude must be an AttitudeTarget, got {type(self.attitude).__name__}")
        if self.attitude.step != self.step:
            raise ValueError(f"attitude target of step {self.attitude.step} in the setpoint of step {self.step}")
        s(self, "tau_q_nm", _vec("tau_q_nm", self.tau_q_nm, None))
        s(self, "flags", _SETPOINT_FLAGS[_uint("flags", self.flags, 8)])

    @property
    def n_joints(self) -> int:
        return int(self.tau_q_nm.shape[0])


# -- decoders' constructors ----------------------------------------------------
# A decoder has values straight off the wire whose ranges the wire format already
# bounds (uint64 step, uint8 flags, n <= MAX_JOINTS checked by the decoder).  These
# build the same immutable instances as the validating constructors, several times
# faster: one read-only float64 array, each field a read-only view of it.


def _frozen_f64(values) -> np.ndarray:
    arr = np.array(values, dtype=np.float64)
    arr.setflags(write=False)
    return arr


def _assemble(cls, **fields):
    obj = object.__new__(cls)
    obj.__dict__.update(fields)  # what a frozen dataclass's __init__ ends with, minus the checks
    return obj


def sensor_frame_from_wire(step: int, time_s: float, values, n: int, flags: int, joint_effort_nm=None,
                           attitude_target: AttitudeTarget | None = None) -> SensorFrame:
    """SensorFrame of wire values: ``values`` = p_WB, quat_WB_wxyz, v_B, w_B, q[:n], qdot[:n], wrench_E;
    the flight controller's reports where it has them (`with_autopilot_reports`).

    For decoders: the caller guarantees 0 <= step < 2**64, 0 <= n <= MAX_JOINTS,
    0 <= flags < 256 and ``len(values) == 19 + 2 n``.
    """
    return sensor_frame_of_array(step, time_s, np.array(values, dtype=np.float64), n, flags, joint_effort_nm,
                                 attitude_target)


def sensor_frame_of_array(step: int, time_s: float, a: np.ndarray, n: int, flags: int, joint_effort_nm=None,
                          attitude_target: AttitudeTarget | None = None) -> SensorFrame:
    """`sensor_frame_from_wire` of a float64 array of the values, which the frame takes over
    (made read-only, not copied: the caller must hold no other reference that writes to it),
    with the flight controller's reports where it has them (`with_autopilot_reports`)."""
    a.setflags(write=False)
    j = 13 + n
    effort = None if joint_effort_nm is None else _frozen_f64(joint_effort_nm)
    return _assemble(SensorFrame, step=step, time_s=float(time_s), p_WB=a[0:3], quat_WB_wxyz=a[3:7],
                     v_B=a[7:10], w_B=a[10:13], q=a[13:j], qdot=a[j : j + n], wrench_E=a[j + n : j + n + 6],
                     flags=_STEP_FLAGS[flags], joint_effort_nm=effort, attitude_target=attitude_target)  # fmt: skip


def frame_values(frame: SensorFrame) -> np.ndarray:
    """The frame's values in the order of `sensor_frame_from_wire` (p_WB, quat_WB_wxyz, v_B,
    w_B, q, qdot, wrench_E), read-only: the one array a decoder's frame holds, else joined."""
    a = frame.p_WB.base
    if a is not None and a.shape == (19 + 2 * frame.q.shape[0],) and frame.wrench_E.base is a:
        return a
    return np.concatenate((frame.p_WB, frame.quat_WB_wxyz, frame.v_B, frame.w_B, frame.q, frame.qdot, frame.wrench_E))


def with_autopilot_reports(frame: SensorFrame, joint_effort_nm, attitude_target: AttitudeTarget | None) -> SensorFrame:
    """`frame` with the flight controller's reports of what it applies (attitude mode): the
    servos' measured joint torques (None: not reported) and the attitude target it flies."""
    effort = None if joint_effort_nm is None else _frozen_f64(joint_effort_nm)
    return _assemble(SensorFrame, **{**frame.__dict__, "joint_effort_nm": effort, "attitude_target": attitude_target})


def torque_setpoint_from_wire(step: int, thrust_n: float, values, n: int, flags: int) -> TorqueSetpoint:
    """TorqueSetpoint of wire values: ``values`` = tau_B_nm (3), tau_q_nm[:n] (bounds as above)."""
    a = _frozen_f64(values)
    return _assemble(TorqueSetpoint, step=step, thrust_n=float(thrust_n), tau_B_nm=a[0:3], tau_q_nm=a[3 : 3 + n],
                     flags=_SETPOINT_FLAGS[flags])  # fmt: skip


def attitude_target_from_wire(step: int, values) -> AttitudeTarget:
    """AttitudeTarget of wire values: ``values`` = quat_wxyz (4), rates_rad_s (3), thrust_normalized."""
    a = _frozen_f64(values[:7])
    return _assemble(AttitudeTarget, step=step, quat_wxyz=a[0:4], rates_rad_s=a[4:7],
                     thrust_normalized=float(values[7]))  # fmt: skip


def attitude_setpoint_from_wire(step: int, attitude: AttitudeTarget, tau_q, n: int, flags: int) -> AttitudeSetpoint:
    """AttitudeSetpoint of wire values: ``attitude`` decoded for ``step``, ``tau_q`` = tau_q_nm[:n] (bounds as above)."""
    a = _frozen_f64(tau_q[:n])
    return _assemble(AttitudeSetpoint, step=step, attitude=attitude, tau_q_nm=a, flags=_SETPOINT_FLAGS[flags])


@dataclass(frozen=True)
class ScenarioInfo:
    """What run this is; sent by the simulator in AM_SCENARIO during the handshake.

    Attributes:
        scenario_id: scenario identifier (uint32).
        n_am: number of aerial manipulators in the run (uint8).
        name: ASCII name, at most 32 bytes.
        seed: random seed of the run (uint32).
        rate_hz: lockstep rate [Hz]; carried as float32.
    """

    scenario_id: int
    n_am: int
    name: str
    seed: int
    rate_hz: float

    def __post_init__(self) -> None:
        s = object.__setattr__
        s(self, "scenario_id", _uint("scenario_id", self.scenario_id, 32))
        s(self, "n_am", _uint("n_am", self.n_am, 8))
        s(self, "seed", _uint("seed", self.seed, 32))
        s(self, "rate_hz", float(self.rate_hz))
        raw = self.name.encode("ascii")  # UnicodeEncodeError is a ValueError
        if len(raw) > SCENARIO_NAME_MAX_BYTES or b"\x00" in raw:
            raise ValueError(f"scenario name {self.name!r} must be <= 32 ASCII bytes without NUL")
        if not (self.rate_hz > 0.0 and np.isfinite(self.rate_hz)):
            raise ValueError(f"rate_hz must be positive and finite, got {self.rate_hz}")


# ------------------------------------------------------------------ plausibility limits
# Plausibility bounds on what crosses the link, defined once (numpy only, no I/O).
#
# The link rejects -- counts and never hands on -- a setpoint or sensor frame that
# is non-finite (the codec's check) or outside these bounds.  They are sanity
# bounds against garbage, forgeries and blown-up numerics, not actuator limits:
# the flight-controller emulation still saturates to the vehicle's real limits.
#
# Defaults are generous enough for any vehicle of this project (a 10 kN thrust
# would lift a tonne); the process mains should pass vehicle-specific ones, e.g.::
#
#     SetpointLimits.for_vehicle(thrust_max_n=rotors.thrust_max_total_n,
#                                joint_torque_max_nm=max(v.joint_torque_max_nm),
#                                n_joints=v.n_joints)


@dataclass(frozen=True)
class SetpointLimits:
    """Bounds a :class:`TorqueSetpoint` or an :class:`AttitudeSetpoint` must satisfy to be applied.

    Attributes:
        thrust_max_n: bound on |thrust_n| [N].
        body_torque_max_nm: bound on each |tau_B_nm| component [N m].
        joint_torque_max_nm: bound on each |tau_q_nm| entry [N m].
        n_joints: required joint count; ``None`` accepts any count <= 8.
        body_rate_max_rad_s: bound on each |rates_rad_s| component of an attitude target [rad/s].
        quat_norm_tol: allowed |norm(quat_wxyz) - 1| of an attitude target (float32 on the wire).

    An attitude target's normalized thrust must lie in [-1, 1] (SET_ATTITUDE_TARGET's range;
    the flight controller uses [0, 1]).
    """

    thrust_max_n: float = 1.0e4
    body_torque_max_nm: float = 1.0e4
    joint_torque_max_nm: float = 1.0e4
    n_joints: int | None = None
    body_rate_max_rad_s: float = 1.0e3
    quat_norm_tol: float = 1.0e-2

    def __post_init__(self) -> None:
        for name in ("thrust_max_n", "body_torque_max_nm", "joint_torque_max_nm", "body_rate_max_rad_s",
                     "quat_norm_tol"):
            v = getattr(self, name)
            if not (v > 0.0 and math.isfinite(v)):
                raise ValueError(f"SetpointLimits.{name} must be positive and finite, got {v}")
        if self.n_joints is not None and not 0 <= self.n_joints <= MAX_JOINTS:
            raise ValueError(f"SetpointLimits.n_joints must be in 0..{MAX_JOINTS}, got {self.n_joints}")

    @classmethod
    def for_vehicle(cls, thrust_max_n: float, joint_torque_max_nm: float, n_joints: int,
                    body_torque_max_nm: float | None = None, margin: float = 2.0) -> SetpointLimits:  # fmt: skip
        """Bounds ``margin`` times the vehicle's actuator limits (body torque default: thrust x 1 m)."""
        tau_b = thrust_max_n if body_torque_max_nm is None else body_torque_max_nm
        return cls(margin * thrust_max_n, margin * tau_b, margin * joint_torque_max_nm, n_joints)

    def violation(self, sp: TorqueSetpoint | AttitudeSetpoint) -> str | None:
        """Why ``sp`` is implausible, or ``None`` if it is within bounds (finite by construction)."""
        if self.n_joints is not None and sp.n_joints != self.n_joints:
            return f"{sp.n_joints} joint torques, expected {self.n_joints}"
        if isinstance(sp, AttitudeSetpoint):
            return self._attitude_violation(sp)
        if not abs(sp.thrust_n) <= self.thrust_max_n:
            return f"|thrust_n| = {abs(sp.thrust_n):.3g} > {self.thrust_max_n:.3g}"
        if not _max_abs(sp.tau_B_nm) <= self.body_torque_max_nm:
            return f"|tau_B_nm| > {self.body_torque_max_nm:.3g}"
        if not _max_abs(sp.tau_q_nm) <= self.joint_torque_max_nm:
            return f"|tau_q_nm| > {self.joint_torque_max_nm:.3g}"
        return None

    def _attitude_violation(self, sp: AttitudeSetpoint) -> str | None:
        att = sp.attitude
        if not abs(att.thrust_normalized) <= 1.0:
            return f"|thrust_normalized| = {abs(att.thrust_normalized):.3g} > 1"
        w, x, y, z = att.quat_wxyz.tolist()
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        if not abs(norm - 1.0) <= self.quat_norm_tol:
            return f"attitude quaternion norm {norm:.6g} is not 1"
        if not _max_abs(att.rates_rad_s) <= self.body_rate_max_rad_s:
            return f"|rates_rad_s| > {self.body_rate_max_rad_s:.3g}"
        if not _max_abs(sp.tau_q_nm) <= self.joint_torque_max_nm:
            return f"|tau_q_nm| > {self.joint_torque_max_nm:.3g}"
        return None


@dataclass(frozen=True)
class SensorLimits:
    """Bounds a :class:`SensorFrame` must satisfy to be handed to the controller.

    Attributes:
        position_max_m: bound on each |p_WB| component [m].
        speed_max_m_s: bound on each |v_B| component [m/s].
        rate_max_rad_s: bound on each |w_B| component [rad/s].
        quat_norm_tol: allowed |norm(quat_WB_wxyz) - 1| (float32 rounding is ~1e-7).
        joint_max_rad: bound on each |q| [rad].
        joint_rate_max_rad_s: bound on each |qdot| [rad/s].
        force_max_n: bound on each wrench force component [N].
        torque_max_nm: bound on each wrench torque component [N m].
    """

    position_max_m: float = 1.0e4
    speed_max_m_s: float = 1.0e3
    rate_max_rad_s: float = 1.0e3
    quat_norm_tol: float = 1.0e-2
    joint_max_rad: float = 1.0e3
    joint_rate_max_rad_s: float = 1.0e4
    force_max_n: float = 1.0e6
    torque_max_nm: float = 1.0e5

    def violation(self, f: SensorFrame) -> str | None:
        """Why ``f`` is implausible, or ``None`` if it is within bounds."""
        n = f.n_joints
        values = np.concatenate((f.p_WB, f.v_B, f.w_B, f.q, f.qdot, f.wrench_E))
        bounds, names = self._bounds(n)
        ok = np.abs(values) <= bounds  # False for NaN too
        if not ok.all():
            i = int(np.argmin(ok))
            return f"|{names[i]}| > {bounds[i]:.3g}"
        w, x, y, z = f.quat_WB_wxyz.tolist()
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        if not abs(norm - 1.0) <= self.quat_norm_tol:
            return f"quaternion norm {norm:.6g} is not 1"
        return None

    def _bounds(self, n: int) -> tuple[np.ndarray, tuple[str, ...]]:
        cache = self.__dict__.setdefault("_cache", {})  # frozen dataclass: a private memo is fine
        if n not in cache:
            groups = (("p_WB", 3, self.position_max_m), ("v_B", 3, self.speed_max_m_s),
                      ("w_B", 3, self.rate_max_rad_s), ("q", n, self.joint_max_rad),
                      ("qdot", n, self.joint_rate_max_rad_s), ("force", 3, self.force_max_n),
                      ("torque", 3, self.torque_max_nm))  # fmt: skip
            cache[n] = (np.array([b for _, k, b in groups for _ in range(k)]),
                        tuple(name for name, k, _ in groups for _ in range(k)))  # fmt: skip
        return cache[n]


def _max_abs(arr) -> float:
    """max |x| of a small array (NaN propagates as NaN; pure Python beats numpy at this size)."""
    vals = arr.tolist()
    if not vals:
        return 0.0
    m = max(map(abs, vals))
    return m if m == m and not any(map(math.isnan, vals)) else math.nan


DEFAULT_SETPOINT_LIMITS = SetpointLimits()
DEFAULT_SENSOR_LIMITS = SensorLimits()
