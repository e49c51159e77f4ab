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
from functools import cached_property, lru_cache

import numpy as np
import pinocchio as pin

from .model import AmModel, DecoupledTerms
from .so3 import hat

_ANGLE_AXES = {"roll": (1, 2, 0), "pitch": (2, 0, 1), "yaw": (0, 1, 2)}  # (i, j, k)
_POS_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class TaskFrame:
    """{t}: rotation R_WT ({w} <- {t}) and origin p_WT in {w} [m]."""

    R_WT: np.ndarray
    p_WT: np.ndarray

    @cached_property
    def H_TW(self) -> np.ndarray:
        """The homogeneous transform {t} <- {w}, [[R_WT^T, -R_WT^T p_WT], [0, 1]] (computed once)."""
        H = np.eye(4)
        H[0:3, 0:3] = self.R_WT.T
        H[0:3, 3] = -self.R_WT.T.dot(self.p_WT)
        return H


@dataclass
class TaskTerms:
    y: np.ndarray  # (n,)
    J_y: np.ndarray  # (n, n+6): ydot = J_y V
    Jdot_y_V: np.ndarray  # (n,)
    Jdot_xi: np.ndarray  # (n,)
    J_e: np.ndarray  # (6, n+6) body Jacobian of {e} (eq. dynamics), LOCAL frame
    J_e_xi: np.ndarray  # (6, n+6) J_e T^-1: {e}'s twist from xi; F_xi = (J_e T^-1)^T F_e
    W: np.ndarray  # (n, 6) rows W_r: ydot_r = W_r J_e V
    H_WE: np.ndarray  # (4, 4) pose of {e} in {w}: [[R_WE, p_WE], [0, 1]]
    Jdot: np.ndarray | None = None  # (n, n+6), only with full=True
    ydot: np.ndarray | None = None  # (n,) J_y V (= J xi), from {e}'s twist

    @cached_property
    def J(self) -> np.ndarray:
        """(n, n+6) J = J_y T^-1 = W J_e T^-1: ydot = J xi (formed on first access; the step
        needs J only through Jdot xi's J T^-1 Tdot V term)."""
        return self.W @ self.J_e_xi

    @property
    def R_WE(self) -> np.ndarray:
        return self.H_WE[0:3, 0:3]

    @property
    def p_WE(self) -> np.ndarray:
        return self.H_WE[0:3, 3]


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
    [0, adot^T R_TE]). The per-component work is on Python floats (3-vectors). The drift in xi,
    Jdot xi = Jdot_y V - J_y T^-1 Tdot V = W (acc_e - J_e T^-1 Tdot V) + Wdot J_e V, is formed the
    same way, from the 6-vector J_e T^-1 Tdot V (J itself is never needed as a matrix).
    """
    pm = model.pin_model
    fid = model.ee_frame_id
    # the frame's placement, recomputed exactly as data.oMf[fid] (half the cost of indexing data.oMf)
    H_WE = pin.updateFramePlacement(pm, data, fid).homogeneous  # a fresh 4x4 array
    J_e = pin.getFrameJacobian(pm, data, fid, pin.LOCAL)
    Jd_e = pin.getFrameJacobianTimeVariation(pm, data, fid, pin.LOCAL)
    V = terms.V
    v0, v1, v2, w0, w1, w2 = J_e.dot(V).tolist()  # {e}'s twist, in {e}
    d0, d1, d2, dw0, dw1, dw2 = Jd_e.dot(V).tolist()
    J_e_xi = J_e.dot(terms.T_inv)
    e0, e1, e2, ew0, ew1, ew2 = J_e_xi.dot(terms.Tdot_V).tolist()  # J_e T^-1 Tdot V
    # classical acceleration of {e}'s origin at zero Vdot (the spatial one misses w x v), in {e}
    a0, a1, a2 = d0 + (w1 * v2 - w2 * v1), d1 + (w2 * v0 - w0 * v2), d2 + (w0 * v1 - w1 * v0)
    x0, x1, x2, xw0, xw1, xw2 = a0 - e0, a1 - e1, a2 - e2, dw0 - ew0, dw1 - ew1, dw2 - ew2  # what Jdot xi weights
    # [R_TE, p_TE] = H_TW H_WE, row by row
    Rl = frame.H_TW.dot(H_WE).tolist()
    (R00, R01, R02, _), (R10, R11, R12, _), (R20, R21, R22, _), _ = Rl
    cols = ((R00, R10, R20), (R01, R11, R21), (R02, R12, R22))  # the axes of {e}, in {t}
    t0, t1, t2 = R00 * w0 + R01 * w1 + R02 * w2, R10 * w0 + R11 * w1 + R12 * w2, R20 * w0 + R21 * w1 + R22 * w2  # w_e in {t}

    y, W, jd, yd, jx, Wd = [], [], [], [], [], []
    for ax in _component_axes(tuple(components)):
        if len(ax) == 1:
            r0, r1, r2, p_k = Rl[ax[0]]
            y.append(p_k)
            W += (r0, r1, r2, 0.0, 0.0, 0.0)
            jd.append(r0 * a0 + r1 * a1 + r2 * a2)
            yd.append(r0 * v0 + r1 * v1 + r2 * v2)
            jx.append(r0 * x0 + r1 * x1 + r2 * x2)
            if full:
                Wd.append([0.0] * 6)
            continue
        i, j, k = ax
        u = u0, u1, u2 = cols[i]  # e_i of {e}, in {t}
        y.append(math.atan2(u[j], u[i]))
        ud = ud0, ud1, ud2 = t1 * u2 - t2 * u1, t2 * u0 - t0 * u2, t0 * u1 - t1 * u0  # w_t x u
        uk, udk = u[k], ud[k]
        D = 1.0 - uk * uk
        g = 2.0 * uk * udk / D**2
        a = [-uk * u0, -uk * u1, -uk * u2]  # e_k - u_k u
        a[k] += 1.0
        b0, b1, b2 = a[0] / D, a[1] / D, a[2] / D
        c0, c1, c2 = ((-udk * u0 - uk * ud0) / D + a[0] * g, (-udk * u1 - uk * ud1) / D + a[1] * g,
                      (-udk * u2 - uk * ud2) / D + a[2] * g)  # adot
        aR = (R00 * b0 + R10 * b1 + R20 * b2, R01 * b0 + R11 * b1 + R21 * b2, R02 * b0 + R12 * b1 + R22 * b2)  # R_TE^T a / D
        adR = (R00 * c0 + R10 * c1 + R20 * c2, R01 * c0 + R11 * c1 + R21 * c2, R02 * c0 + R12 * c1 + R22 * c2)
        W += (0.0, 0.0, 0.0) + aR
        wd = adR[0] * w0 + adR[1] * w1 + adR[2] * w2  # Wdot_r J_e V
        jd.append(aR[0] * dw0 + aR[1] * dw1 + aR[2] * dw2 + wd)
        yd.append(aR[0] * w0 + aR[1] * w1 + aR[2] * w2)
        jx.append(aR[0] * xw0 + aR[1] * xw1 + aR[2] * xw2 + wd)
        if full:
            Wd.append((0.0, 0.0, 0.0) + adR)
    n = len(y)
    W = np.array(W).reshape(n, 6)  # rows W_r (a flat list is the cheapest to convert)
    J_y = W.dot(J_e)
    y_jd = np.array(y + jd + jx + yd)  # y, Jdot_y V, Jdot xi and ydot in one array
    # positional, in field order (y, J_y, Jdot_y_V, Jdot_xi, J_e, J_e_xi, W, H_WE, Jdot, ydot): matching keywords costs more
    out = TaskTerms(y_jd[0:n], J_y, y_jd[n:2 * n], y_jd[2 * n:3 * n], J_e, J_e_xi, W, H_WE, None, y_jd[3 * n:])
    if full:
        if terms.Tdot is None:
            raise ValueError("task_terms(full=True) needs decoupled_terms(full=True)")
        hwe = hat((w0, w1, w2))
        Jd_aug = Jd_e.copy()  # d/dt (R_TE J_e) = R_TE (hat(w_e) J_e + Jdot_e), per 3-row block
        Jd_aug[0:3] += hwe @ J_e[0:3]
        Jd_aug[3:6] += hwe @ J_e[3:6]
        Jdot_y = W @ Jd_aug + np.array(Wd) @ J_e
        out.Jdot = Jdot_y @ terms.T_inv - out.J @ terms.Tdot @ terms.T_inv
    return out
