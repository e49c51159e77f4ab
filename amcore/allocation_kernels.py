"""`amcore.allocation.Allocation.allocate`'s per-command steps (numba, as amcore.law): PX4's
pseudo-inverse allocation with sequential desaturation, one small kernel per step of
ControlAllocationSequentialDesaturation (amcore.allocation's docstring lists them). Its
readable reference is tests/amcore/reference_allocation.py; tests/amcore/test_allocation_kernels.py
compares the two.

The rotor table's constants travel in one array (`constants`: the mix's roll, pitch, yaw and
thrust columns, each rotor's least output, the normalized effectiveness rows, each rotor's
most thrust); `allocate` writes the outputs, the allocated and the unallocated control,
whether it desaturated and the rotor thrusts into one array. `_min` and `_max` keep their
first argument on ties, as Python's min and max do. Imported at an `Allocation`'s first
allocation: the pure modules that only read its scales do not load numba. numba's
cache keys each kernel on its own and its callees' files (amcore.jit).
"""
from __future__ import annotations

import numpy as np

from .jit import kernel

# rows of the constants array (each `count` long): the mix's columns, the least outputs, the
# normalized effectiveness rows of roll, pitch, yaw and thrust, each rotor's most thrust [N]
ROLL, PITCH, YAW, THRUST, OUT_MIN, EFF, F_MAX = 0, 1, 2, 3, 4, 5, 9
N_ROWS = 10


@kernel
def _max(a, b):
    return b if b > a else a


@kernel
def _min(a, b):
    return b if b < a else a


@kernel
def gain(v, out, out_min, hi, weak):
    """computeDesaturationGain: k_min + k_max over the outputs outside [min, hi]."""
    k_min = k_max = 0.0
    for i in range(out.shape[0]):
        if abs(v[i]) < weak:
            continue
        if out[i] < out_min[i]:
            k = (out_min[i] - out[i]) / v[i]
            k_min, k_max = _min(k_min, k), _max(k_max, k)
        if out[i] > hi:
            k = (hi - out[i]) / v[i]
            k_min, k_max = _min(k_min, k), _max(k_max, k)
    return k_min + k_max


@kernel
def desaturate(out, v, out_min, hi, weak, thrust_down_only):
    """desaturateActuators along v, in place; with thrust_down_only, a move that would raise
    the thrust is not made."""
    g = gain(v, out, out_min, hi, weak)
    if thrust_down_only and g > 0.0:
        return
    for i in range(out.shape[0]):
        out[i] = out[i] + g * v[i]
    g = 0.5 * gain(v, out, out_min, hi, weak)
    for i in range(out.shape[0]):
        out[i] = out[i] + g * v[i]


@kernel
def mix_and_desaturate(c, roll, pitch, yaw, thrust, hi, weak, yaw_margin, result):
    """`allocate` up to the rotor thrusts: the outputs, the allocated and the unallocated
    control, whether it desaturated."""
    n = c.shape[1]
    r, p, y, t, lo = c[ROLL], c[PITCH], c[YAW], c[THRUST], c[OUT_MIN]
    out = np.empty(n)
    inside = True
    for i in range(n):
        out[i] = roll * r[i] + pitch * p[i] + thrust * t[i]
        full = out[i] + yaw * y[i]
        result[i] = full
        if not (out[i] >= lo[i] and out[i] <= hi and full >= lo[i] and full <= hi):
            inside = False
    if inside:  # inside the limits with and without yaw: every desaturation gain below is zero
        result[n + 8] = 0.0
        return
    desaturate(out, t, lo, hi, weak, True)
    desaturate(out, r, lo, hi, weak, False)
    desaturate(out, p, lo, hi, weak, False)
    for i in range(n):
        out[i] = out[i] + yaw * y[i]  # mixYaw
    lo_min = lo[0]
    for i in range(1, n):
        lo_min = _min(lo_min, lo[i])
    desaturate(out, y, lo, hi + (hi - lo_min) * yaw_margin, weak, False)
    desaturate(out, t, lo, hi, weak, True)
    for i in range(n):
        result[i] = _min(_max(out[i], lo[i]), hi)
    request = (roll, pitch, yaw, thrust)
    for a in range(4):
        s = 0.0
        for i in range(n):
            s += c[EFF + a, i] * result[i]
        result[n + a] = s
        result[n + 4 + a] = request[a] - s
    result[n + 8] = 1.0


@kernel
def rotor_thrusts(c, result):
    """Each rotor's thrust [N]: its output times its most thrust, after the outputs."""
    n = c.shape[1]
    for i in range(n):
        result[n + 9 + i] = result[i] * c[F_MAX, i]


@kernel
def allocate(c, roll, pitch, yaw, thrust, hi, weak, yaw_margin, result):
    """Outputs for normalized (roll, pitch, yaw) torque and thrust (mixAirmodeDisabled) into
    result: the outputs (count), the allocated and the unallocated control (4 each), 1.0 if it
    desaturated (else the request is met exactly and the two middle parts are unset), then
    the rotor thrusts [N] the outputs command (count; `rotor_thrusts`)."""
    mix_and_desaturate(c, roll, pitch, yaw, thrust, hi, weak, yaw_margin, result)
    rotor_thrusts(c, result)


def constants(mix_columns, out_min, effectiveness_rows, thrust_max_n) -> np.ndarray:
    """The (N_ROWS, count) constants array of `allocate`."""
    return np.vstack([np.array(mix_columns, dtype=float), np.array(out_min, dtype=float)[None, :],
                      np.array(effectiveness_rows, dtype=float), np.array(thrust_max_n, dtype=float)[None, :]])
