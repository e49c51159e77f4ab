"""Flight-controller emulation: thrust/torque allocation for an X quadrotor, with limits.

Pure numpy. The simulator never applies a wrench the rotors could not produce: the
controller's (thrust, body torque) is mixed into rotor thrusts, clipped to
[thrust_min_n, thrust_max_n], and the wrench those rotors really make is applied.

Rotor geometry (body frame B: x forward, y left, z up; all rotors thrust along +z_B):

    rotor i sits at azimuth 45 deg + i * 90 deg (i = 0..3: front-left, rear-left,
    rear-right, front-right), at arm_length_m from the CoM, so p_i = d (+-1, +-1, 0)
    with d = arm_length_m / sqrt(2). Its drag torque about +z_B is s_i c f_i with
    s_i = +1, -1, +1, -1 (diagonal rotors spin the same way) and c = yaw_moment_coeff_m.

    [T, tau_x, tau_y, tau_z]^T = A f,   A = [[1, 1, 1, 1], [y_i], [-x_i], [s_i c]]

Saturation priority when the request is infeasible (never silent: `saturated` is set):

    1. total thrust T is kept, clamped only to [count * thrust_min_n, count * thrust_max_n];
    2. roll/pitch torque is kept;
    3. yaw torque is sacrificed first: scaled by the largest factor in [0, 1] that fits;
    4. if even zero yaw does not fit, roll/pitch are scaled together (direction kept),
       then yaw gets whatever still fits.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from amcore.config import RotorParams

_FEASIBILITY_TOL_N = 1e-9  # rotor-thrust slack accepted as "exact" (round-off of A^-1)


@dataclass(frozen=True)
class MixResult:
    """Outcome of one allocation.

    rotor_thrusts_n: (4,) per-rotor thrust [N]; applied_thrust_n: total thrust along +z_B [N];
    applied_tau_B_nm: (3,) body torque the rotors produce [N m]; yaw_scale, roll_pitch_scale:
    fraction of the requested yaw / roll-pitch torque kept (1.0 when feasible);
    saturated: True when the applied wrench differs from the request.
    """

    rotor_thrusts_n: np.ndarray
    applied_thrust_n: float
    applied_tau_B_nm: np.ndarray
    saturated: bool
    yaw_scale: float = 1.0
    roll_pitch_scale: float = 1.0


@dataclass(frozen=True)
class JointTorqueResult:
    """Joint torques after limiting: applied_nm (n,) [N m]; saturated if any was clipped."""

    applied_nm: np.ndarray
    saturated: bool


@dataclass(frozen=True)
class QuadMixer:
    """Allocation of an X quadrotor (see module docstring); build with `QuadMixer.from_rotors`."""

    rotors: RotorParams
    A: np.ndarray = field(repr=False)  # (4, 4) rotor thrusts -> [T, tau_x, tau_y, tau_z]
    A_inv: np.ndarray = field(repr=False)
    p_B_rotors_m: np.ndarray = field(repr=False)  # (4, 3) rotor positions in B
    spin: np.ndarray = field(repr=False)  # (4,) sign of each rotor's drag torque about +z_B
    A_inv_rows: tuple[tuple[float, ...], ...] = field(repr=False, default=())  # A_inv as floats (per-step path)
    A_rows: tuple[tuple[float, ...], ...] = field(repr=False, default=())  # A as floats (per-step path)

    @staticmethod
    def from_rotors(rotors: RotorParams) -> "QuadMixer":
        if rotors.count != 4 or rotors.layout != "x":
            raise ValueError(
                f"QuadMixer supports count = 4, layout = 'x' only; got count = {rotors.count}, "
                f"layout = '{rotors.layout}'"
            )
        if not 0.0 <= rotors.thrust_min_n < rotors.thrust_max_n:
            raise ValueError(f"need 0 <= thrust_min_n < thrust_max_n, got {rotors.thrust_min_n}, {rotors.thrust_max_n}")
        azimuth = np.deg2rad(45.0 + 90.0 * np.arange(4))
        p = rotors.arm_length_m * np.stack([np.cos(azimuth), np.sin(azimuth), np.zeros(4)], axis=1)
        spin = np.array([1.0, -1.0, 1.0, -1.0])
        A = np.stack([np.ones(4), p[:, 1], -p[:, 0], spin * rotors.yaw_moment_coeff_m])
        A_inv = np.linalg.inv(A)
        return QuadMixer(rotors=rotors, A=A, A_inv=A_inv, p_B_rotors_m=p, spin=spin,
                         A_inv_rows=tuple(map(tuple, A_inv.tolist())), A_rows=tuple(map(tuple, A.tolist())))

    # ------------------------------------------------------------------ allocation
    def rotor_thrusts(self, thrust_n: float, tau_B_nm) -> np.ndarray:
        """Unconstrained rotor thrusts f = A^-1 [T, tau_B] [N] (may violate limits)."""
        return self.A_inv @ np.concatenate([[thrust_n], np.asarray(tau_B_nm, dtype=float)])

    def wrench(self, rotor_thrusts_n) -> tuple[float, np.ndarray]:
        """(T [N], tau_B [N m]) produced by the given rotor thrusts."""
        u = self.A @ np.asarray(rotor_thrusts_n, dtype=float)
        return float(u[0]), u[1:].copy()

    def wrench_floats(self, rotor_thrusts_n) -> tuple[float, list[float]]:
        """`wrench` on Python floats (the per-step path): (T [N], [tau_x, tau_y, tau_z] [N m])."""
        f0, f1, f2, f3 = rotor_thrusts_n
        T, tx, ty, tz = (a0 * f0 + a1 * f1 + a2 * f2 + a3 * f3 for a0, a1, a2, a3 in self.A_rows)
        return T, [tx, ty, tz]

    def feasible(self, thrust_n: float, tau_B_nm) -> bool:
        f = self.rotor_thrusts(thrust_n, tau_B_nm)
        return bool(np.all(f >= self.rotors.thrust_min_n - _FEASIBILITY_TOL_N)
                    and np.all(f <= self.rotors.thrust_max_n + _FEASIBILITY_TOL_N))

    def _max_scale(self, f0: np.ndarray, df: np.ndarray) -> float:
        """Largest s in [0, 1] with f0 + s df inside the rotor limits (f0 must be inside)."""
        lo = self.rotors.thrust_min_n - _FEASIBILITY_TOL_N
        hi = self.rotors.thrust_max_n + _FEASIBILITY_TOL_N
        s = 1.0
        for a, d in zip(f0, df):
            if d > 0.0:
                s = min(s, (hi - a) / d)
            elif d < 0.0:
                s = min(s, (lo - a) / d)
        return max(0.0, s)

    def mix(self, thrust_n: float, tau_B_nm) -> MixResult:
        """Rotor thrusts for (T [N] along +z_B, tau_B [N m] about the base CoM, in B).

        Exact when feasible; otherwise the priority of the module docstring applies and
        `saturated` is True.
        """
        tau = np.asarray(tau_B_nm, dtype=float).reshape(3)
        thrust_n = float(thrust_n)
        tx, ty, tz = tau.tolist()
        if not (math.isfinite(thrust_n) and math.isfinite(tx + ty + tz)):
            raise ValueError(f"non-finite command: thrust_n = {thrust_n}, tau_B_nm = {tau}")
        r = self.rotors
        lo, hi = r.thrust_min_n - _FEASIBILITY_TOL_N, r.thrust_max_n + _FEASIBILITY_TOL_N
        T = min(max(thrust_n, r.count * r.thrust_min_n), r.count * r.thrust_max_n)
        if T == thrust_n:  # the common, feasible case on Python floats (it runs per AM per step)
            f = [a0 * T + (a1 * tx + a2 * ty) + a3 * tz for a0, a1, a2, a3 in self.A_inv_rows]
            if min(f) >= lo and max(f) <= hi:
                f = [min(max(x, r.thrust_min_n), r.thrust_max_n) for x in f]
                return MixResult(rotor_thrusts_n=np.array(f), applied_thrust_n=thrust_n, applied_tau_B_nm=tau.copy(),
                                 saturated=False)
        col = self.A_inv  # columns: effect of unit T, tau_x, tau_y, tau_z on rotor thrusts
        f_T = col[:, 0] * T
        f_rp = col[:, 1] * tau[0] + col[:, 2] * tau[1]
        f_yaw = col[:, 3] * tau[2]
        # f_T is inside the limits because T was clamped; scale roll/pitch, then yaw.
        s_rp = self._max_scale(f_T, f_rp)
        f_base = f_T + s_rp * f_rp
        s_yaw = self._max_scale(f_base, f_yaw)
        f = np.clip(f_base + s_yaw * f_yaw, r.thrust_min_n, r.thrust_max_n)
        T_applied, tau_applied = self.wrench(f)
        return MixResult(rotor_thrusts_n=f, applied_thrust_n=T_applied, applied_tau_B_nm=tau_applied,
                         saturated=True, yaw_scale=s_yaw, roll_pitch_scale=s_rp)


# ---------------------------------------------------------------------- joint torques
def limit_joint_torques(tau_q_nm, tau_max_nm) -> JointTorqueResult:
    """Clip each joint torque to [-tau_max, tau_max] [N m]; report whether any was clipped."""
    tau = np.asarray(tau_q_nm, dtype=float)
    tau_max = np.asarray(tau_max_nm, dtype=float)
    if tau.shape != tau_max.shape:
        raise ValueError(f"got joint torques of shape {tau.shape} for {tau_max.shape[0]} joints")
    t, t_max = tau.tolist(), tau_max.tolist()  # Python floats: a few joints, per AM per step
    if not math.isfinite(sum(t)):
        raise ValueError(f"non-finite joint torque command: {tau}")
    applied = [min(max(x, -m), m) for x, m in zip(t, t_max)]
    return JointTorqueResult(applied_nm=np.array(applied), saturated=applied != t)


# ---------------------------------------------------------------------- derived limits
def max_total_thrust_n(rotors: RotorParams) -> float:
    """Largest total thrust [N] (all rotors at thrust_max_n)."""
    return rotors.count * rotors.thrust_max_n


def hover_thrust_n(mass_kg: float, gravity_mps2: float) -> float:
    """Total thrust [N] that balances the weight of `mass_kg`."""
    return mass_kg * gravity_mps2


def torque_limits_nm(rotors: RotorParams, thrust_n: float) -> np.ndarray:
    """(3,) largest |tau_x|, |tau_y|, |tau_z| [N m] reachable about each body axis alone
    while keeping total thrust `thrust_n` (0 if that thrust itself is infeasible)."""
    mixer = QuadMixer.from_rotors(rotors)
    f_T = mixer.A_inv[:, 0] * thrust_n
    if not mixer.feasible(thrust_n, np.zeros(3)):
        return np.zeros(3)
    # Limits are symmetric by the layout's symmetry; probe with a large request and scale.
    big = 1e6
    return np.array([big * mixer._max_scale(f_T, mixer.A_inv[:, 1 + k] * big) for k in range(3)])


def hover_torque_limits_nm(rotors: RotorParams, mass_kg: float, gravity_mps2: float) -> np.ndarray:
    """(3,) roll/pitch/yaw torque authority [N m] at hover thrust (see `torque_limits_nm`)."""
    return torque_limits_nm(rotors, hover_thrust_n(mass_kg, gravity_mps2))
