"""Flight-controller failsafe of one AM after its companion is lost (pure: numpy + amcore).

What an autopilot does on offboard loss (PX4: hold, then land), for an aerial manipulator:
- HOLD for `hold_s`: keep the base where it was when the companion was lost (position PD
  on the base, level attitude at the last heading, gravity compensation from the AM's own
  model, pinocchio's g(q)), and make the arm compliant: gravity compensation and joint
  damping, no stiffness. An AM that was squeezing an object with others thus lets go
  instead of pushing or dragging it, and the remaining AMs' impedance takes over its
  share (holding the arm's pose instead made one lost AM of ten pull the ring apart).
- LAND: the same, with the position target descending at `descent_mps`; once the base has
  not come down for `touchdown_s` although the target is `touchdown_gap_m` below it (the
  ground, or whatever it stands on, holds it up), motors off (thrust 0) and joints limp.
The flight controller computes this from its own state estimate (here the simulator's
state) and never needs the companion. Gains are moderate on purpose: the failsafe must be
stable for any vehicle the scenario flies, not fast.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from amcore.model import AmModel, AmState, generalized_gravity
from amcore.so3 import Rz, vee


@dataclass(frozen=True)
class FailsafeGains:
    k_p: float = 16.0  # position stiffness per kg [N/m/kg]
    k_d: float = 6.4  # velocity damping per kg [N s/m/kg]
    k_R: float = 6.0  # attitude stiffness [N m/rad]
    k_w: float = 0.6  # attitude damping [N m s/rad]
    d_q: tuple[float, ...] = ()  # joint damping [N m s/rad]; no stiffness: compliant arm; empty: joint_damping(model)
    hold_s: float = 5.0
    descent_mps: float = 0.3
    touchdown_gap_m: float = 0.15
    touchdown_s: float = 0.5


# The derived damping's time constant [s]: each limp joint's speed decays in this time on its own
# inertia at the nominal pose. 13.5 ms is what the paper arm's shoulder was flown with (1.0 N m s/rad
# on M_qq,11 = 0.0135 kg m^2; am3dof.toml keeps its tuned values for all three joints).
JOINT_DAMPING_TAU_S = 0.0135


def joint_damping(model: AmModel) -> tuple[float, ...]:
    """The failsafe's joint damping [N m s/rad]: the vehicle's [safety].failsafe_joint_damping, or
    d_q,i = M_qq,ii(q_nominal) / JOINT_DAMPING_TAU_S with M_qq the arm's joint-space inertia
    (pinocchio's CRBA, base level)."""
    v = model.vehicle
    if v.safety.failsafe_joint_damping:
        return tuple(v.safety.failsafe_joint_damping)
    pm = model.pin_model
    q = pin.neutral(pm)
    q[7:] = v.q_nominal_rad
    M = pin.crba(pm, pm.createData(), q)
    return tuple(float(M[6 + i, 6 + i]) / JOINT_DAMPING_TAU_S for i in range(model.n))


@dataclass(frozen=True)
class FailsafeCommand:
    mode: str  # "hold" | "land" | "landed"
    thrust_n: float
    tau_B_nm: np.ndarray
    tau_q_nm: np.ndarray


class Failsafe:
    """Engaged at time `t0_s` in state `x0`; `command(t, x)` each step."""

    def __init__(self, model: AmModel, x0: AmState, t0_s: float, gains: FailsafeGains = FailsafeGains()) -> None:
        n = model.n
        if not gains.d_q:
            gains = dataclasses.replace(gains, d_q=joint_damping(model))
        if len(gains.d_q) != n:
            raise ValueError(f"failsafe joint gains need {n} entries")
        self.model, self.g = model, gains
        self.data = model.pin_model.createData()
        self.t0 = t0_s
        self.p_hold = np.array(x0.p_WB, dtype=float)
        b1 = x0.R_WB[:, 0]
        self.R_hold = Rz(float(np.arctan2(b1[1], b1[0])))
        self.mode = "hold"
        self._z_low, self._t_low = np.inf, t0_s  # lowest base height in LAND and when it was reached

    def command(self, t: float, x: AmState) -> FailsafeCommand:
        g, m = self.g, self.model.mass_kg
        p_ref = self.p_hold.copy()
        if t - self.t0 >= g.hold_s:
            self.mode = "land" if self.mode == "hold" else self.mode
            p_ref[2] = self.p_hold[2] - g.descent_mps * (t - self.t0 - g.hold_s)
        R = x.R_WB
        if self.mode == "land":
            if x.p_WB[2] < self._z_low - 0.01:
                self._z_low, self._t_low = x.p_WB[2], t
            elif p_ref[2] < x.p_WB[2] - g.touchdown_gap_m and t - self._t_low > g.touchdown_s:
                self.mode = "landed"
        if self.mode == "landed":
            return FailsafeCommand("landed", 0.0, np.zeros(3), np.zeros(self.model.n))
        grav = generalized_gravity(self.model, self.data, x)  # [f_B; tau_B; tau_q] the actuators must supply
        v_W = R @ x.v_B
        f_W = R @ grav[0:3] + m * (-g.k_p * (x.p_WB - p_ref) - g.k_d * v_W)
        thrust = float(f_W @ R[:, 2])
        # desired attitude: thrust along f_W, heading of the hold pose
        b3 = f_W / np.linalg.norm(f_W)
        b2 = np.cross(b3, self.R_hold[:, 0])
        b2 /= np.linalg.norm(b2)
        R_d = np.column_stack([np.cross(b2, b3), b2, b3])
        e_R = 0.5 * vee(R_d.T @ R - R.T @ R_d)
        tau_B = grav[3:6] - g.k_R * e_R - g.k_w * x.w_B
        tau_q = grav[6:] - np.asarray(g.d_q) * x.qdot
        return FailsafeCommand(self.mode, thrust, tau_B, tau_q)
