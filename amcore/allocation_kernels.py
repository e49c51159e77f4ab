"""`amcore.allocation.Allocation.allocate`'s per-command steps (numba, as amcore.law): PX4's
pseudo-inverse allocation with sequential desaturation, one small kernel per step of
ControlAllocationSequentialDesaturation (amcore.allocation's docstring lists them). Its
readable reference is tests/amcore/reference_allocation.py; tests/amcore/test_allocation_kernels.py
compares the two.

The rotor table's constants and the result travel in two numpy records, their fields named
(numba reads and writes them by name), each in an array of one, as simulator.fc_kernels'
`STATE` and `PARAMS`. Their subarrays are a rotor count long, so each count has its own
dtypes (`constants_dtype`, `result_dtype`, made once per count) and numba compiles each
kernel once per count. The constants (`constants`): the mix's roll, pitch, yaw and thrust
columns, each rotor's least output, the normalized effectiveness rows, each rotor's most
thrust, the most output, the effectiveness computeDesaturationGain ignores and yaw's margin
(scalars carried in the record: a call unboxes three floats fewer). The result
(`new_result`), which `allocate` writes: the outputs, the allocated and the unallocated
control, whether it desaturated, the rotor thrusts; `amcore.allocation.Allocation.read_result`
reads it. `pymin` and `pymax` keep their first argument on ties and NaNs, as Python's min
and max do (simulator.fc_kernels takes them too).
Imported at an `Allocation`'s first allocation: the pure modules that only read its scales do
not load numba. numba's cache keys each kernel on its own and its callees' files (amcore.jit).
"""
from __future__ import annotations

import functools

import numpy as np

from .jit import kernel


@functools.lru_cache(maxsize=None)
def constants_dtype(count: int) -> np.dtype:
    """The constants record of `count` rotors: the mix's columns (`roll`, `pitch`, `yaw`,
    `thrust`: outputs per unit normalized command), each rotor's least output `out_min`, the
    normalized effectiveness rows of roll, pitch, yaw and thrust (`effectiveness`, (4, count):
    normalized control per unit output), each rotor's most thrust `thrust_max_n` [N], the
    most output `out_max`, the effectiveness below which computeDesaturationGain ignores a
    rotor (`weak`) and yaw's room above full output (`yaw_margin`, a fraction of the range)."""
    rotors = (np.float64, (count,))
    return np.dtype([("roll", *rotors), ("pitch", *rotors), ("yaw", *rotors), ("thrust", *rotors),
                     ("out_min", *rotors), ("effectiveness", np.float64, (4, count)), ("thrust_max_n", *rotors),
                     ("out_max", np.float64), ("weak", np.float64), ("yaw_margin", np.float64)])


@functools.lru_cache(maxsize=None)
def result_dtype(count: int) -> np.dtype:
    """The result record of `count` rotors: the `outputs` (count,), the `allocated` and the
    `unallocated` control (4,: roll, pitch, yaw, thrust, normalized), `desaturated` (1.0 if it
    desaturated, else 0.0: the request is met exactly and the two middle fields are left as
    they were) and the rotor thrusts `thrusts_n` [N] (count,)."""
    rotors = (np.float64, (count,))
    return np.dtype([("outputs", *rotors), ("allocated", np.float64, (4,)), ("unallocated", np.float64, (4,)),
                     ("desaturated", np.float64), ("thrusts_n", *rotors)])


@kernel
def pymax(a, b):
    """Python's max(a, b) of two floats: a on a tie or a NaN b."""
    return b if b > a else a


@kernel
def pymin(a, b):
    """Python's min(a, b) of two floats: a on a tie or a NaN b."""
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
            k_min, k_max = pymin(k_min, k), pymax(k_max, k)
        if out[i] > hi:
            k = (hi - out[i]) / v[i]
            k_min, k_max = pymin(k_min, k), pymax(k_max, k)
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
def mix_and_desaturate(c, roll, pitch, yaw, thrust, r):
    """`allocate` up to the rotor thrusts, with the constants record c into the result record
    r: the outputs, the allocated and the unallocated control, whether it desaturated."""
    lo, hi, weak = c.out_min, c.out_max, c.weak
    n = lo.shape[0]
    out = np.empty(n)
    inside = True
    for i in range(n):
        out[i] = roll * c.roll[i] + pitch * c.pitch[i] + thrust * c.thrust[i]
        full = out[i] + yaw * c.yaw[i]
        r.outputs[i] = full
        if not (out[i] >= lo[i] and out[i] <= hi and full >= lo[i] and full <= hi):
            inside = False
    if inside:  # inside the limits with and without yaw: every desaturation gain below is zero
        r.desaturated = 0.0
        return
    desaturate(out, c.thrust, lo, hi, weak, True)
    desaturate(out, c.roll, lo, hi, weak, False)
    desaturate(out, c.pitch, lo, hi, weak, False)
    for i in range(n):
        out[i] = out[i] + yaw * c.yaw[i]  # mixYaw
    lo_min = lo[0]
    for i in range(1, n):
        lo_min = pymin(lo_min, lo[i])
    desaturate(out, c.yaw, lo, hi + (hi - lo_min) * c.yaw_margin, weak, False)
    desaturate(out, c.thrust, lo, hi, weak, True)
    for i in range(n):
        r.outputs[i] = pymin(pymax(out[i], lo[i]), hi)
    request = (roll, pitch, yaw, thrust)
    for a in range(4):
        s = 0.0
        for i in range(n):
            s += c.effectiveness[a, i] * r.outputs[i]
        r.allocated[a] = s
        r.unallocated[a] = request[a] - s
    r.desaturated = 1.0


@kernel
def rotor_thrusts(c, r):
    """Each rotor's thrust [N] into the result record r: its output times its most thrust,
    after the outputs."""
    for i in range(r.outputs.shape[0]):
        r.thrusts_n[i] = r.outputs[i] * c.thrust_max_n[i]


@kernel
def allocate(constants, roll, pitch, yaw, thrust, result):
    """Outputs for normalized (roll, pitch, yaw) torque and thrust (mixAirmodeDisabled) into
    result's record (`result_dtype`), with the constants (`constants_dtype`), each an array
    of one record (numba takes an array from Python at a third of a bare record's cost): the
    outputs, the allocated and the unallocated control, `desaturated` (1.0 if it desaturated;
    else 0.0, the request met exactly and the two middle fields unset), then the rotor
    thrusts [N] the outputs command (`rotor_thrusts`)."""
    c, r = constants[0], result[0]
    mix_and_desaturate(c, roll, pitch, yaw, thrust, r)
    rotor_thrusts(c, r)


def new_result(count: int) -> np.ndarray:
    """A zero result record (`result_dtype(count)`), in an array of one."""
    return np.zeros(1, result_dtype(count))


def constants(mix_columns, out_min, effectiveness_rows, thrust_max_n, out_max, weak, yaw_margin) -> np.ndarray:
    """The constants record of `allocate` (`constants_dtype`), in an array of one: mix_columns
    the mix's (roll, pitch, yaw, thrust) columns, each a rotor count long."""
    roll, pitch, yaw, thrust = (np.array(col, dtype=float) for col in mix_columns)
    a = np.zeros(1, constants_dtype(roll.shape[0]))
    c = a[0]
    c["roll"], c["pitch"], c["yaw"], c["thrust"] = roll, pitch, yaw, thrust
    c["out_min"], c["effectiveness"], c["thrust_max_n"] = out_min, effectiveness_rows, thrust_max_n
    c["out_max"], c["weak"], c["yaw_margin"] = out_max, weak, yaw_margin
    return a
