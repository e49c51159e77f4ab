"""The allocation's per-command steps in plain Python: the readable reference of
amcore.allocation_kernels (PX4's ControlAllocationSequentialDesaturation, airmode off, as
amcore.allocation's docstring lists the steps), over an `Allocation`'s set-up."""
from __future__ import annotations

from amcore.allocation import SATURATION_TOL, WEAK_EFFECTIVENESS, YAW_MARGIN, Allocation, AllocationResult


def _gain(v, out, out_min, hi: float) -> float:
    """computeDesaturationGain: k_min + k_max over the outputs outside [min, hi]."""
    k_min = k_max = 0.0
    for vi, x, lo in zip(v, out, out_min):
        if abs(vi) < WEAK_EFFECTIVENESS:
            continue
        if x < lo:
            k = (lo - x) / vi
            k_min, k_max = min(k_min, k), max(k_max, k)
        if x > hi:
            k = (hi - x) / vi
            k_min, k_max = min(k_min, k), max(k_max, k)
    return k_min + k_max


def _desaturate(out: list, v, out_min, hi: float, thrust_down_only: bool = False) -> list:
    """desaturateActuators along v; with thrust_down_only, a move that would raise the thrust
    (v is the thrust column, positive here in FLU) is not made."""
    g = _gain(v, out, out_min, hi)
    if thrust_down_only and g > 0.0:
        return out
    out = [x + g * vi for x, vi in zip(out, v)]
    g = 0.5 * _gain(v, out, out_min, hi)
    return [x + g * vi for x, vi in zip(out, v)]


def allocate(a: Allocation, roll: float, pitch: float, yaw: float, thrust: float) -> AllocationResult:
    """mixAirmodeDisabled for normalized (roll, pitch, yaw) torque and thrust."""
    r, p, y, t = (tuple(c) for c in a.mix.T.tolist())
    lo, hi = a.out_min, a.out_max
    out = [roll * x + pitch * u + thrust * w for x, u, w in zip(r, p, t)]
    full = [x + yaw * u for x, u in zip(out, y)]
    if all(x >= m for x, m in zip(out, lo)) and max(out) <= hi and all(x >= m for x, m in zip(full, lo)) \
            and max(full) <= hi:
        return AllocationResult(tuple(full), (roll, pitch, yaw, thrust), (0.0, 0.0, 0.0, 0.0), False)
    out = _desaturate(out, t, lo, hi, thrust_down_only=True)
    out = _desaturate(out, r, lo, hi)
    out = _desaturate(out, p, lo, hi)
    out = [x + yaw * u for x, u in zip(out, y)]  # mixYaw
    out = _desaturate(out, y, lo, hi + (hi - min(lo)) * YAW_MARGIN)
    out = _desaturate(out, t, lo, hi, thrust_down_only=True)
    out = tuple(min(max(x, m), hi) for x, m in zip(out, lo))
    allocated = tuple(sum(e * x for e, x in zip(row, out)) for row in a.effectiveness_normalized.tolist())
    unallocated = (roll - allocated[0], pitch - allocated[1], yaw - allocated[2], thrust - allocated[3])
    axes = tuple(bool(abs(u) > SATURATION_TOL) for u in unallocated)
    return AllocationResult(out, allocated, unallocated, any(axes), axes)
