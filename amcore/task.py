"""Task variable y of eq. jacobian_xi, its Jacobians and drift.

y is the end-effector configuration in the AM's task frame {t}: the world frame turned
about z by the AM's heading and placed at a chosen origin, so that N AMs around an
object each work in their own radial plane. Components (see TaskSpec):
- "x", "y", "z": position of {e}'s origin in {t};
- "roll", "pitch", "yaw": the planar angle of {e} about that task axis k. With (i, j, k)
  cyclic and u = R_te e_i (the end-effector's i-axis seen in {t}),
      theta_k = atan2(u_j, u_i),   thetadot_k = a^T w_t,  a = (e_k - u_k u) / (1 - u_k^2),
  which reduces to the plain joint-angle sum for a purely planar motion and stays exact
  when the base rolls out of the plane.

ydot = J_y V = J xi with J = J_y T^-1. The drift used in eq. u3 is
    Jdot xi = Jdot_y V - J_y T^-1 Tdot V,
where Jdot_y V is built from the *classical* acceleration of {e}'s origin (the spatial
acceleration misses w x v).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .model import AmModel, DecoupledTerms
from .so3 import cross, hat

_ANGLE_AXES = {"roll": (1, 2, 0), "pitch": (2, 0, 1), "yaw": (0, 1, 2)}  # (i, j, k)
_POS_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class TaskFrame:
    """{t}: rotation R_WT ({w} <- {t}) and origin p_WT in {w} [m]."""

    R_WT: np.ndarray
    p_WT: np.ndarray


@dataclass
class TaskTerms:
    y: np.ndarray  # (n,)
    J_y: np.ndarray  # (n, n+6): ydot = J_y V
    Jdot_y_V: np.ndarray  # (n,)
    J: np.ndarray  # (n, n+6): ydot = J xi
    Jdot_xi: np.ndarray  # (n,)
    J_e: np.ndarray  # (6, n+6) body Jacobian of {e} (eq. dynamics), LOCAL frame
    p_WE: np.ndarray
    R_WE: np.ndarray
    Jdot: np.ndarray | None = None  # (n, n+6), only with full=True


def angle_of(R_TE: np.ndarray, comp: str) -> float:
    i, j, _ = _ANGLE_AXES[comp]
    return float(np.arctan2(R_TE[j, i], R_TE[i, i]))


def task_terms(model: AmModel, data: pin.Data, terms: DecoupledTerms, frame: TaskFrame,
               components: tuple[str, ...], full: bool = False) -> TaskTerms:
    """Evaluate y, J, Jdot xi at the state of `terms` (which must have just filled `data`)."""
    pm = model.pin_model
    fid = model.ee_frame_id
    oMe = data.oMf[fid]
    R_WE, p_WE = oMe.rotation, oMe.translation
    J_e = pin.getFrameJacobian(pm, data, fid, pin.LOCAL)
    Jd_e = pin.getFrameJacobianTimeVariation(pm, data, fid, pin.LOCAL)
    V = terms.V
    tw = J_e @ V
    v_e, w_e = tw[0:3], tw[3:6]
    dtw = Jd_e @ V
    R_TW = frame.R_WT.T
    R_TE = R_TW @ R_WE
    # classical acceleration of {e}'s origin and angular acceleration at zero Vdot, in {t}
    acc_lin = R_TE @ (cross(w_e, v_e) + dtw[0:3])
    acc_ang = R_TE @ dtw[3:6]
    Jl = R_TE @ J_e[0:3]
    Ja = R_TE @ J_e[3:6]
    w_t = R_TE @ w_e

    n = len(components)
    y = np.empty(n)
    J_y = np.empty((n, V.size))
    Jdot_y_V = np.empty(n)
    if full:
        hwe = hat(w_e)
        Jdl = R_TE @ (hwe @ J_e[0:3] + Jd_e[0:3])
        Jda = R_TE @ (hwe @ J_e[3:6] + Jd_e[3:6])
        Jdot_y = np.empty((n, V.size))
    for r, c in enumerate(components):
        if c in _POS_AXES:
            k = _POS_AXES[c]
            y[r] = (R_TW @ (p_WE - frame.p_WT))[k]
            J_y[r] = Jl[k]
            Jdot_y_V[r] = acc_lin[k]
            if full:
                Jdot_y[r] = Jdl[k]
        else:
            i, j, k = _ANGLE_AXES[c]
            u = R_TE[:, i]
            y[r] = np.arctan2(u[j], u[i])
            D = 1.0 - u[k] ** 2
            ek = np.zeros(3)
            ek[k] = 1.0
            a = (ek - u[k] * u) / D
            ud = cross(w_t, u)
            ad = (-ud[k] * u - u[k] * ud) / D + (ek - u[k] * u) * (2.0 * u[k] * ud[k]) / D**2
            J_y[r] = a @ Ja
            Jdot_y_V[r] = ad @ w_t + a @ acc_ang
            if full:
                Jdot_y[r] = ad @ Ja + a @ Jda
    J = J_y @ terms.T_inv
    Jdot_xi = Jdot_y_V - J @ terms.Tdot_V
    out = TaskTerms(y=y, J_y=J_y, Jdot_y_V=Jdot_y_V, J=J, Jdot_xi=Jdot_xi, J_e=J_e, p_WE=p_WE.copy(), R_WE=R_WE.copy())
    if full:
        if terms.Tdot is None:
            raise ValueError("task_terms(full=True) needs decoupled_terms(full=True)")
        out.Jdot = Jdot_y @ terms.T_inv - J @ terms.Tdot @ terms.T_inv
    return out
