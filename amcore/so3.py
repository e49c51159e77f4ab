"""Small SO(3) helpers: hat/vee (eq. hat), quaternion <-> rotation matrix, elementary rotations."""
from __future__ import annotations

import math

import numpy as np


def hat(r: np.ndarray) -> np.ndarray:
    """Skew-symmetric matrix of r (eq. hat): hat(r) @ x == np.cross(r, x)."""
    x, y, z = r.tolist() if isinstance(r, np.ndarray) else r  # Python floats: 4x faster here
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def vee(S: np.ndarray) -> np.ndarray:
    """Inverse of hat for a skew-symmetric matrix (uses the antisymmetric part)."""
    return 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def quat_wxyz_to_R(qwxyz: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion given as (w, x, y, z); normalises first."""
    w, x, y, z = qwxyz.tolist() if isinstance(qwxyz, np.ndarray) else map(float, qwxyz)  # Python floats
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array((
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    )).reshape(3, 3)  # a flat tuple: cheaper than nested lists


def quat_xyzw_of_R(R: np.ndarray) -> list[float]:
    """Unit quaternion [x, y, z, w] of a rotation matrix, as Eigen (and so pinocchio) builds
    it from a matrix (amcore.law.quaternion_xyzw, compiled)."""
    from . import law  # law imports nothing of so3; imported here to keep so3 light

    return law.quaternion_xyzw(np.asarray(R, dtype=float)).tolist()


def R_to_quat_wxyz(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) with w >= 0 of a rotation matrix (Shepperd's method, on floats)."""
    x, y, z, w = quat_xyzw_of_R(R)
    return np.array([w, x, y, z]) if w >= 0.0 else np.array([-w, -x, -y, -z])


def Rz(psi: float) -> np.ndarray:
    """Rotation about z by psi [rad]."""
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def exp_so3(w: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: rotation exp(hat(w))."""
    th = float(np.linalg.norm(w))
    if th < 1e-12:
        return np.eye(3) + hat(w)
    K = hat(np.asarray(w) / th)
    return np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * (K @ K)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for 3-vectors; np.cross costs ~25x more on this size (axis handling)."""
    a0, a1, a2 = a.tolist() if isinstance(a, np.ndarray) else a  # Python floats: 3x faster
    b0, b1, b2 = b.tolist() if isinstance(b, np.ndarray) else b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
