"""Compiled kernels of telemetry.capture: finishing a batch of binary samples in one call (pure).

The publisher's sender thread wakes every 0.1 s with ~100 pre-samples of each key (a
companion's controller state at 1 kHz); finishing them one Python call at a time cost ~5 us
of CPU per sample in a control loop (the two quaternions ~4 us, the slicing ~1 us). `assemble`
does a whole batch in one call: each output sample is a fixed program of byte copies out of
its pre-sample, quaternions of the rotation matrices in it, and booleans of its numbers.

Compiled and cached on disk as amcore.law is (amcore.jit: numba's cache is keyed on this
file); `warm_up` makes the first call, which amruntime.jitcache.warm runs under its
machine-wide lock and telemetry.wiring at start-up, so no control loop waits for a compile.
"""
from __future__ import annotations

import numpy as np

from amcore.jit import kernel

# what an instruction of a program does: program[i] = (op, destination byte, source byte, bytes)
COPY = 0  # copy `bytes` bytes
QUATERNION = 1  # the unit quaternion (w, x, y, z) (float64[4]) of the row-major 3x3 float64 at the source
FLAG = 2  # one bool byte: the float64 at the source is not 0 (NaN is true, as Python's bool)


@kernel
def quaternion_wxyz(R, q):
    """q = the unit quaternion (w, x, y, z), w >= 0, of a 3x3 rotation matrix R, with exactly
    the arithmetic of amcore.so3.R_to_quat_wxyz_shepperd (the builders' in telemetry.schema), so the same bits."""
    a, b, c = R[0, 0], R[0, 1], R[0, 2]
    d, e, f = R[1, 0], R[1, 1], R[1, 2]
    g, h, i = R[2, 0], R[2, 1], R[2, 2]
    tr = a + e + i
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q[0], q[1], q[2], q[3] = 0.25 * s, (h - f) / s, (c - g) / s, (d - b) / s
    elif a >= e and a >= i:
        s = 2.0 * np.sqrt(1.0 + a - e - i)
        q[0], q[1], q[2], q[3] = (h - f) / s, 0.25 * s, (b + d) / s, (c + g) / s
    elif e >= i:
        s = 2.0 * np.sqrt(1.0 + e - a - i)
        q[0], q[1], q[2], q[3] = (c - g) / s, (b + d) / s, 0.25 * s, (f + h) / s
    else:
        s = 2.0 * np.sqrt(1.0 + i - a - e)
        q[0], q[1], q[2], q[3] = (d - b) / s, (c + g) / s, (f + h) / s, 0.25 * s
    n = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    k = (1.0 if q[0] >= 0.0 else -1.0) / n
    for j in range(4):
        q[j] *= k


@kernel
def copy_bytes(out, dst, src, at, n):
    """out[dst:dst + n] = src[at:at + n]. A loop over unsigned indices: with no negative index
    to wrap around, it compiles to a vectorized copy (3x faster than a slice assignment)."""
    dst, at = np.uint64(dst), np.uint64(at)
    for j in range(np.uint64(n)):
        out[dst + j] = src[at + j]


@kernel
def assemble(pre, out, program):
    """Row r of `out` (uint8, prefilled with what every sample has in common) from row r of
    `pre` (uint8) by `program` (int64 rows: op, destination, source, bytes; see COPY etc.).
    Numbers are read and written through aligned scratch arrays: the byte offsets may be any."""
    R = np.empty((3, 3))
    R_bytes = R.reshape(9).view(np.uint8)
    q = np.empty(4)
    q_bytes = q.view(np.uint8)
    x = np.empty(1)
    x_bytes = x.view(np.uint8)
    for r in range(pre.shape[0]):
        row_in, row_out = pre[r], out[r]
        for i in range(program.shape[0]):
            op, dst, src, n = program[i, 0], program[i, 1], program[i, 2], program[i, 3]
            if op == COPY:
                copy_bytes(row_out, dst, row_in, src, n)
            elif op == QUATERNION:
                copy_bytes(R_bytes, 0, row_in, src, 72)
                quaternion_wxyz(R, q)
                copy_bytes(row_out, dst, q_bytes, 0, 32)
            else:
                copy_bytes(x_bytes, 0, row_in, src, 8)
                row_out[dst] = 0 if x[0] == 0.0 else 1


def warm_up() -> None:
    """The kernels' first call (compiled, or loaded from the cache), with the types
    telemetry.capture passes: read-only bytes in, a fresh array out."""
    pre = np.frombuffer(np.eye(3).tobytes() + bytes(8), np.uint8).reshape(1, 80)
    out = np.zeros((1, 33), np.uint8)
    assemble(pre, out, np.array([[QUATERNION, 0, 0, 72], [FLAG, 32, 72, 8], [COPY, 0, 0, 1]], np.int64))
