"""Control allocation from the rotors' effectiveness matrix, as PX4's control_allocator does
(pure: numpy for set-up, Python floats per step).

The rotor table (`amcore.rotors.RotorParams`, PX4's CA_ROTORn_*) and its effectiveness matrix
B (6 x n: the base wrench per newton of each rotor's thrust, `amcore.rotors.effectiveness`, as
ActuatorEffectivenessRotors builds it) are the geometry this module allocates over.

What the paper's law asks for is the thrust T along z_B and the body torque tau_B (eq. u3 and
eq. ori_controller give them); the lateral force is held at zero. The allocation follows
ControlAllocationPseudoInverse and ControlAllocationSequentialDesaturation (MC_AIRMODE = 0):

1. mix = pinv(B) over the control axes (roll, pitch, yaw torque, F_x, F_y, F_z): where the
   rotors can make lateral force (canted rotors) the pseudo-inverse solves for zero of it;
   where they cannot (all axes parallel), those rows are zero and change nothing. It is
   computed in exact rational arithmetic and rounded once (`pinv_exact`), not by LAPACK:
   numpy's SVD gives last bits that depend on the BLAS kernel the CPU selects (OpenBLAS's
   SkylakeX and Haswell kernels differ by ~2e-14 on am4dof's mix), and the mix reaches the
   attitude-mode gains the loader derives (so the scenario fingerprint) and every step of
   the flight, which must be the same on every host.
2. The mix is normalized as PX4 normalizes it: roll and pitch by one scale such that a unit
   command moves a quad X's rotors by +-0.707 of their range, yaw by its largest entry,
   thrust by the mean of its nonzero entries. A normalized command u on an axis is the
   physical torque u * torque_scale_nm (thrust: u * thrust_scale_n).
3. Outputs (rotor thrust / its maximum) start from roll, pitch and thrust; desaturated along
   thrust (only downwards), roll, then pitch; yaw is added last, with 15 % room above full
   output, and desaturated alone (yaw is given up first); then thrust again, only downwards.
   The outputs are clipped to each rotor's [thrust_min/thrust_max, 1].

Torque mode (the companion's thrust and body torque) and the emulated PX4 (attitude mode)
both call `Allocation.allocate`; torque mode converts its physical request with the scales.
Steps 1 and 2 are set-up (numpy, here); step 3, per command, is `amcore.allocation_kernels`
(numba), loaded at the first allocation (or at `kernel_constants`), so that the modules that
only read the scales (the config loader's PX4 gains, the envelope's set-up) do not load
numba. The kernel writes a named record (`allocation_kernels.result_dtype`); `read_result`
turns one into the `AllocationResult` and the rotor thrusts, for `allocate_thrusts` and for a
caller that ran the kernel itself. Step 3's readable reference, the steps above in plain
Python, is tests/amcore/reference_allocation.py.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache

import numpy as np

from .rotors import RotorParams, effectiveness

YAW_MARGIN = 0.15  # ControlAllocationSequentialDesaturation: yaw's room above full output
WEAK_EFFECTIVENESS = 0.2  # computeDesaturationGain ignores actuators weaker than this
_SMALL_MIX = 1e-3  # normalizeControlAllocationMatrix: entries counted as nonzero for roll/pitch
# an axis counts as saturated when its unallocated normalized command exceeds this: PX4's
# ControlAllocator reports a setpoint achieved while |unallocated|^2 < 1e-6 (7 mN m of roll here)
SATURATION_TOL = 1e-3
AXES = ("roll", "pitch", "yaw", "thrust")
_NO_AXES = (False, False, False, False)  # saturated_axes of an allocation that met every axis
_NONE_UNALLOCATED = (0.0, 0.0, 0.0, 0.0)


def frozen_instance(cls, **fields):
    """An instance of the frozen dataclass `cls` with the given fields, as its `__init__`
    leaves it, without that method's per-field `object.__setattr__` (the per-step path,
    whose fields are known to be what the annotations say: here and in the simulator's
    flight controller)."""
    obj = object.__new__(cls)
    obj.__dict__.update(fields)
    return obj


@dataclass(frozen=True)
class AllocationResult:
    """One allocation: outputs (count,) in [min, max]; allocated and unallocated control in
    normalized units (roll, pitch, yaw torque, thrust); saturated_axes: per axis of `AXES`,
    whether its command was not met; saturated if any was."""

    outputs: tuple[float, ...]
    allocated: tuple[float, float, float, float]
    unallocated: tuple[float, float, float, float]
    saturated: bool
    saturated_axes: tuple[bool, bool, bool, bool] = (False, False, False, False)


@dataclass(frozen=True)
class WrenchAllocation:
    """A physical request allocated (torque mode): rotor thrusts [N], the wrench they make
    (F_B [N], tau_B [N m], both in B; F_B's z is the thrust) and the normalized allocation."""

    rotor_thrusts_n: tuple[float, ...]
    force_B_n: tuple[float, float, float]
    tau_B_nm: tuple[float, float, float]
    allocation: AllocationResult

    @property
    def saturated(self) -> bool:
        return self.allocation.saturated

    @property
    def applied_thrust_n(self) -> float:
        return self.force_B_n[2]


class Allocation:
    """PX4's pseudo-inverse allocation with sequential desaturation, airmode off, for any
    rotor table (see the module docstring)."""

    def __init__(self, rotors: RotorParams) -> None:
        self.rotors = rotors
        self.count = rotors.count
        self.B = effectiveness(rotors)  # (6, n) per newton
        self.f_max = np.array(rotors.thrust_max(), dtype=float)
        self.f_min = np.array(rotors.thrust_min(), dtype=float)
        B_out = self.B * self.f_max  # per unit output
        # control axes in PX4's order: roll, pitch, yaw torque, thrust x, y, z
        B_ctrl = np.vstack([B_out[3:6], B_out[0:3]])
        mix = pinv_exact(B_ctrl)  # (n, 6)
        lapack = np.linalg.pinv(B_ctrl)
        if not np.allclose(mix, lapack, rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(lapack).max()))):
            mix = lapack  # a table within rounding of losing an axis: LAPACK's cutoff decides its rank
        mix[np.abs(mix) < 1e-12] = 0.0
        scale = np.ones(6)
        n_rp = [int(np.sum(np.abs(mix[:, k]) > _SMALL_MIX)) for k in (0, 1)]
        rp = max((math.sqrt(math.fsum(x * x for x in mix[:, k].tolist()) / (n / 2.0))
                  for k, n in zip((0, 1), n_rp) if n), default=1.0)
        scale[0] = scale[1] = rp
        scale[2] = float(mix[:, 2].max())
        for k in (5, 4, 3):  # thrust z first: an axis with no actuator takes its scale
            nz = np.abs(mix[:, k]) > np.finfo(np.float32).eps
            scale[k] = math.fsum(np.abs(mix[nz, k]).tolist()) / int(nz.sum()) if nz.any() else scale[5]
        self.mix_full = mix / scale  # (n, 6) outputs per unit normalized command
        # the four axes the law commands: roll, pitch, yaw, thrust z (lateral setpoints are 0)
        self.mix = self.mix_full[:, [0, 1, 2, 5]]
        self.effectiveness_normalized = B_ctrl[[0, 1, 2, 5]] * scale[[0, 1, 2, 5], None]
        self.torque_scale_nm = tuple((1.0 / scale[:3]).tolist())  # physical torque per unit normalized torque
        self.thrust_scale_n = float(1.0 / scale[5])  # physical thrust per unit normalized thrust
        self.out_min = tuple((self.f_min / self.f_max).tolist())
        self.out_max = 1.0
        self.rotor_thrust_max_n = tuple(self.f_max.tolist())  # per rotor [N]
        self._inv_scale = (scale[0], scale[1], scale[2], scale[5])
        self._kernel = None  # amcore.allocation_kernels.allocate, its constants and result, at the first allocation
        self._read = None  # the result record array `read_result` read last, and its fields' views

    def kernel_constants(self) -> np.ndarray:
        """The constants record of `amcore.allocation_kernels.allocate` for this rotor table
        (`allocation_kernels.constants_dtype(count)`, in an array of one), loading the kernel
        module at the first call (numba: the pure modules that only read the scales do not)."""
        if self._kernel is None:
            self._load_kernel()
        return self._c

    def _load_kernel(self) -> None:
        from . import allocation_kernels

        self._c = allocation_kernels.constants(tuple(map(tuple, self.mix.T.tolist())), self.out_min,
                                               tuple(map(tuple, self.effectiveness_normalized.tolist())),
                                               self.rotor_thrust_max_n, self.out_max, WEAK_EFFECTIVENESS, YAW_MARGIN)
        self._result = allocation_kernels.new_result(self.count)
        self._kernel = allocation_kernels.allocate

    def allocate(self, roll: float, pitch: float, yaw: float, thrust: float) -> AllocationResult:
        """Outputs for normalized (roll, pitch, yaw) torque and thrust (mixAirmodeDisabled)."""
        return self.allocate_thrusts(roll, pitch, yaw, thrust)[0]

    def allocate_thrusts(self, roll: float, pitch: float, yaw: float,
                         thrust: float) -> tuple[AllocationResult, tuple[float, ...]]:
        """`allocate`, and the rotor thrusts [N] its outputs command (each output times its
        rotor's most thrust)."""
        if self._kernel is None:
            self._load_kernel()
        self._kernel(self._c, roll, pitch, yaw, thrust, self._result)
        return self.read_result(self._result, roll, pitch, yaw, thrust)

    def read_result(self, result: np.ndarray, roll: float, pitch: float, yaw: float,
                    thrust: float) -> tuple[AllocationResult, tuple[float, ...]]:
        """The allocation and the rotor thrusts [N] in a result record
        (`allocation_kernels.result_dtype(count)`, in an array of one) that
        `allocation_kernels.allocate` wrote for the normalized request (roll, pitch, yaw,
        thrust), without running it again: where it did not desaturate, the request is what
        was allocated. The fields are read through views made at the first read of an array
        and kept for the next reads of that array (a field's view costs ~0.1 us); ValueError
        for a record of another rotor count."""
        if self._read is None or self._read[0] is not result:
            if result.shape != (1,) or result.dtype.names is None or result.dtype["outputs"].shape != (self.count,):
                raise ValueError(f"not a result record of {self.count} rotors: {result.dtype} {result.shape}")
            self._read = (result, result["outputs"][0], result["allocated"][0], result["unallocated"][0],
                          result["desaturated"], result["thrusts_n"][0])
        _, outputs, allocated, unallocated, desaturated, thrusts_n = self._read
        out, thrusts = tuple(outputs.tolist()), tuple(thrusts_n.tolist())
        if desaturated.item() == 0.0:
            return frozen_instance(AllocationResult, outputs=out, allocated=(roll, pitch, yaw, thrust),
                                   unallocated=_NONE_UNALLOCATED, saturated=False, saturated_axes=_NO_AXES), thrusts
        u = tuple(unallocated.tolist())
        axes = tuple([abs(x) > SATURATION_TOL for x in u])
        return frozen_instance(AllocationResult, outputs=out, allocated=tuple(allocated.tolist()),
                               unallocated=u, saturated=any(axes), saturated_axes=axes), thrusts

    # ------------------------------------------------------------------ physical units
    def normalized(self, thrust_n: float, tau_B_nm) -> tuple[float, float, float, float]:
        """(roll, pitch, yaw, thrust) normalized commands of a physical request."""
        s = self._inv_scale
        return (tau_B_nm[0] * s[0], tau_B_nm[1] * s[1], tau_B_nm[2] * s[2], thrust_n * s[3])

    def wrench(self, rotor_thrusts_n) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(F_B [N], tau_B [N m]) the given rotor thrusts make: B f."""
        w = (self.B @ np.array(rotor_thrusts_n, dtype=float)).tolist()  # one matmul: ~4x the Python rows' speed
        return (w[0], w[1], w[2]), (w[3], w[4], w[5])

    def allocate_wrench(self, thrust_n: float, tau_B_nm) -> WrenchAllocation:
        """Rotor thrusts for T [N] along +z_B and tau_B [N m] about the base origin, in B, with
        zero lateral force where the geometry allows; exact when feasible, else desaturated
        as the module docstring says. ValueError for a non-finite request."""
        tx, ty, tz = np.asarray(tau_B_nm, dtype=float).tolist()
        thrust_n = float(thrust_n)
        if not (math.isfinite(thrust_n) and math.isfinite(tx + ty + tz)):
            raise ValueError(f"non-finite command: thrust_n = {thrust_n}, tau_B_nm = {[tx, ty, tz]}")
        a, f = self.allocate_thrusts(*self.normalized(thrust_n, (tx, ty, tz)))
        F, tau = self.wrench(f)
        return frozen_instance(WrenchAllocation, rotor_thrusts_n=f, force_B_n=F, tau_B_nm=tau, allocation=a)

    # ------------------------------------------------------------------ authority
    def authority(self, thrust_n: float, tau_B_nm=(0.0, 0.0, 0.0)) -> dict[str, tuple[float, float]]:
        """Per torque axis, the most torque [N m] the allocation adds to the operating point
        (T, tau_B) before a rotor leaves its range, downwards and upwards: {axis: (-lo, +hi)}.
        Along the mix's column, as the allocator moves the rotors (no null-space search).
        Both 0 if the operating point itself is infeasible."""
        c = np.array(self.normalized(thrust_n, tau_B_nm))
        u0 = self.mix @ c
        lo, hi = np.array(self.out_min), self.out_max
        if np.any(u0 < lo - 1e-12) or np.any(u0 > hi + 1e-12):
            return {ax: (0.0, 0.0) for ax in AXES[:3]}
        out = {}
        for k, ax in enumerate(AXES[:3]):
            col = self.mix[:, k]
            up = down = math.inf
            for x, v, m in zip(u0, col, lo):
                if v > 0.0:
                    up, down = min(up, (hi - x) / v), min(down, (x - m) / v)
                elif v < 0.0:
                    up, down = min(up, (m - x) / v), min(down, (x - hi) / v)
            out[ax] = (down * self.torque_scale_nm[k], up * self.torque_scale_nm[k])
        return out


def pinv_exact(A) -> np.ndarray:
    """The Moore-Penrose pseudo-inverse of a small matrix, exact and rounded once to float64:
    the same bits on every CPU and BLAS. Computed in rationals (every float is one) from a full-
    rank factorization A = C F (F: the nonzero rows of A's reduced row echelon form, C: A's
    pivot columns), A+ = F^T (F F^T)^-1 (C^T C)^-1 C^T. Entries below 1e-12 of the largest
    count as zero (a rotor axis computed as cos(pi/2) = 6e-17), as LAPACK's cutoff would."""
    a = np.asarray(A, dtype=float)
    return np.array(_pinv_rows(tuple(map(tuple, a.tolist())), a.shape[1]))  # (n, m)


@lru_cache(maxsize=64)  # an Allocation per vehicle and process, often of the same table
def _pinv_rows(a: tuple[tuple[float, ...], ...], n: int) -> tuple[tuple[float, ...], ...]:
    m = len(a)
    big = max((abs(x) for r in a for x in r), default=0.0)
    rows = [[Fraction(x) if abs(x) > 1e-12 * big else Fraction(0) for x in r] for r in a]
    echelon = [row[:] for row in rows]
    pivots = _eliminate(echelon, n)
    r = len(pivots)
    if r == 0:
        return tuple((0.0,) * m for _ in range(n))
    F = echelon[:r]  # r x n
    C = [[rows[i][c] for c in pivots] for i in range(m)]  # m x r
    Ft, Ct = [list(col) for col in zip(*F)], [list(col) for col in zip(*C)]  # n x r, r x m
    inner = _matmul(_inverse(_matmul(F, Ft)), _inverse(_matmul(Ct, C)))  # (F F^T)^-1 (C^T C)^-1
    return tuple(tuple(float(x) for x in row) for row in _matmul(_matmul(Ft, inner), Ct))


def _matmul(X, Y):
    return [[sum(x * y for x, y in zip(row, col)) for col in zip(*Y)] for row in X]


def _eliminate(rows: list, cols: int) -> list[int]:
    """Gauss-Jordan on `rows` (lists of Fractions, changed in place) over their first `cols`
    columns: the reduced row echelon form, and its pivot columns."""
    pivots: list[int] = []
    for c in range(cols):
        r = len(pivots)
        if r == len(rows):
            break
        k = next((i for i in range(r, len(rows)) if rows[i][c] != 0), None)
        if k is None:
            continue
        rows[r], rows[k] = rows[k], rows[r]
        lead = rows[r][c]
        rows[r] = [x / lead for x in rows[r]]
        for i in range(len(rows)):
            if i != r and rows[i][c] != 0:
                f = rows[i][c]
                rows[i] = [x - f * y for x, y in zip(rows[i], rows[r])]
        pivots.append(c)
    return pivots


def _inverse(M):
    """The inverse of a nonsingular square matrix of Fractions: Gauss-Jordan on [M | I]."""
    r = len(M)
    aug = [list(row) + [Fraction(int(i == j)) for j in range(r)] for i, row in enumerate(M)]
    _eliminate(aug, r)
    return [row[r:] for row in aug]
