"""Desired attitude eq. Rd and its derivatives; w_b,d's derivative (eq. ori_vel_error)."""
from __future__ import annotations

import numpy as np

from amcore.attitude import desired_attitude
from amcore.so3 import exp_so3, hat, vee


def _poly(t, c):
    return c[0] + c[1] * t + c[2] * t**2 + c[3] * t**3


def _attitude_at(t, cf, psi):
    f = _poly(t, cf)
    fd = cf[1] + 2 * cf[2] * t + 3 * cf[3] * t**2
    fdd = 2 * cf[2] + 6 * cf[3] * t
    ps = psi[0] + psi[1] * t + psi[2] * t**2
    psd = psi[1] + 2 * psi[2] * t
    psdd = 2 * psi[2]
    b1 = np.array([np.cos(ps), np.sin(ps), 0])
    b1d = psd * np.array([-np.sin(ps), np.cos(ps), 0])
    b1dd = psdd * np.array([-np.sin(ps), np.cos(ps), 0]) - psd**2 * b1
    return desired_attitude(f, fd, fdd, b1, b1d, b1dd)


def test_desired_attitude_structure_and_derivatives():
    rng = np.random.default_rng(0)
    h = 1e-4
    for _ in range(20):
        cf = [np.array([0, 0, 17.0]) + rng.normal(size=3) * 3, rng.normal(size=3) * 5,
              rng.normal(size=3) * 5, rng.normal(size=3) * 5]
        psi = rng.normal(size=3)
        R, Om, Omd = _attitude_at(0.0, cf, psi)
        assert np.abs(R.T @ R - np.eye(3)).max() < 1e-12 and np.linalg.det(R) > 0
        f = cf[0]
        assert np.abs(R[:, 2] - f / np.linalg.norm(f)).max() < 1e-12  # b_3d = f_d / |f_d|
        b1 = np.array([np.cos(psi[0]), np.sin(psi[0]), 0])
        assert abs(R[:, 1] @ b1) < 1e-12  # b_2d is orthogonal to the heading
        Rp, Omp, _ = _attitude_at(h, cf, psi)
        Rm, Omm, _ = _attitude_at(-h, cf, psi)
        Om_fd = vee(R.T @ (Rp - Rm) / (2 * h))
        assert np.abs(Om - Om_fd).max() < 1e-6
        assert np.abs(Omd - (Omp - Omm) / (2 * h)).max() < 1e-5


def test_w_bd_derivative_includes_minus_hat_w_term():
    """d/dt (R_b^T R_d Omega_d) = -hat(w_b) w_bd + R_b^T R_d Omegadot_d."""
    rng = np.random.default_rng(1)
    h = 1e-5
    cf = [np.array([1.0, -2, 18]), np.array([2.0, 1, -3]), np.array([-1.0, 3, 2]), np.array([0.5, 0, 1])]
    psi = np.array([0.3, 0.4, -0.2])
    R0 = exp_so3(rng.normal(size=3))
    w = rng.normal(size=3)

    def w_bd(t):
        Rb = R0 @ exp_so3(w * t)
        Rd, Om, _ = _attitude_at(t, cf, psi)
        return Rb.T @ Rd @ Om

    Rd, Om, Omd = _attitude_at(0.0, cf, psi)
    wbd = R0.T @ Rd @ Om
    analytic = -np.cross(w, wbd) + R0.T @ Rd @ Omd
    fd = (w_bd(h) - w_bd(-h)) / (2 * h)
    assert np.abs(analytic - fd).max() < 1e-6
    assert np.abs((R0.T @ Rd @ Omd) - fd).max() > 1e-3  # without the term it is wrong


def _attitude_numpy(f, fd, fdd, b1, b1d, b1dd):
    """eq. Rd on numpy arrays, as first written: unit vectors, cross products, vee(R^T Rdot)."""
    def unit(a, ad, add):
        n = np.linalg.norm(a)
        return (a / n, ad / n - a * (a @ ad) / n**3,
                add / n - 2 * ad * (a @ ad) / n**3 - a * (ad @ ad + a @ add) / n**3 + 3 * a * (a @ ad) ** 2 / n**5)
    b3, b3d, b3dd = unit(f, fd, fdd)
    b2, b2d, b2dd = unit(np.cross(b3, b1), np.cross(b3d, b1) + np.cross(b3, b1d),
                         np.cross(b3dd, b1) + 2 * np.cross(b3d, b1d) + np.cross(b3, b1dd))
    R = np.column_stack([np.cross(b2, b3), b2, b3])
    Rd = np.column_stack([np.cross(b2d, b3) + np.cross(b2, b3d), b2d, b3d])
    Rdd = np.column_stack([np.cross(b2dd, b3) + 2 * np.cross(b2d, b3d) + np.cross(b2, b3dd), b2dd, b3dd])
    Om = vee(R.T @ Rd)
    return R, Om, vee(R.T @ Rdd - hat(Om) @ hat(Om))


def test_compiled_law_matches_numpy_transcription():
    rng = np.random.default_rng(2)
    for _ in range(200):
        args = [np.array([0, 0, 17.0]) + 4 * rng.normal(size=3), 5 * rng.normal(size=3), 5 * rng.normal(size=3)]
        psi, psid, psidd = rng.normal(size=3)
        c, s = np.cos(psi), np.sin(psi)
        args += [np.array([c, s, 0.0]), psid * np.array([-s, c, 0.0]),
                 psidd * np.array([-s, c, 0.0]) - psid**2 * np.array([c, s, 0.0])]
        for got, ref in zip(desired_attitude(*args), _attitude_numpy(*args)):
            assert np.abs(got - ref).max() <= 1e-13 * max(1.0, np.abs(ref).max())
