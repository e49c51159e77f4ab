"""3-vector and 3x3 arithmetic on tuples of Python floats.

At this size numpy's cost is its per-call overhead (0.5-1.5 us per operation), several
times the arithmetic itself; the control laws' chains of 3-vector operations (eqs.
Com_controller, Rd, ori_controller) therefore run on plain floats. Vectors are 3-tuples
(any 3-sequence is accepted), matrices nested lists as returned by ndarray.tolist().
Each function unpacks its arguments into locals first (mv: a third cheaper than indexing
them term by term).
"""
from __future__ import annotations

Vec = tuple[float, float, float]


def dot(a, b) -> float:
    a0, a1, a2 = a
    b0, b1, b2 = b
    return a0 * b0 + a1 * b1 + a2 * b2


def cross(a, b) -> Vec:
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def add(a, b) -> Vec:
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a0 + b0, a1 + b1, a2 + b2)


def sub(a, b) -> Vec:
    a0, a1, a2 = a
    b0, b1, b2 = b
    return (a0 - b0, a1 - b1, a2 - b2)


def scale(s: float, a) -> Vec:
    a0, a1, a2 = a
    return (s * a0, s * a1, s * a2)


def div(a, s: float) -> Vec:
    a0, a1, a2 = a
    return (a0 / s, a1 / s, a2 / s)


def mv(M, x) -> Vec:
    """M x."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = M
    x0, x1, x2 = x
    return (m00 * x0 + m01 * x1 + m02 * x2, m10 * x0 + m11 * x1 + m12 * x2, m20 * x0 + m21 * x1 + m22 * x2)


def mtv(M, x) -> Vec:
    """M^T x."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = M
    x0, x1, x2 = x
    return (m00 * x0 + m10 * x1 + m20 * x2, m01 * x0 + m11 * x1 + m21 * x2, m02 * x0 + m12 * x1 + m22 * x2)


def cols_mv(c0, c1, c2, x) -> Vec:
    """[c0 c1 c2] x for a matrix given by its columns."""
    a0, a1, a2 = c0
    b0, b1, b2 = c1
    d0, d1, d2 = c2
    x0, x1, x2 = x
    return (a0 * x0 + b0 * x1 + d0 * x2, a1 * x0 + b1 * x1 + d1 * x2, a2 * x0 + b2 * x1 + d2 * x2)


def vee_RtX(R_cols, X_cols) -> Vec:
    """vee(R^T X) (eq. hat's inverse, antisymmetric part) for 3x3 matrices given by their
    columns: (R^T X)_ij = r_i . x_j and vee(S) = (S21 - S12, S02 - S20, S10 - S01) / 2."""
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = R_cols
    (p0, p1, p2), (q0, q1, q2), (r0, r1, r2) = X_cols
    return (0.5 * ((c0 * q0 + c1 * q1 + c2 * q2) - (b0 * r0 + b1 * r1 + b2 * r2)),
            0.5 * ((a0 * r0 + a1 * r1 + a2 * r2) - (c0 * p0 + c1 * p1 + c2 * p2)),
            0.5 * ((b0 * p0 + b1 * p1 + b2 * p2) - (a0 * q0 + a1 * q1 + a2 * q2)))
