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
from functools import cached_property, lru_cache

import numpy as np
import pinocchio as pin

from . import law
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

    @cached_property
    def e_y_W(self) -> np.ndarray:
        """{t}'s y axis in {w}, R_WT[:, 1] (computed once)."""
        return self.R_WT[:, 1].copy()

    @classmethod
    def with_transform(cls, R_WT: np.ndarray, p_WT: np.ndarray, H_TW: np.ndarray, e_y_W: np.ndarray) -> "TaskFrame":
        """The frame with its H_TW and e_y_W computed beside it (amcore.law.adapted_reference):
        they become the cached properties' values, as a first read would store them."""
        f = cls(R_WT, p_WT)
        f.__dict__.update(H_TW=H_TW, e_y_W=e_y_W)
        return f


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
def _component_axes(components: tuple[str, ...]) -> tuple[tuple[int, int, int], ...]:
    return tuple((_POS_AXES[c], -1, -1) if c in _POS_AXES else _ANGLE_AXES[c] for c in components)


def component_axes(components: tuple[str, ...]) -> np.ndarray:
    """The components as amcore.law.task reads them: a row (k, -1, -1) for the position along
    {t}'s axis k, (i, j, k) for the planar angle about axis k."""
    return np.array(_component_axes(tuple(components)), dtype=np.int64).reshape(-1, 3)


def task_terms(model: AmModel, data: pin.Data, terms: DecoupledTerms, frame: TaskFrame,
               components: tuple[str, ...], full: bool = False) -> TaskTerms:
    """Evaluate y, J_y, Jdot xi at the state of `terms` (which must have just filled `data`):
    pinocchio's placement and Jacobians of {e}, then the compiled amcore.law.task (each
    component's rate is a weighting of {e}'s body twist, ydot_r = W_r J_e V; derivation there).
    With full=True, Jdot = d/dt (J_y T^-1) is formed too, with numpy.
    """
    pm = model.pin_model
    fid = model.ee_frame_id
    H_WE = pin.updateFramePlacement(pm, data, fid).homogeneous
    J_e = pin.getFrameJacobian(pm, data, fid, pin.LOCAL)
    Jd_e = pin.getFrameJacobianTimeVariation(pm, data, fid, pin.LOCAL)
    V = terms.V
    y, J_y, ydot, Jdot_y_V, Jdot_xi, J_e_xi, W, Wdot = law.task(frame.H_TW, H_WE, J_e, Jd_e, V, terms.T_inv,
                                                         terms.Tdot_V, component_axes(components))
    out = TaskTerms(y=y, J_y=J_y, Jdot_y_V=Jdot_y_V, Jdot_xi=Jdot_xi, J_e=J_e, J_e_xi=J_e_xi, W=W, H_WE=H_WE,
                    ydot=ydot)
    if full:
        if terms.Tdot is None:
            raise ValueError("task_terms(full=True) needs decoupled_terms(full=True)")
        hwe = hat(J_e.dot(V)[3:6])  # {e}'s angular velocity, in {e}
        Jd_aug = Jd_e.copy()  # d/dt (R_TE J_e) = R_TE (hat(w_e) J_e + Jdot_e), per 3-row block
        Jd_aug[0:3] += hwe @ J_e[0:3]
        Jd_aug[3:6] += hwe @ J_e[3:6]
        Jdot_y = W @ Jd_aug + Wdot @ J_e
        out.Jdot = Jdot_y @ terms.T_inv - out.J @ terms.Tdot @ terms.T_inv
    return out
