"""Desired attitude of eq. Rd and its first two time derivatives.

    R_b,d = [b_2d x b_3d, b_2d, b_3d],  b_3d = f_d / |f_d|,
    b_2d = (b_3d x b_1d) / |b_3d x b_1d|,

with b_1d the desired heading. Given f_d and its derivatives (and b_1d's), this returns
R_d, Omega_d = (R_d^T Rdot_d)^vee and Omegadot_d, both in the desired frame. The paper's
w_b,d = R_b^T R_d Omega_d (eq. ori_vel_error) and its derivative are formed in control.
"""
from __future__ import annotations

import numpy as np

from .so3 import cross, hat, vee


def _unit_derivs(a: np.ndarray, ad: np.ndarray, add: np.ndarray):
    """u = a/|a| and its first two derivatives."""
    n = float(np.linalg.norm(a))
    u = a / n
    ud = ad / n - a * (a @ ad) / n**3
    udd = add / n - 2.0 * ad * (a @ ad) / n**3 - a * (ad @ ad + a @ add) / n**3 + 3.0 * a * (a @ ad) ** 2 / n**5
    return u, ud, udd


def desired_attitude(f, fd, fdd, b1, b1d, b1dd):
    """(R_d, Omega_d, Omegadot_d) of eq. Rd. Raises if |f_d| or |b_3d x b_1d| vanishes."""
    if np.linalg.norm(f) < 1e-6:
        raise FloatingPointError("eq. Rd needs |f_d| > 0")
    b3, b3d, b3dd = _unit_derivs(f, fd, fdd)
    c = cross(b3, b1)
    if np.linalg.norm(c) < 1e-6:
        raise FloatingPointError("eq. Rd: heading b_1d is parallel to b_3d")
    cd = cross(b3d, b1) + cross(b3, b1d)
    cdd = cross(b3dd, b1) + 2.0 * cross(b3d, b1d) + cross(b3, b1dd)
    b2, b2d, b2dd = _unit_derivs(c, cd, cdd)
    b1c = cross(b2, b3)
    b1cd = cross(b2d, b3) + cross(b2, b3d)
    b1cdd = cross(b2dd, b3) + 2.0 * cross(b2d, b3d) + cross(b2, b3dd)
    R = np.column_stack([b1c, b2, b3])
    Rd = np.column_stack([b1cd, b2d, b3d])
    Rdd = np.column_stack([b1cdd, b2dd, b3dd])
    Om = vee(R.T @ Rd)
    Omd = vee(R.T @ Rdd - hat(Om) @ hat(Om))
    return R, Om, Omd
