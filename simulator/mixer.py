"""Joint-torque limits of the arm's drivers (pure numpy). The rotors' allocation is
`amcore.allocation`, built from the vehicle's rotor table."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class JointTorqueResult:
    """Joint torques after limiting: applied_nm (n,) [N m]; saturated if any was clipped."""

    applied_nm: np.ndarray
    saturated: bool


# ---------------------------------------------------------------------- joint torques
def limit_joint_torques(tau_q_nm, tau_max_nm) -> JointTorqueResult:
    """Clip each joint torque to [-tau_max, tau_max] [N m]; report whether any was clipped."""
    tau = np.asarray(tau_q_nm, dtype=float)
    tau_max = np.asarray(tau_max_nm, dtype=float)
    if tau.shape != tau_max.shape:
        raise ValueError(f"got joint torques of shape {tau.shape} for {tau_max.shape[0]} joints")
    t, t_max = tau.tolist(), tau_max.tolist()  # Python floats: a few joints, per AM per step
    if not math.isfinite(sum(t)):
        raise ValueError(f"non-finite joint torque command: {tau}")
    applied = [min(max(x, -m), m) for x, m in zip(t, t_max)]
    return JointTorqueResult(applied_nm=np.array(applied), saturated=applied != t)
