"""SO(3) on the Python side: hat/vee (eq. hat), rotation matrices, unit quaternions, Euler angles.

Pure math (numpy and math only). The compiled counterparts that kernels call are in
amcore.quat_kernels (numba); these are for Python callers, on Python floats where one value is
converted at a time (numpy costs ~1 us per call at these sizes), on arrays for a log's (N, 4).

Conventions:
- A unit quaternion q_AB is Hamilton's (i j = k) and takes vectors of frame B into frame A,
  as R_AB = R(q_AB) does: R(q) v = q v q^*. q and -q are the same rotation; where a function
  picks one, its docstring says so (w >= 0).
- Order: the project's wire types, sensor frames and telemetry (amlink.types, SensorFrame.
  quat_WB_wxyz) store (w, x, y, z); PyBullet, and Eigen / pinocchio's free-flyer configuration,
  store (x, y, z, w). Every name that takes or gives a quaternion says which (`_wxyz`, `_xyzw`).
- Euler angles are Z-Y-X (R = Rz(yaw) Ry(pitch) Rx(roll)), as PX4's matrix::Eulerf, in rad.
- Frames are those of the quaternion handed in; converting ENU/FLU to PX4's NED/FRD is a
  wire concern (amlink.px4).

Where two functions compute the same quantity with different arithmetic (they differ in the
last bits), both are kept because each feeds numbers a flown vehicle or a log depends on:
`R_to_quat_wxyz` (Eigen's, as the law builds pinocchio's configuration) and
`R_to_quat_wxyz_shepperd` (telemetry's, matched by telemetry.kernels); `quat_wxyz_rotate`
(q v q^*, the MAVLink decoding's) and `quat_wxyz_R_times` (through the entries of R, the
free-running simulator's).
"""
from __future__ import annotations

import math

import numpy as np


# ----------------------------------------------------------------------------- so(3)
def hat(r: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix of r (eq. hat): hat(r) @ x == np.cross(r, x)."""
    x, y, z = r.tolist() if isinstance(r, np.ndarray) else r  # Python floats: 4x faster here
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def vee(S: np.ndarray) -> np.ndarray:
    """Inverse of hat for a skew-symmetric matrix (uses the antisymmetric part)."""
    return 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for 3-vectors; np.cross costs ~25x more on this size (axis handling)."""
    a0, a1, a2 = a.tolist() if isinstance(a, np.ndarray) else a  # Python floats: 3x faster
    b0, b1, b2 = b.tolist() if isinstance(b, np.ndarray) else b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


# ----------------------------------------------------------------------------- rotation matrices
def Rz(psi: float) -> np.ndarray:
    """Rotation about z by psi [rad]."""
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def exp_so3(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: rotation exp(hat(w)), w a rotation vector [rad]."""
    th = float(np.linalg.norm(w))
    if th < 1e-12:
        return np.eye(3) + hat(w)
    K = hat(np.asarray(w) / th)
    return np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * (K @ K)


# ----------------------------------------------------------------------------- quaternion -> R
def quat_wxyz_normalized(q_wxyz) -> tuple[float, float, float, float]:
    """q / |q| for a quaternion (w, x, y, z), on Python floats (as quat_kernels.quat_normalized)."""
    w, x, y, z = q_wxyz
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return (w / n, x / n, y / n, z / n)


def unit_quat_wxyz_to_R(q_wxyz) -> np.ndarray:
    """Rotation matrix R(q) (3, 3) of a quaternion (w, x, y, z) taken as unit: not normalised,
    so a slightly off norm gives a slightly non-orthogonal R (as quat_kernels.rotation)."""
    q = q_wxyz.tolist() if isinstance(q_wxyz, np.ndarray) else q_wxyz  # Python floats
    return np.array(_R_entries(q)).reshape(3, 3)  # a flat tuple: cheaper than nested lists


def _R_entries(q_wxyz) -> tuple[float, ...]:
    """The nine entries of R(q), row by row, of a quaternion (w, x, y, z) taken as unit, on Python floats."""
    w, x, y, z = q_wxyz
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y),
            2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x),
            2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


def quat_wxyz_to_R(qwxyz) -> np.ndarray:
    """Rotation matrix R(q) (3, 3) of a quaternion (w, x, y, z); normalises first."""
    q = qwxyz.tolist() if isinstance(qwxyz, np.ndarray) else map(float, qwxyz)  # Python floats
    return unit_quat_wxyz_to_R(quat_wxyz_normalized(tuple(q)))


def quats_wxyz_to_R(q_wxyz: np.ndarray) -> np.ndarray:
    """quat_wxyz_to_R of each row: (N, 4) quaternions (w, x, y, z), normalised, -> (N, 3, 3)."""
    w, x, y, z = (q_wxyz / np.linalg.norm(q_wxyz, axis=1, keepdims=True)).T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


# ----------------------------------------------------------------------------- R -> quaternion
def quat_xyzw_of_R(R: np.ndarray) -> list[float]:
    """Unit quaternion [x, y, z, w] of a rotation matrix, as Eigen (and so pinocchio) builds
    it from a matrix (amcore.law.quaternion_xyzw, compiled); the sign is Eigen's (w may be < 0)."""
    from . import law  # law imports nothing of so3; imported here to keep so3 light

    return law.quaternion_xyzw(np.asarray(R, dtype=float)).tolist()


def R_to_quat_wxyz(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) with w >= 0 of a rotation matrix: quat_xyzw_of_R's
    (Eigen's arithmetic, compiled), reordered and signed. The form the simulation and the law use."""
    x, y, z, w = quat_xyzw_of_R(R)
    return np.array([w, x, y, z]) if w >= 0.0 else np.array([-w, -x, -y, -z])


def R_to_quat_wxyz_shepperd(R) -> list[float]:
    """Unit quaternion [w, x, y, z], w >= 0, of a 3x3 rotation matrix (numpy or nested lists),
    by Shepperd's method with s = 2 sqrt(1 + the largest of tr, R_ii - ...) and divisions by s.

    The same rotation as R_to_quat_wxyz, rounded differently: the telemetry's form (on Python
    floats, ~5x cheaper than numpy for one matrix; telemetry.kernels.quaternion_wxyz compiles
    this arithmetic and must give the same bits)."""
    (a, b, c), (d, e, f), (g, h, i) = (R.tolist() if hasattr(R, "tolist") else R)
    tr = a + e + i
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (h - f) / s, (c - g) / s, (d - b) / s]
    elif a >= e and a >= i:
        s = 2.0 * math.sqrt(1.0 + a - e - i)
        q = [(h - f) / s, 0.25 * s, (b + d) / s, (c + g) / s]
    elif e >= i:
        s = 2.0 * math.sqrt(1.0 + e - a - i)
        q = [(c - g) / s, (b + d) / s, 0.25 * s, (f + h) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + i - a - e)
        q = [(d - b) / s, (c + g) / s, (f + h) / s, 0.25 * s]
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    k = (1.0 if q[0] >= 0.0 else -1.0) / n
    return [q[0] * k, q[1] * k, q[2] * k, q[3] * k]


def quat_xyzw_of_wxyz(q_wxyz) -> list[float]:
    """The same quaternion in PyBullet's / Eigen's order: (w, x, y, z) -> [x, y, z, w]."""
    w, x, y, z = q_wxyz
    return [x, y, z, w]


# ----------------------------------------------------------------------------- composing, rotating vectors
def quat_wxyz_boxplus(q_wxyz, d) -> list[float]:
    """q (+) d = q (x) Exp(d): q turned by the rotation vector d [rad] in its own (body) frame,
    as a unit quaternion [w, x, y, z] with w >= 0 (q itself, as given, when d is exactly 0)."""
    a = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    if a == 0.0:
        return list(q_wxyz)
    k = math.sin(0.5 * a) / a
    bw, bx, by, bz = math.cos(0.5 * a), k * d[0], k * d[1], k * d[2]
    aw, ax, ay, az = q_wxyz
    w = aw * bw - ax * bx - ay * by - az * bz
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    n = math.sqrt(w * w + x * x + y * y + z * z)
    sgn = 1.0 if w >= 0.0 else -1.0
    return [sgn * w / n, sgn * x / n, sgn * y / n, sgn * z / n]


def quat_wxyz_rotate(q_wxyz, v) -> tuple[float, float, float]:
    """q v q^* = R(q) v for a unit quaternion q (w, x, y, z), on Python floats, as
    v + w t + u x t with u = (x, y, z), t = 2 u x v (no matrix built)."""
    w, x, y, z = q_wxyz
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    return (vx + w * tx + (y * tz - z * ty), vy + w * ty + (z * tx - x * tz), vz + w * tz + (x * ty - y * tx))


def quat_wxyz_rotate_inverse(q_wxyz, v) -> tuple[float, float, float]:
    """q^* v q = R(q)^T v: for q_WB, a vector in W expressed in B; quat_wxyz_rotate by the conjugate."""
    w, x, y, z = q_wxyz
    return quat_wxyz_rotate((w, -x, -y, -z), v)


def quat_wxyz_R_times(q_wxyz, v) -> tuple[float, float, float]:
    """R(q) v for a unit quaternion q (w, x, y, z), through the entries of R (unit_quat_wxyz_to_R),
    row by row, on Python floats."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _R_entries(q_wxyz)
    a, b, c = v
    return (r00 * a + r01 * b + r02 * c, r10 * a + r11 * b + r12 * c, r20 * a + r21 * b + r22 * c)


def quat_wxyz_R_T_times(q_wxyz, v) -> tuple[float, float, float]:
    """R(q)^T v for a unit quaternion q (w, x, y, z), through the entries of R, column by column."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _R_entries(q_wxyz)
    a, b, c = v
    return (r00 * a + r10 * b + r20 * c, r01 * a + r11 * b + r21 * c, r02 * a + r12 * b + r22 * c)


def quat_wxyz_from_x_to(d) -> list[float]:
    """[w, x, y, z] of the shortest rotation taking +x to the direction d (any length; the
    identity for d = 0, a half turn about z for d along -x)."""
    n = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    if n == 0.0:
        return [1.0, 0.0, 0.0, 0.0]
    ux, uy, uz = d[0] / n, d[1] / n, d[2] / n
    w = 1.0 + ux  # q = (1 + x.u, x cross u) normalised
    if w < 1e-9:  # opposite to +x: half turn about z
        return [0.0, 0.0, 0.0, 1.0]
    qx, qy, qz = 0.0, -uz, uy
    m = math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
    return [w / m, qx / m, qy / m, qz / m]


# ----------------------------------------------------------------------------- Euler angles (Z-Y-X)
def yaw_of_quat_wxyz(q_wxyz) -> float:
    """Yaw [rad] of q (w, x, y, z) about the z axis of its outer frame: atan2(R[1, 0], R[0, 0])."""
    w, x, y, z = q_wxyz
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def euler_zyx_of_quat_wxyz(q_wxyz) -> tuple[float, float, float]:
    """(roll, pitch, yaw) [rad] of q (w, x, y, z) with R = Rz(yaw) Ry(pitch) Rx(roll), as PX4's
    matrix::Eulerf; pitch from an argument clipped to [-1, 1]."""
    w, x, y, z = q_wxyz
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    return roll, pitch, yaw_of_quat_wxyz(q_wxyz)


def euler_zyx_of_quats_wxyz(q_wxyz: np.ndarray) -> np.ndarray:
    """euler_zyx_of_quat_wxyz of each row: (N, 4) (w, x, y, z) -> (N, 3) roll, pitch, yaw [rad]."""
    w, x, y, z = q_wxyz.T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=1)
