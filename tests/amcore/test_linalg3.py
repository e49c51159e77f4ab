"""Closed-form 3x3 inverse, solve and smallest singular value against np.linalg."""
from __future__ import annotations

import numpy as np
import pytest

from amcore import linalg3


def _matrix(rng, sigmas):
    U, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    V, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return U @ np.diag(sigmas) @ V.T


def _spectra(rng, count):
    """Well and badly conditioned, nearly rank-deficient by one and two, clustered."""
    for k in range(count):
        kind = k % 4
        if kind == 0:
            s = 10 ** rng.uniform(-2, 1, 3)
        elif kind == 1:
            s = 10 ** rng.uniform(-9, 1, 3)
        elif kind == 2:
            s = 10 ** rng.uniform(-2, 2) * (1 + 10 ** rng.uniform(-9, -1) * rng.normal(size=3))
        else:
            s = np.array([1.0, 10 ** rng.uniform(-12, 0), 10 ** rng.uniform(-12, 0)])
        yield np.abs(s)


def test_inverse_and_solve_match_numpy():
    rng = np.random.default_rng(0)
    for s in _spectra(rng, 400):
        s = np.clip(s, 1e-6, None)  # keep cond <= ~1e8 so both results are meaningful
        A = _matrix(rng, s)
        b = rng.normal(size=3)
        cond = s.max() / s.min()
        Ai = np.linalg.inv(A)
        assert np.abs(linalg3.inv(A) - Ai).max() <= 1e-14 * cond * np.abs(Ai).max()
        x = np.linalg.solve(A, b)
        assert np.abs(linalg3.solve(A, b) - x).max() <= 1e-14 * cond * max(1.0, np.abs(x).max())


def test_sigma_min_matches_svd():
    rng = np.random.default_rng(1)
    for s in _spectra(rng, 2000):
        A = _matrix(rng, s)
        sv = np.linalg.svd(A, compute_uv=False)
        assert abs(linalg3.sigma_min(A) - sv[-1]) <= 1e-12 * sv[0]
    # the working range of Jbar_3 (sigma ~ 0.3..3) to full relative precision
    for _ in range(500):
        A = _matrix(rng, rng.uniform(0.3, 3.0, 3))
        sv = np.linalg.svd(A, compute_uv=False)
        assert abs(linalg3.sigma_min(A) - sv[-1]) <= 1e-13 * sv[-1]


def test_sigma_min_and_solve_is_both():
    rng = np.random.default_rng(3)
    for s in _spectra(rng, 400):
        A = _matrix(rng, np.clip(s, 1e-6, None))
        b = rng.normal(size=3)
        sig, x = linalg3.sigma_min_and_solve(A, b)
        assert sig == linalg3.sigma_min(A)
        assert np.array_equal(x, linalg3.solve(A, b))


def test_exactly_singular():
    A = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    assert linalg3.sigma_min(A) == 0.0
    with pytest.raises(np.linalg.LinAlgError):
        linalg3.inv(A)
    with pytest.raises(np.linalg.LinAlgError):
        linalg3.solve(A, np.ones(3))
    assert linalg3.sigma_min_and_solve(A, np.ones(3)) == (0.0, None)


@pytest.mark.parametrize("n", [1, 2, 4])
def test_other_sizes_fall_back_to_numpy(n):
    rng = np.random.default_rng(n)
    A = rng.normal(size=(n, n)) + 3 * np.eye(n)
    b = rng.normal(size=n)
    assert np.array_equal(linalg3.inv(A), np.linalg.inv(A))
    assert np.array_equal(linalg3.solve(A, b), np.linalg.solve(A, b))
    assert linalg3.sigma_min(A) == np.linalg.svd(A, compute_uv=False)[-1]


def test_symmetric_inverse_matches_numpy():
    """inv_sym reads the upper triangle of a symmetric matrix; as accurate as inv."""
    rng = np.random.default_rng(5)
    for s in _spectra(rng, 400):
        s = np.clip(s, 1e-6, None)
        U, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        A = U @ np.diag(s * rng.choice([-1.0, 1.0], size=3)) @ U.T  # symmetric, possibly indefinite
        A = np.triu(A) + np.triu(A, 1).T  # exactly symmetric
        cond = s.max() / s.min()
        Ai = np.linalg.inv(A)
        assert np.abs(linalg3.inv_sym(A) - Ai).max() <= 1e-14 * cond * np.abs(Ai).max()
    with pytest.raises(np.linalg.LinAlgError):
        linalg3.inv_sym(np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 0.0]]))
    A = rng.normal(size=(4, 4))
    A = A + A.T + 8 * np.eye(4)
    assert np.array_equal(linalg3.inv_sym(A), np.linalg.inv(A))


def test_sigma_min_and_solve_as_list():
    rng = np.random.default_rng(7)
    for n in (3, 2):
        A = rng.normal(size=(n, n)) + 3 * np.eye(n)
        b = rng.normal(size=n)
        s, x = linalg3.sigma_min_and_solve(A, b)
        s2, x2 = linalg3.sigma_min_and_solve(A, b, as_list=True)
        assert s == s2 and isinstance(x2, list) and x2 == x.tolist()
