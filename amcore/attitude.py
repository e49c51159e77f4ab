"""Desired attitude of eq. Rd and its first two time derivatives.

    R_b,d = [b_2d x b_3d, b_2d, b_3d],  b_3d = f_d / |f_d|,
    b_2d = (b_3d x b_1d) / |b_3d x b_1d|,

with b_1d the desired heading. Given f_d and its derivatives (and b_1d's), this returns
R_d, Omega_d = (R_d^T Rdot_d)^vee and Omegadot_d, both in the desired frame. The paper's
w_b,d = R_b^T R_d Omega_d (eq. ori_vel_error) and its derivative are formed by the
orientation law. The equation itself is amcore.law.desired_attitude (compiled).
"""
from __future__ import annotations

import numpy as np

from . import law


def desired_attitude(f, fd, fdd, b1, b1d, b1dd) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R_d, Omega_d, Omegadot_d) of eq. Rd from f_d, its two derivatives and b_1d's (3-vectors).
    Raises FloatingPointError if |f_d| or |b_3d x b_1d| vanishes."""
    args = [np.array(x, dtype=float) for x in (f, fd, fdd, b1, b1d, b1dd)]
    return law.desired_attitude(*args)
