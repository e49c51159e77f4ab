"""amcore.so3: properties of the Python-side rotation helpers (unit norm, inverses, q and -q the
same rotation, R orthonormal), their agreement with pinocchio (Eigen) and with the compiled
amcore.quat_kernels, and each arithmetic form against its literal definition."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from amcore import quat_kernels as qk
from amcore import so3

I3 = np.eye(3)
FLIPS = (I3, np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]))


def _quats(rng, k: int, unit: bool = True):
    for _ in range(k):
        q = rng.normal(size=4)
        yield tuple((q / np.linalg.norm(q)).tolist()) if unit else tuple((q * rng.uniform(0.2, 3.0)).tolist())


def _rotations(rng, k: int):
    for _ in range(k):
        yield so3.exp_so3(rng.normal(size=3) * rng.uniform(0.0, 3.2))


def Rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def Ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


# ----------------------------------------------------------------------------- so(3)
def test_hat_is_the_cross_product_and_vee_its_inverse():
    rng = np.random.default_rng(1)
    for _ in range(50):
        r, x = rng.normal(size=3), rng.normal(size=3)
        np.testing.assert_allclose(so3.hat(r) @ x, np.cross(r, x), atol=1e-14)
        np.testing.assert_array_equal(so3.hat(r), -so3.hat(r).T)
        np.testing.assert_allclose(so3.vee(so3.hat(r)), r, atol=0.0)
        np.testing.assert_allclose(so3.cross(r, x), np.cross(r, x), atol=1e-14)


def test_exp_so3_is_a_rotation_about_its_axis():
    rng = np.random.default_rng(2)
    for _ in range(50):
        w = rng.normal(size=3)
        R = so3.exp_so3(w)
        np.testing.assert_allclose(R @ R.T, I3, atol=1e-14)
        np.testing.assert_allclose(R @ w, w, atol=1e-14)
        np.testing.assert_allclose(R, pin.exp3(w), atol=1e-14)
    np.testing.assert_allclose(so3.exp_so3([0.0, 0.0, 0.7]), so3.Rz(0.7), atol=1e-15)


# ----------------------------------------------------------------------------- quaternion -> R
def test_R_of_a_quaternion_is_orthonormal_and_the_same_for_minus_q():
    rng = np.random.default_rng(3)
    for q in _quats(rng, 300, unit=False):
        R = so3.quat_wxyz_to_R(q)
        np.testing.assert_allclose(R @ R.T, I3, atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
        np.testing.assert_array_equal(so3.quat_wxyz_to_R(tuple(-c for c in q)), R)  # bit for bit
        np.testing.assert_array_equal(so3.quat_wxyz_to_R(np.array(q)), R)  # an array or a sequence alike
        w, x, y, z = so3.quat_wxyz_normalized(q)
        assert w * w + x * x + y * y + z * z == pytest.approx(1.0, abs=1e-15)
        np.testing.assert_array_equal(R, so3.unit_quat_wxyz_to_R((w, x, y, z)))


def test_R_of_a_quaternion_agrees_with_pinocchio_and_the_compiled_rotation():
    rng = np.random.default_rng(4)
    for q in _quats(rng, 300):
        w, x, y, z = q
        R = so3.unit_quat_wxyz_to_R(q)
        np.testing.assert_allclose(R, pin.Quaternion(w, x, y, z).toRotationMatrix(), atol=1e-15)
        np.testing.assert_allclose(R, qk.rotation(np.array(q)), atol=1e-15)
        np.testing.assert_allclose(so3.quat_wxyz_to_R(q), R, atol=1e-15)


def test_the_batched_R_is_the_R_of_each_row():
    rng = np.random.default_rng(5)
    Q = np.array(list(_quats(rng, 64, unit=False)))
    Rs = so3.quats_wxyz_to_R(Q)
    assert Rs.shape == (64, 3, 3)
    for q, R in zip(Q, Rs):
        np.testing.assert_allclose(R, so3.quat_wxyz_to_R(q), atol=1e-15)


# ----------------------------------------------------------------------------- R -> quaternion
def test_R_to_quat_inverts_R_of_quat_with_w_nonnegative():
    rng = np.random.default_rng(6)
    for R0 in _rotations(rng, 300):
        for F in FLIPS:
            R = R0 @ F if np.linalg.det(F) > 0 else R0
            for q in (so3.R_to_quat_wxyz(R), np.array(so3.R_to_quat_wxyz_shepperd(R))):
                assert q[0] >= 0.0
                assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
                np.testing.assert_allclose(so3.quat_wxyz_to_R(q), R, atol=1e-14)
            # the two forms are one rotation, rounded differently
            np.testing.assert_allclose(so3.R_to_quat_wxyz_shepperd(R), so3.R_to_quat_wxyz(R), atol=1e-14)


def test_the_xyzw_quaternion_of_R_is_eigens():
    rng = np.random.default_rng(7)
    for R in _rotations(rng, 200):
        xyzw = np.array(so3.quat_xyzw_of_R(R))
        np.testing.assert_allclose(xyzw, pin.Quaternion(R).coeffs(), atol=1e-15)  # coeffs: x, y, z, w
        wxyz = so3.R_to_quat_wxyz(R)
        sign = 1.0 if xyzw[3] >= 0.0 else -1.0
        np.testing.assert_array_equal(np.array(so3.quat_xyzw_of_wxyz(wxyz)), sign * xyzw)  # reordered, signed


# ----------------------------------------------------------------------------- composing, rotating vectors
def test_the_two_forms_of_rotating_a_vector_are_R_v_and_inverses():
    rng = np.random.default_rng(8)
    for q in _quats(rng, 300):
        v = tuple(rng.normal(size=3).tolist())
        R = so3.unit_quat_wxyz_to_R(q)
        Rv, RTv = R @ np.array(v), R.T @ np.array(v)
        np.testing.assert_allclose(so3.quat_wxyz_rotate(q, v), Rv, atol=1e-14)
        np.testing.assert_allclose(so3.quat_wxyz_R_times(q, v), Rv, atol=1e-14)
        np.testing.assert_allclose(so3.quat_wxyz_rotate_inverse(q, v), RTv, atol=1e-14)
        np.testing.assert_allclose(so3.quat_wxyz_R_T_times(q, v), RTv, atol=1e-14)
        np.testing.assert_allclose(so3.quat_wxyz_rotate_inverse(q, so3.quat_wxyz_rotate(q, v)), v, atol=1e-14)
        minus = tuple(-c for c in q)
        assert so3.quat_wxyz_rotate(minus, v) == so3.quat_wxyz_rotate(q, v)  # q and -q: the same rotation
        # the inverse is the rotation by the conjugate, bit for bit
        assert so3.quat_wxyz_rotate_inverse(q, v) == so3.quat_wxyz_rotate(qk.quat_conj(q), v)


def test_boxplus_turns_q_in_its_own_frame():
    rng = np.random.default_rng(9)
    for q in _quats(rng, 300):
        d = rng.normal(size=3) * rng.uniform(0.0, 2.0)
        p = so3.quat_wxyz_boxplus(q, d.tolist())
        assert p[0] >= 0.0
        assert np.linalg.norm(p) == pytest.approx(1.0, abs=1e-15)
        np.testing.assert_allclose(so3.quat_wxyz_to_R(p), so3.quat_wxyz_to_R(q) @ so3.exp_so3(d), atol=1e-14)
        ref = qk.quat_canonical(qk.quat_normalized(qk.quat_mul(q, qk.quat_exp(d))))
        np.testing.assert_allclose(p, ref, atol=1e-15)
    q = (-0.5, 0.5, 0.5, 0.5)
    assert so3.quat_wxyz_boxplus(q, [0.0, 0.0, 0.0]) == list(q)  # as given, not re-signed


def test_quat_from_x_to_points_x_along_d():
    rng = np.random.default_rng(10)
    for _ in range(200):
        d = rng.normal(size=3) * rng.uniform(0.01, 10.0)
        q = so3.quat_wxyz_from_x_to(d.tolist())
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
        np.testing.assert_allclose(so3.quat_wxyz_to_R(q)[:, 0], d / np.linalg.norm(d), atol=1e-12)
    assert so3.quat_wxyz_from_x_to([0.0, 0.0, 0.0]) == [1.0, 0.0, 0.0, 0.0]
    np.testing.assert_allclose(so3.quat_wxyz_to_R(so3.quat_wxyz_from_x_to([-2.0, 0.0, 0.0]))[:, 0], [-1, 0, 0],
                               atol=1e-15)


# ----------------------------------------------------------------------------- Euler angles
def test_euler_zyx_rebuilds_R_and_the_batch_agrees():
    rng = np.random.default_rng(11)
    qs = list(_quats(rng, 300))
    for q in qs:
        roll, pitch, yaw = so3.euler_zyx_of_quat_wxyz(q)
        np.testing.assert_allclose(so3.Rz(yaw) @ Ry(pitch) @ Rx(roll), so3.unit_quat_wxyz_to_R(q), atol=1e-12)
        assert so3.yaw_of_quat_wxyz(q) == yaw
        assert so3.euler_zyx_of_quat_wxyz(tuple(-c for c in q)) == (roll, pitch, yaw)
    np.testing.assert_allclose(so3.euler_zyx_of_quats_wxyz(np.array(qs)),
                               [so3.euler_zyx_of_quat_wxyz(q) for q in qs], atol=1e-15)
    psi = 2.5
    assert so3.yaw_of_quat_wxyz(so3.R_to_quat_wxyz(so3.Rz(psi))) == pytest.approx(psi, abs=1e-15)
