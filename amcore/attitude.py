"""Desired attitude of eq. Rd and its first two time derivatives.

    R_b,d = [b_2d x b_3d, b_2d, b_3d],  b_3d = f_d / |f_d|,
    b_2d = (b_3d x b_1d) / |b_3d x b_1d|,

with b_1d the desired heading. Given f_d and its derivatives (and b_1d's), this returns
R_d, Omega_d = (R_d^T Rdot_d)^vee and Omegadot_d, both in the desired frame. The paper's
w_b,d = R_b^T R_d Omega_d (eq. ori_vel_error) and its derivative are formed in control.

The arithmetic is on 3-tuples of Python floats (see amcore.vec3).
"""
from __future__ import annotations

import math

import numpy as np

from .vec3 import Vec


def _unit_derivs(a: Vec, ad: Vec, add: Vec) -> tuple[Vec, Vec, Vec]:
    """u = a/|a| and its first two derivatives."""
    a0, a1, a2 = a
    d0, d1, d2 = ad
    e0, e1, e2 = add
    nn = a0 * a0 + a1 * a1 + a2 * a2
    n = math.sqrt(nn)
    n3 = n * nn
    a_ad = a0 * d0 + a1 * d1 + a2 * d2
    s1 = a_ad / n3
    s2 = (d0 * d0 + d1 * d1 + d2 * d2 + a0 * e0 + a1 * e1 + a2 * e2) / n3 - 3.0 * a_ad * a_ad / (n3 * nn)
    return ((a0 / n, a1 / n, a2 / n),
            (d0 / n - a0 * s1, d1 / n - a1 * s1, d2 / n - a2 * s1),
            (e0 / n - 2.0 * d0 * s1 - a0 * s2, e1 / n - 2.0 * d1 * s1 - a1 * s2, e2 / n - 2.0 * d2 * s1 - a2 * s2))


def _cross_derivs(a: Vec, ad: Vec, add: Vec, b: Vec, bd: Vec, bdd: Vec) -> tuple[Vec, Vec, Vec]:
    """a x b and its first two derivatives."""
    a0, a1, a2 = a
    d0, d1, d2 = ad
    e0, e1, e2 = add
    b0, b1, b2 = b
    f0, f1, f2 = bd
    g0, g1, g2 = bdd
    c = (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
    cd = (d1 * b2 - d2 * b1 + (a1 * f2 - a2 * f1),
          d2 * b0 - d0 * b2 + (a2 * f0 - a0 * f2),
          d0 * b1 - d1 * b0 + (a0 * f1 - a1 * f0))
    cdd = (e1 * b2 - e2 * b1 + 2.0 * (d1 * f2 - d2 * f1) + (a1 * g2 - a2 * g1),
           e2 * b0 - e0 * b2 + 2.0 * (d2 * f0 - d0 * f2) + (a2 * g0 - a0 * g2),
           e0 * b1 - e1 * b0 + 2.0 * (d0 * f1 - d1 * f0) + (a0 * g1 - a1 * g0))
    return c, cd, cdd


def _cross_derivs_const(a: Vec, ad: Vec, add: Vec, b: Vec) -> tuple[Vec, Vec, Vec]:
    """_cross_derivs for a constant b (its derivative terms vanish)."""
    a0, a1, a2 = a
    d0, d1, d2 = ad
    e0, e1, e2 = add
    b0, b1, b2 = b
    return ((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0),
            (d1 * b2 - d2 * b1, d2 * b0 - d0 * b2, d0 * b1 - d1 * b0),
            (e1 * b2 - e2 * b1, e2 * b0 - e0 * b2, e0 * b1 - e1 * b0))


_ZERO = (0.0, 0.0, 0.0)


def desired_attitude_cols(f, fd, fdd, b1, b1d, b1dd):
    """Columns (b_1, b_2, b_3) of R_d, Omega_d and Omegadot_d as 3-tuples (eq. Rd).

    Inputs are 3-sequences of floats. Raises if |f_d| or |b_3d x b_1d| vanishes.
    """
    f0, f1, f2 = f
    if f0 * f0 + f1 * f1 + f2 * f2 < 1e-12:
        raise FloatingPointError("eq. Rd needs |f_d| > 0")
    b3, b3d, b3dd = _unit_derivs(f, fd, fdd)
    if b1d == _ZERO and b1dd == _ZERO:  # a constant heading (the grasp mission's)
        c, cd, cdd = _cross_derivs_const(b3, b3d, b3dd, b1)
    else:
        c, cd, cdd = _cross_derivs(b3, b3d, b3dd, b1, b1d, b1dd)
    c0, c1, c2 = c
    if c0 * c0 + c1 * c1 + c2 * c2 < 1e-12:
        raise FloatingPointError("eq. Rd: heading b_1d is parallel to b_3d")
    b2, b2d, b2dd = _unit_derivs(c, cd, cdd)
    # R_d = [x, y, z] = [b_2d x b_3d, b_2d, b_3d]. Omega_d = vee(R^T Rdot) and Omegadot_d =
    # vee(R^T Rddot - hat(Omega_d)^2) (the square is symmetric, vee drops it), with
    # vee(S) = (S21 - S12, S02 - S20, S10 - S01) / 2. With xdot = ydot x z + y x zdot and
    # xddot = yddot x z + 2 ydot x zdot + y x zddot, the triple products give z.xdot = -x.zdot,
    # y.xdot = -x.ydot, z.xddot = 2 z.(ydot x zdot) - x.zddot, y.xddot = 2 y.(ydot x zdot) - x.yddot,
    # so x's derivatives are never formed.
    y0, y1, y2 = b2
    z0, z1, z2 = b3
    x = x0, x1, x2 = (y1 * z2 - y2 * z1, y2 * z0 - y0 * z2, y0 * z1 - y1 * z0)
    p0, p1, p2 = b2d
    q0, q1, q2 = b3d
    r0, r1, r2 = b2dd
    s0, s1, s2 = b3dd
    v0, v1, v2 = p1 * q2 - p2 * q1, p2 * q0 - p0 * q2, p0 * q1 - p1 * q0  # ydot x zdot
    Om = (0.5 * ((z0 * p0 + z1 * p1 + z2 * p2) - (y0 * q0 + y1 * q1 + y2 * q2)),
          x0 * q0 + x1 * q1 + x2 * q2,
          -(x0 * p0 + x1 * p1 + x2 * p2))
    Omd = (0.5 * ((z0 * r0 + z1 * r1 + z2 * r2) - (y0 * s0 + y1 * s1 + y2 * s2)),
           (x0 * s0 + x1 * s1 + x2 * s2) - (z0 * v0 + z1 * v1 + z2 * v2),
           (y0 * v0 + y1 * v1 + y2 * v2) - (x0 * r0 + x1 * r1 + x2 * r2))
    return (x, b2, b3), Om, Omd


def desired_attitude(f, fd, fdd, b1, b1d, b1dd):
    """(R_d, Omega_d, Omegadot_d) of eq. Rd as arrays. Raises if |f_d| or |b_3d x b_1d| vanishes."""
    args = [x.tolist() if isinstance(x, np.ndarray) else tuple(x) for x in (f, fd, fdd, b1, b1d, b1dd)]
    cols, Om, Omd = desired_attitude_cols(*args)
    return np.array(cols).T.copy(), np.array(Om), np.array(Omd)
