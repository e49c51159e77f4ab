"""telemetry.kernels: the compiled quaternion has exactly the bits of the literal one
(amcore.so3.R_to_quat_wxyz_shepperd) in every branch; the assembly program copies, converts and
flags as it says."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amcore.so3 import R_to_quat_wxyz_shepperd
from telemetry import kernels


def _q(R) -> np.ndarray:
    q = np.empty(4)
    kernels.quaternion_wxyz(np.ascontiguousarray(R, dtype=float), q)
    return q


def _rotations(rng, k: int):
    for _ in range(k):
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        yield R * np.linalg.det(R)


def test_the_compiled_quaternion_is_the_literal_one_bit_for_bit():
    rng = np.random.default_rng(3)
    flips = [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0])]
    branches = set()
    for R in _rotations(rng, 4000):
        for F in flips:  # the trace's sign and the largest diagonal entry vary: every branch of Shepperd's method
            M = R @ F if np.linalg.det(F) > 0 else R
            d = np.diag(M)
            branches.add(-1 if d.sum() > 0 else int(np.argmax(d)))
            assert _q(M).tobytes() == np.array(R_to_quat_wxyz_shepperd(M)).tobytes()
    assert branches == {-1, 0, 1, 2}
    for M in flips + [np.zeros((3, 3)), np.full((3, 3), np.nan), np.diag([np.inf, 1.0, 1.0])]:
        want = np.array(R_to_quat_wxyz_shepperd(M))
        got = _q(M)
        assert np.array_equal(np.isnan(got), np.isnan(want))
        assert np.array_equal(got[~np.isnan(got)], want[~np.isnan(want)])


def test_assemble_copies_quaternions_and_flags_by_its_program():
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 degrees about z
    rows = []
    for flag in (0.0, -0.0, 2.5, math.nan):
        rows.append(b"abc" + bytes(5) + R.tobytes() + np.array([flag]).tobytes())
    pre = np.frombuffer(b"".join(rows), np.uint8).reshape(4, -1)
    out = np.full((4, 40), 7, np.uint8)  # bytes 35..39: the template, left alone
    program = np.array([[kernels.COPY, 1, 0, 3], [kernels.QUATERNION, 4, 8, 72], [kernels.FLAG, 36, 80, 8]],
                       np.int64)
    kernels.assemble(pre, out, program)
    for r, flag in zip(out, (0, 0, 1, 1)):  # NaN is true, as Python's bool(nan); -0.0 is zero
        assert bytes(r[1:4]) == b"abc" and r[0] == 7 and r[36] == flag and list(r[37:]) == [7, 7, 7]
        assert np.frombuffer(bytes(r[4:36]), np.float64).tolist() == pytest.approx(R_to_quat_wxyz_shepperd(R))
