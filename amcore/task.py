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

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pinocchio as pin

from .model import AmModel, DecoupledTerms
from .so3 import hat
from .vec3 import cross, mtv, mv

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


@lru_cache(maxsize=None)
def _component_axes(components: tuple[str, ...]) -> tuple[tuple[int, ...], ...]:
    """(k,) for a position component, (i, j, k) for a planar angle."""
    return tuple((_POS_AXES[c],) if c in _POS_AXES else _ANGLE_AXES[c] for c in components)


def task_terms(model: AmModel, data: pin.Data, terms: DecoupledTerms, frame: TaskFrame,
               components: tuple[str, ...], full: bool = False) -> TaskTerms:
    """Evaluate y, J, Jdot xi at the state of `terms` (which must have just filled `data`).

    Each component's rate is a weighting of {e}'s body twist: ydot_r = W_r J_e V, with W_r =
    [e_k^T R_TE, 0] for a position and [0, a^T R_TE] for an angle. Its drift is W_r times
    {e}'s classical acceleration at zero Vdot plus Wdot_r J_e V (only angles have Wdot_r:
    [0, adot^T R_TE]). The per-component work is on Python floats (3-vectors).
    """
    pm = model.pin_model
    fid = model.ee_frame_id
    H_WE = data.oMf[fid].homogeneous  # a fresh 4x4 array
    R_WE, p_WE = H_WE[0:3, 0:3], H_WE[0:3, 3]
    J_e = pin.getFrameJacobian(pm, data, fid, pin.LOCAL)
    Jd_e = pin.getFrameJacobianTimeVariation(pm, data, fid, pin.LOCAL)
    V = terms.V
    v0, v1, v2, w0, w1, w2 = J_e.dot(V).tolist()  # {e}'s twist, in {e}
    d0, d1, d2, dw0, dw1, dw2 = Jd_e.dot(V).tolist()
    # classical acceleration of {e}'s origin at zero Vdot (the spatial one misses w x v), in {e}
    acc = (d0 + (w1 * v2 - w2 * v1), d1 + (w2 * v0 - w0 * v2), d2 + (w0 * v1 - w1 * v0))
    R_TE = frame.R_WT.T.dot(R_WE)
    Rl = R_TE.tolist()
    p_TE = frame.R_WT.T.dot(p_WE - frame.p_WT).tolist()
    w_t = mv(Rl, (w0, w1, w2))  # w_e in {t}

    y, W, Wd, jd = [], [], [], []
    for ax in _component_axes(tuple(components)):
        if len(ax) == 1:
            row = Rl[ax[0]]
            y.append(p_TE[ax[0]])
            W += row + [0.0, 0.0, 0.0]
            Wd.append([0.0] * 6)
            jd.append(row[0] * acc[0] + row[1] * acc[1] + row[2] * acc[2])
            continue
        i, j, k = ax
        u = (Rl[0][i], Rl[1][i], Rl[2][i])  # e_i of {e}, in {t}
        y.append(math.atan2(u[j], u[i]))
        ud = cross(w_t, u)
        uk, udk = u[k], ud[k]
        D = 1.0 - uk * uk
        g = 2.0 * uk * udk / D**2
        a = [-uk * u[0], -uk * u[1], -uk * u[2]]  # e_k - u_k u
        a[k] += 1.0
        ad = ((-udk * u[0] - uk * ud[0]) / D + a[0] * g, (-udk * u[1] - uk * ud[1]) / D + a[1] * g,
              (-udk * u[2] - uk * ud[2]) / D + a[2] * g)
        aR = mtv(Rl, (a[0] / D, a[1] / D, a[2] / D))  # R_TE^T a
        adR = mtv(Rl, ad)
        W += (0.0, 0.0, 0.0, aR[0], aR[1], aR[2])
        Wd.append([0.0, 0.0, 0.0, adR[0], adR[1], adR[2]])
        jd.append(aR[0] * dw0 + aR[1] * dw1 + aR[2] * dw2 + (adR[0] * w0 + adR[1] * w1 + adR[2] * w2))
    W = np.array(W).reshape(-1, 6)  # rows W_r (a flat list is the cheapest to convert)
    J_y = W.dot(J_e)
    Jdot_y_V = np.array(jd)
    J = J_y.dot(terms.T_inv)
    Jdot_xi = Jdot_y_V - J.dot(terms.Tdot_V)
    out = TaskTerms(y=np.array(y), J_y=J_y, Jdot_y_V=Jdot_y_V, J=J, Jdot_xi=Jdot_xi, J_e=J_e, p_WE=p_WE, R_WE=R_WE)
    if full:
        if terms.Tdot is None:
            raise ValueError("task_terms(full=True) needs decoupled_terms(full=True)")
        hwe = hat((w0, w1, w2))
        Jd_aug = Jd_e.copy()  # d/dt (R_TE J_e) = R_TE (hat(w_e) J_e + Jdot_e), per 3-row block
        Jd_aug[0:3] += hwe @ J_e[0:3]
        Jd_aug[3:6] += hwe @ J_e[3:6]
        Jdot_y = W @ Jd_aug + np.array(Wd) @ J_e
        out.Jdot = Jdot_y @ terms.T_inv - J @ terms.Tdot @ terms.T_inv
    return out
