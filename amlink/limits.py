"""Plausibility bounds on what crosses the link, defined once (numpy only, no I/O).

The link rejects -- counts and never hands on -- a setpoint or sensor frame that
is non-finite (the codec's check) or outside these bounds.  They are sanity
bounds against garbage, forgeries and blown-up numerics, not actuator limits:
the flight-controller emulation still saturates to the vehicle's real limits.

Defaults are generous enough for any vehicle of this project (a 10 kN thrust
would lift a tonne); the process mains should pass vehicle-specific ones, e.g.::

    SetpointLimits.for_vehicle(thrust_max_n=rotors.thrust_max_total_n,
                               joint_torque_max_nm=max(v.joint_torque_max_nm),
                               n_joints=v.n_joints)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amlink.types import MAX_JOINTS, AttitudeSetpoint, SensorFrame, TorqueSetpoint


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
