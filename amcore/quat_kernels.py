"""Unit quaternions (w, x, y, z) in compiled kernels (numba; pure math, no I/O): the helpers
the estimator (amcore.estimator), the devices (simulator.device_kernels) and the emulated
autopilot (simulator.fc_kernels) share.

Each takes quaternions and vectors as 4- or 3-sequences (a tuple or a 1-D array) and returns a
tuple, except `rotation` (a (3, 3) array). A Python caller that wants an array wraps the
result in np.array. The expressions are written out term by term, in one order, so that
every caller rounds alike; amcore.jit keys their callers' cache entries on this file.
"""
from __future__ import annotations

import math

import numpy as np

from .jit import kernel


@kernel
def quat_mul(a, b):
    """The Hamilton product a (x) b."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


@kernel
def quat_conj(q):
    """The conjugate: the inverse of a unit quaternion."""
    return (q[0], -q[1], -q[2], -q[3])


@kernel
def quat_normalized(q):
    w, x, y, z = q
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return (w / n, x / n, y / n, z / n)


@kernel
def quat_canonical(q):
    """The same rotation with w >= 0."""
    return (q[0], q[1], q[2], q[3]) if q[0] >= 0.0 else (-q[0], -q[1], -q[2], -q[3])


@kernel
def quat_exp(d):
    """The unit quaternion of rotation vector d [rad] (first order below 1e-12 rad)."""
    a = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    if a < 1e-12:
        return (1.0, 0.5 * d[0], 0.5 * d[1], 0.5 * d[2])
    k = math.sin(0.5 * a) / a
    return (math.cos(0.5 * a), k * d[0], k * d[1], k * d[2])


@kernel
def quat_log(q):
    """The rotation vector [rad] of unit quaternion q (the shorter way round)."""
    w = q[0]
    s = 1.0
    if w < 0.0:
        s = -1.0
        w = -w
    n = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if n < 1e-12:
        return (2.0 * s * q[1], 2.0 * s * q[2], 2.0 * s * q[3])
    k = s * 2.0 * math.atan2(n, w) / n
    return (k * q[1], k * q[2], k * q[3])


@kernel
def quat_z_axis(q):
    """The third column of the rotation matrix of q: the body's z axis in the world frame."""
    w, x, y, z = q
    return (2.0 * (w * y + x * z), 2.0 * (y * z - w * x), w * w - x * x - y * y + z * z)


@kernel
def rotation(q):
    """The rotation matrix R_WB of unit quaternion q_WB, a (3, 3) array."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return np.array([[1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
                     [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
                     [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)]])
