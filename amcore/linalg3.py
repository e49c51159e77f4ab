"""Closed-form dense linear algebra for 3x3 matrices, with a generic fallback.

The numpy laws built beside the compiled one solve with small blocks every step (the
baseline's damped IK, amcore.offboard's joint torques for a body torque). np.linalg spends
5-15 us per call on argument handling at this size; the cofactor formulas below take 1-3 us. Any other size
goes to np.linalg unchanged (the task dimension is the arm's joint count).

Accuracy: with singular values s1 >= s2 >= s3, the cofactors carry absolute errors
~ eps s1^2 and det(A) ~ eps s1^2 s2, so the inverse, Cramer's rule and `sigma_min` are as
accurate as LU or an SVD (relative error ~ eps s1 / s3) while s2 is not small against s1.
Where s2 < ~1e-3 s1 (nearly rank-deficient by two) np.linalg takes over; none of the
controller's matrices comes near that. Checked against np.linalg in tests/amcore/test_linalg3.py.
"""
from __future__ import annotations

import math

import numpy as np


def _closed_form(A: np.ndarray, need_e2: bool = True):
    """(|A|_F^2, adj(A) row by row as 9 floats, |adj A|_F^2, det A) as Python floats, or None
    where a 3x3 A is too close to rank one for the cofactors (s2 / s1 < ~1e-3) or A is not 3x3.
    With need_e2=False, |adj A|_F^2 may be returned as None (when det A alone settles the test)."""
    if A.shape != (3, 3):
        return None
    (a, b, c), (d, e, f), (g, h, i) = A.tolist()
    c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g
    c10, c11, c12 = c * h - b * i, a * i - c * g, b * g - a * h
    c20, c21, c22 = b * f - c * e, c * d - a * f, a * e - b * d
    det = a * c00 + b * c01 + c * c02
    e1 = a * a + b * b + c * c + d * d + e * e + f * f + g * g + h * h + i * i
    # det^2 >= 1e-4 e1^3 implies e2 >= s1^2 s2^2 >= 1e-2 s1^4 >= 1e-3 e1^2 (s3 <= s2, e1 <= 3 s1^2):
    # the test below would pass, so an inverse or solve need not form e2
    if need_e2 or det * det < 1e-4 * e1 * e1 * e1:
        # = s1^2 s2^2 + s1^2 s3^2 + s2^2 s3^2
        e2 = (c00 * c00 + c01 * c01 + c02 * c02 + c10 * c10 + c11 * c11 + c12 * c12
              + c20 * c20 + c21 * c21 + c22 * c22)
        if e2 < 1e-6 * e1 * e1:
            return None
    else:
        e2 = None
    return e1, (c00, c10, c20, c01, c11, c21, c02, c12, c22), e2, det


def inv(A: np.ndarray) -> np.ndarray:
    """A^-1; raises np.linalg.LinAlgError if A is singular."""
    cf = _closed_form(A, need_e2=False)
    if cf is None:
        return np.linalg.inv(A)
    _, (a, b, c, d, e, f, g, h, i), _, det = cf
    if det == 0.0:
        raise np.linalg.LinAlgError("Singular matrix")
    s = 1.0 / det
    # a flat tuple and reshape: cheaper than numpy parsing nested lists
    return np.array((a * s, b * s, c * s, d * s, e * s, f * s, g * s, h * s, i * s)).reshape(3, 3)


def inv_sym(A: np.ndarray) -> np.ndarray:
    """A^-1 for a symmetric A, read from its upper triangle; raises np.linalg.LinAlgError if A
    is singular. Its cofactor matrix is symmetric too: 6 cofactors instead of inv's 9, with
    the same rank test and accuracy."""
    if A.shape != (3, 3):
        return np.linalg.inv(A)
    (a, b, c), (_, e, f), (_, _, i) = A.tolist()
    c00, c01, c02 = e * i - f * f, f * c - b * i, b * f - e * c
    c11, c12, c22 = a * i - c * c, b * c - a * f, a * e - b * b
    det = a * c00 + b * c01 + c * c02
    e1 = a * a + e * e + i * i + 2.0 * (b * b + c * c + f * f)
    if det * det < 1e-4 * e1 * e1 * e1:  # see _closed_form
        e2 = c00 * c00 + c11 * c11 + c22 * c22 + 2.0 * (c01 * c01 + c02 * c02 + c12 * c12)
        if e2 < 1e-6 * e1 * e1:
            return np.linalg.inv(A)
    if det == 0.0:
        raise np.linalg.LinAlgError("Singular matrix")
    s = 1.0 / det
    c00, c01, c02, c11, c12, c22 = c00 * s, c01 * s, c02 * s, c11 * s, c12 * s, c22 * s
    return np.array((c00, c01, c02, c01, c11, c12, c02, c12, c22)).reshape(3, 3)


def solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with A x = b (b a vector); raises np.linalg.LinAlgError if A is singular."""
    cf = _closed_form(A, need_e2=False)
    if cf is None:
        return np.linalg.solve(A, b)
    _, adj, _, det = cf
    if det == 0.0:
        raise np.linalg.LinAlgError("Singular matrix")
    return np.array(_adj_solve(adj, det, b.tolist()))


def _adj_solve(adj, det: float, b) -> tuple[float, float, float]:
    """adj(A) b / det on Python floats (adj row by row as 9 floats)."""
    a, bb, c, d, e, f, g, h, i = adj
    b0, b1, b2 = b
    return ((a * b0 + bb * b1 + c * b2) / det, (d * b0 + e * b1 + f * b2) / det, (g * b0 + h * b1 + i * b2) / det)


def sigma_min_and_solve(A: np.ndarray, b: np.ndarray, as_list: bool = False) -> tuple[float, np.ndarray | None]:
    """(sigma_min(A), A^-1 b) sharing one adjugate; A^-1 b is None if A is singular, a list of
    Python floats with as_list=True."""
    cf = _closed_form(A)
    if cf is None:
        try:
            x = np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            x = None
        return float(np.linalg.svd(A, compute_uv=False)[-1]), (x.tolist() if as_list and x is not None else x)
    _, adj, _, det = cf
    if det == 0.0:
        return 0.0, None
    x = _adj_solve(adj, det, b.tolist())
    return _sigma_min(A, cf), (list(x) if as_list else np.array(x))


def sigma_min(A: np.ndarray) -> float:
    """Smallest singular value of A.

    For 3x3: the smallest root lambda_3 of det(lambda I - A A^T) = lambda^3 - e1 lambda^2 +
    e2 lambda - e3, with e1 = |A|_F^2, e2 = |adj A|_F^2, e3 = det(A)^2, all formed from A
    (never from A A^T, so a small sigma_min keeps its accuracy). Newton's iteration from 0
    climbs monotonically to that root: the cubic is increasing and concave below it. The
    root is accepted only where it is well conditioned, p'(lambda_3) >= 1e-2 e2; for a
    nearly repeated smallest singular value (and s2 << s1) np.linalg.svd decides.
    """
    cf = _closed_form(A)
    if cf is None:
        return float(np.linalg.svd(A, compute_uv=False)[-1])
    return _sigma_min(A, cf)


def _sigma_min(A: np.ndarray, cf) -> float:
    e1, _, e2, det = cf
    e3 = det * det
    if e3 == 0.0:
        return 0.0
    lam = e3 / e2  # Newton's first step from 0
    for _ in range(60):
        dp = (3.0 * lam - 2.0 * e1) * lam + e2
        if dp < 1e-2 * e2:
            break
        step = (((lam - e1) * lam + e2) * lam - e3) / dp
        lam -= step
        if -1e-15 * lam <= step <= 1e-15 * lam:
            return math.sqrt(lam)
    return float(np.linalg.svd(A, compute_uv=False)[-1])
