"""Plausibility bounds on what crosses the link, defined once (numpy only, no I/O).

The link rejects -- counts and never hands on -- a setpoint or sensor frame that
is non-finite (the codec's check) or outside these bounds.  They are sanity
bounds against garbage, forgeries and blown-up numerics, not actuator limits:
the flight-controller emulation still saturates to the vehicle's real limits.

Defaults are generous enough for any vehicle of this project (a 10 kN thrust
would lift a tonne); the process mains should pass vehicle-specific ones, e.g.::

    SetpointLimits.for_vehicle(thrust_max_n=rotors.count * rotors.thrust_max_n,
                               joint_torque_max_nm=max(v.joint_torque_max_nm),
                               n_joints=v.n_joints)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amlink.types import MAX_JOINTS, SensorFrame, TorqueSetpoint


@dataclass(frozen=True)
class SetpointLimits:
    """Bounds a :class:`TorqueSetpoint` must satisfy to be applied.

    Attributes:
        thrust_max_n: bound on |thrust_n| [N].
        body_torque_max_nm: bound on each |tau_B_nm| component [N m].
        joint_torque_max_nm: bound on each |tau_q_nm| entry [N m].
        n_joints: required joint count; ``None`` accepts any count <= 8.
    """

    thrust_max_n: float = 1.0e4
    body_torque_max_nm: float = 1.0e4
    joint_torque_max_nm: float = 1.0e4
    n_joints: int | None = None

    def __post_init__(self) -> None:
        for name in ("thrust_max_n", "body_torque_max_nm", "joint_torque_max_nm"):
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

    def violation(self, sp: TorqueSetpoint) -> str | None:
        """Why ``sp`` is implausible, or ``None`` if it is within bounds (finite by construction)."""
        if self.n_joints is not None and sp.n_joints != self.n_joints:
            return f"{sp.n_joints} joint torques, expected {self.n_joints}"
        if not abs(sp.thrust_n) <= self.thrust_max_n:
            return f"|thrust_n| = {abs(sp.thrust_n):.3g} > {self.thrust_max_n:.3g}"
        if not np.all(np.abs(sp.tau_B_nm) <= self.body_torque_max_nm):
            return f"|tau_B_nm| > {self.body_torque_max_nm:.3g}"
        if not np.all(np.abs(sp.tau_q_nm) <= self.joint_torque_max_nm):
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
        for name, arr, bound in (
            ("p_WB", f.p_WB, self.position_max_m), ("v_B", f.v_B, self.speed_max_m_s),
            ("w_B", f.w_B, self.rate_max_rad_s), ("q", f.q, self.joint_max_rad),
            ("qdot", f.qdot, self.joint_rate_max_rad_s), ("force", f.wrench_E[:3], self.force_max_n),
            ("torque", f.wrench_E[3:], self.torque_max_nm),
        ):  # fmt: skip
            if not np.all(np.abs(arr) <= bound):
                return f"|{name}| > {bound:.3g}"
        norm = float(np.sqrt(np.dot(f.quat_WB_wxyz, f.quat_WB_wxyz)))
        if not abs(norm - 1.0) <= self.quat_norm_tol:
            return f"quaternion norm {norm:.6g} is not 1"
        return None


DEFAULT_SETPOINT_LIMITS = SetpointLimits()
DEFAULT_SENSOR_LIMITS = SensorLimits()
