"""The rotors' geometry, as PX4's ActuatorEffectivenessRotors describes it (pure: numpy).

A vehicle file's [rotors] table gives one row per rotor (PX4's CA_ROTORn_PX/PY/PZ, AX/AY/AZ,
KM): its position p_i and unit thrust axis a_i in the base frame B (x forward, y left, z up;
origin at the base link's origin), and its signed moment ratio KM_i (> 0 for a ccw rotor). One
newton of its thrust makes the wrench about the base's origin, in B, as
ActuatorEffectivenessRotors::computeEffectivenessMatrix builds it
(src/modules/control_allocator/ActuatorEffectiveness/ActuatorEffectivenessRotors.cpp, PX4 v1.14):

    F_i   = a_i
    tau_i = p_i x a_i - KM_i a_i

so B = [F_i; tau_i] (6 x n) maps rotor thrusts f [N] to the base wrench (F, tau). PX4's FRD
frame and this FLU frame describe the same vectors; the formula holds in either.

The allocation (amcore.allocation), the simulator's rotor forces and the vehicle loader's
checks (amcore.config) are built from these rows alone; this module imports neither.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np


ROTOR_SPINS = ("ccw", "cw")  # seen from above the rotor, looking down its thrust axis
ROTOR_COUNT_RANGE = (4, 16)  # PX4's CA_ROTOR_COUNT allows up to 12; 16 leaves room for coaxial octos
ROTOR_SPACING_MIN_M = 0.01  # two rotors closer than this are one rotor entered twice


@dataclass(frozen=True)
class Rotor:
    """One rotor as PX4's control allocation describes it (CA_ROTORn_PX/PY/PZ, AX/AY/AZ, KM),
    in the base frame B (x forward, y left, z up; origin at the base link's origin, which is
    its centre of mass in the shipped URDFs).

    position_m: where its thrust acts [m] (PX4 PX/PY/PZ, which are FRD); axis: the direction of
    its thrust, normalized when loaded (PX4 AX/AY/AZ); spin: "ccw" or "cw" seen from the side
    the thrust points to; moment_ratio_m: its drag torque per newton of thrust [N m / N] (|KM|;
    PX4's KM is +moment_ratio_m for ccw, - for cw). The drag torque on the base is
    -KM f axis: a ccw rotor yaws the base clockwise. thrust_min_n, thrust_max_n and
    time_constant_s override the [rotors] table's values for this rotor (None: the table's).
    """

    position_m: tuple[float, float, float]
    axis: tuple[float, float, float]
    spin: Literal["ccw", "cw"]  # ROTOR_SPINS
    moment_ratio_m: float
    thrust_min_n: float | None = None
    thrust_max_n: float | None = None
    time_constant_s: float | None = None

    @property
    def km(self) -> float:
        """PX4's CA_ROTORn_KM: signed moment ratio, > 0 for a ccw rotor [m]."""
        return self.moment_ratio_m if self.spin == "ccw" else -self.moment_ratio_m


@dataclass(frozen=True)
class RotorParams:
    """The multirotor's rotors: one `Rotor` row each ([[rotors.rotor]] in a vehicle file),
    with the thrust range and lag every row takes unless it gives its own. The allocation
    (amcore.allocation) and the simulator's rotor forces are built from these rows alone."""

    rotor: tuple[Rotor, ...]
    thrust_max_n: float  # per rotor [N]
    thrust_min_n: float = 0.0
    # First-order lag of each rotor's thrust behind its command [s]; 0 is an ideal actuator.
    # The vehicle file gives the physical value and its source (configs/vehicles/am3dof.toml).
    time_constant_s: float = 0.0

    @property
    def count(self) -> int:
        return len(self.rotor)

    def thrust_min(self) -> tuple[float, ...]:
        """Per rotor, its least thrust [N]."""
        return tuple(self.thrust_min_n if r.thrust_min_n is None else r.thrust_min_n for r in self.rotor)

    def thrust_max(self) -> tuple[float, ...]:
        """Per rotor, its greatest thrust [N]."""
        return tuple(self.thrust_max_n if r.thrust_max_n is None else r.thrust_max_n for r in self.rotor)

    def time_constants(self) -> tuple[float, ...]:
        """Per rotor, its thrust lag [s] (0: ideal)."""
        return tuple(self.time_constant_s if r.time_constant_s is None else r.time_constant_s for r in self.rotor)

    @property
    def lagging(self) -> bool:
        return any(t > 0.0 for t in self.time_constants())

    @property
    def thrust_max_total_n(self) -> float:
        """Sum of the rotors' greatest thrusts [N] (along their own axes)."""
        return float(sum(self.thrust_max()))

    @property
    def thrust_max_z_n(self) -> float:
        """Greatest thrust along z_B [N]: every rotor at its maximum, the cant's share lost."""
        return float(sum(f * r.axis[2] / math.hypot(*r.axis) for f, r in zip(self.thrust_max(), self.rotor)))


def effectiveness(rotors: RotorParams) -> np.ndarray:
    """(6, n) wrench (F_x, F_y, F_z [N], tau_x, tau_y, tau_z [N m]) in B per newton of each
    rotor's thrust (see the module docstring)."""
    cols = []
    for r in rotors.rotor:
        a = np.asarray(r.axis, dtype=float)
        a = a / np.linalg.norm(a)
        p = np.asarray(r.position_m, dtype=float)
        cols.append(np.concatenate([a, np.cross(p, a) - r.km * a]))
    return np.array(cols).T


def table_problem(r: RotorParams) -> tuple[str, str] | None:
    """What makes a rotor table one the allocation cannot use, as (the key under [rotors], why),
    or None: finite rows, unit-able axes, known spins, sane ranges, no rotor entered twice, and
    a layout that makes thrust along +z_B and torque about every body axis (the effectiveness
    matrix's [F_z, tau] rows have full rank 4)."""
    lo_n, hi_n = ROTOR_COUNT_RANGE
    if not lo_n <= r.count <= hi_n:
        return ".rotor", f"expected {lo_n} to {hi_n} rotors, got {r.count}"
    for i, row in enumerate(r.rotor):
        w = f".rotor[{i}]"
        if not all(math.isfinite(x) and abs(x) <= 5.0 for x in row.position_m):
            return f"{w}.position_m", f"must be finite and within 5 m of the base, got {list(row.position_m)}"
        if not all(math.isfinite(x) for x in row.axis) or math.hypot(*row.axis) < 1e-6:
            return f"{w}.axis", f"must be a nonzero finite direction, got {list(row.axis)}"
        if not 0.0 < row.moment_ratio_m <= 1.0:
            return f"{w}.moment_ratio_m", f"must be in (0, 1] m (PX4's default |KM| is 0.05), got {row.moment_ratio_m!r}"
    for i, (f_min, f_max, tau) in enumerate(zip(r.thrust_min(), r.thrust_max(), r.time_constants())):
        own = any(getattr(r.rotor[i], k) is not None for k in ("thrust_min_n", "thrust_max_n", "time_constant_s"))
        w = f".rotor[{i}]" if own else ""
        if not (math.isfinite(f_max) and 0.0 <= f_min < f_max <= 1000.0):
            return w, f"need 0 <= thrust_min_n < thrust_max_n <= 1000 N, got {f_min!r} and {f_max!r}"
        if not 0.0 <= tau <= 1.0:
            return f"{w}.time_constant_s", f"must be in [0, 1] s (0: ideal), got {tau!r}"
    for i in range(r.count):
        for j in range(i):
            d = math.dist(r.rotor[i].position_m, r.rotor[j].position_m)
            if d < ROTOR_SPACING_MIN_M:
                return (f".rotor[{i}].position_m", f"{d * 1e3:.1f} mm from rotor[{j}]: the same rotor entered twice? "
                        f"(rotors at least {ROTOR_SPACING_MIN_M * 1e3:g} mm apart)")
    B = effectiveness(r)
    if not np.all(B[2] > 0.0):
        k = int(np.argmin(B[2]))
        return f".rotor[{k}].axis", f"every rotor must thrust upward (axis z > 0), got {list(r.rotor[k].axis)}"
    s = np.linalg.svd(B[2:6], compute_uv=False)
    if s[-1] < 1e-6 * s[0]:
        _, _, vt = np.linalg.svd(B[2:6].T)
        names = ("thrust along z", "roll torque", "pitch torque", "yaw torque")
        weak = names[int(np.argmax(np.abs(vt[-1])))]
        return ".rotor", (f"this layout cannot make {weak} independently of the other axes "
                          f"(the effectiveness matrix's [F_z, tau] rows have rank < 4)")
    return None
