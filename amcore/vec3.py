"""3-vector and 3x3 arithmetic on tuples of Python floats.

At this size numpy's cost is its per-call overhead (0.5-1.5 us per operation), several
times the arithmetic itself; the control laws' chains of 3-vector operations (eqs.
Com_controller, Rd, ori_controller) therefore run on plain floats. Vectors are 3-tuples
(any 3-sequence is accepted), matrices nested lists as returned by ndarray.tolist().
"""
from __future__ import annotations

Vec = tuple[float, float, float]


def dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def add(a, b) -> Vec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a, b) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def scale(s: float, a) -> Vec:
    return (s * a[0], s * a[1], s * a[2])


def div(a, s: float) -> Vec:
    return (a[0] / s, a[1] / s, a[2] / s)


def mv(M, x) -> Vec:
    """M x."""
    return (M[0][0] * x[0] + M[0][1] * x[1] + M[0][2] * x[2],
            M[1][0] * x[0] + M[1][1] * x[1] + M[1][2] * x[2],
            M[2][0] * x[0] + M[2][1] * x[1] + M[2][2] * x[2])


def mtv(M, x) -> Vec:
    """M^T x."""
    return (M[0][0] * x[0] + M[1][0] * x[1] + M[2][0] * x[2],
            M[0][1] * x[0] + M[1][1] * x[1] + M[2][1] * x[2],
            M[0][2] * x[0] + M[1][2] * x[1] + M[2][2] * x[2])


def cols_mv(c0, c1, c2, x) -> Vec:
    """[c0 c1 c2] x for a matrix given by its columns."""
    return (c0[0] * x[0] + c1[0] * x[1] + c2[0] * x[2],
            c0[1] * x[0] + c1[1] * x[1] + c2[1] * x[2],
            c0[2] * x[0] + c1[2] * x[1] + c2[2] * x[2])


def vee_RtX(R_cols, X_cols) -> Vec:
    """vee(R^T X) (eq. hat's inverse, antisymmetric part) for 3x3 matrices given by their
    columns: (R^T X)_ij = r_i . x_j and vee(S) = (S21 - S12, S02 - S20, S10 - S01) / 2."""
    (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = R_cols
    (p0, p1, p2), (q0, q1, q2), (r0, r1, r2) = X_cols
    return (0.5 * ((c0 * q0 + c1 * q1 + c2 * q2) - (b0 * r0 + b1 * r1 + b2 * r2)),
            0.5 * ((a0 * r0 + a1 * r1 + a2 * r2) - (c0 * p0 + c1 * p1 + c2 * p2)),
            0.5 * ((b0 * p0 + b1 * p1 + b2 * p2) - (a0 * q0 + a1 * q1 + a2 * q2)))
