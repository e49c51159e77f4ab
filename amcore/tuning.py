"""What a user needs to tune a vehicle, at its nominal pose (pure: numpy and pinocchio).

- the whole AM's mass and rotational inertia (about its CoM and about the base's origin, body
  axes, arm locked at q_nominal_rad, base level);
- PX4's torque units S (N m per unit of normalized torque, amcore.allocation) and the
  attitude-mode gains in effect beside amcore.px4_gains' rule;
- sigma_min(Jbar_3) at the nominal pose (eq. u3: the joint block of the dynamically consistent
  task Jacobian; the law's singularity guard, [safety].sigma_damping, acts below it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import px4_gains
from .config import VehicleParams, px4_units
from .model import AmModel, AmState, create_data, decoupled_terms
from .task import TaskFrame, task_terms


@dataclass(frozen=True)
class Tuning:
    mass_kg: float
    J_com_kg_m2: np.ndarray  # (3, 3) about the whole AM's CoM, body axes
    J_base_kg_m2: np.ndarray  # (3, 3) about the base's origin, body axes
    torque_units_nm: tuple[float, float, float]  # roll, pitch, yaw
    gains: dict[str, float]  # in effect ([flight_controller])
    rule: dict[str, float]  # amcore.px4_gains' for this vehicle
    sigma_min_J3: float
    Lambda_y_diag: np.ndarray  # task inertia per component at the nominal pose


def nominal_tuning(v: VehicleParams, model: AmModel) -> Tuning:
    pm = model.pin_model
    data = create_data(model)
    q = np.array(v.q_nominal_rad, dtype=float)
    qp = pin.neutral(pm)
    qp[7:] = q
    pin.ccrba(pm, data, qp, np.zeros(pm.nv))
    J_com = np.array(data.Ig.inertia)
    J_base, S = px4_units(v)
    state = AmState(p_WB=np.zeros(3), R_WB=np.eye(3), v_B=np.zeros(3), w_B=np.zeros(3), q=q, qdot=np.zeros_like(q))
    tm = decoupled_terms(model, data, state)
    tk = task_terms(model, data, tm, TaskFrame(np.eye(3), np.zeros(3)), tuple(v.task.components))
    JyMi = tk.J_y @ tm.M_inv
    Lambda_y = np.linalg.inv(JyMi @ tk.J_y.T)
    Jbar = Lambda_y @ JyMi @ tm.T.T  # eq. u3's Jbar = Lambda_y J_y M^-1 T^T
    sigma = float(np.linalg.svd(Jbar[:, 6:], compute_uv=False).min())
    fc = v.flight_controller
    return Tuning(model.mass_kg, J_com, np.array(pin.crba(pm, data, qp)[3:6, 3:6]), S,
                  {k: getattr(fc, k) for k in px4_gains.REFERENCE}, px4_gains.derived_gains(J_base, S), sigma,
                  np.diag(Lambda_y).copy())


def tuning_lines(v: VehicleParams, t: Tuning) -> list[str]:
    """The figures as `am-vehicle` prints them."""
    def diag(J):
        return ", ".join(f"{x:.4f}" for x in np.diag(J))

    lines = [f"whole AM at q_nominal_rad: {t.mass_kg:.3f} kg; inertia about its CoM diag({diag(t.J_com_kg_m2)}) "
             f"kg m^2, about the base's origin diag({diag(t.J_base_kg_m2)}) kg m^2 (body axes roll, pitch, yaw)",
             f"PX4's torque units (attitude mode): one unit of normalized torque is roll {t.torque_units_nm[0]:.3f}, "
             f"pitch {t.torque_units_nm[1]:.3f}, yaw {t.torque_units_nm[2]:.3f} N m",
             f"sigma_min(Jbar_3) at q_nominal_rad: {t.sigma_min_J3:.3f} ([safety].sigma_damping "
             f"{v.safety.sigma_damping:g}: the law damps its inverse below that)",
             "task inertia Lambda_y at q_nominal_rad, per component: "
             + ", ".join(f"{c} {x:.3g}" for c, x in zip(v.task.components, t.Lambda_y_diag))]
    rate = [k for k in px4_gains.REFERENCE if "RATE_P" in k or "RATE_I" in k or "RATE_D" in k or "INT_LIM" in k]
    lines.append("attitude-mode rate gains in effect (amcore.px4_gains' rule for this vehicle where they differ):")
    for k in rate:
        have, rule = t.gains[k], t.rule[k]
        same = abs(have - rule) <= 1e-3 * max(abs(rule), 1e-12)
        lines.append(f"  {k} = {have:.4g}" + ("" if same else f"   (rule: {rule:.4g})"))
    return lines
