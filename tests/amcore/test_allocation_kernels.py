"""The allocation (amcore.allocation_kernels, through `Allocation`) against its readable
reference (tests/amcore/reference_allocation.py), inside the limits and desaturated, for the
quad and the canted hexarotor.

Tolerance: 1e-12 on every normalized output and control, 1e-12 N per newton of a rotor's most
thrust. Both sides take the same steps on IEEE doubles; what may differ is only the order
numba's compiler gives a sum (a few ulps, ~1e-16 here), which the tolerance leaves room for
while a wrong step (a desaturation along the wrong axis, a missed clip) moves outputs by
1e-3 or more. Saturation flags must agree exactly away from SATURATION_TOL's edge."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amcore.allocation import SATURATION_TOL, Allocation
from amcore.config import load_vehicle

from .reference_allocation import allocate as reference_allocate

VEHICLES = Path(__file__).resolve().parents[2] / "configs" / "vehicles"
TOL = 1e-12


def _close(a, b) -> bool:
    return len(a) == len(b) and all(abs(x - y) <= TOL for x, y in zip(a, b))


@pytest.mark.parametrize("vehicle", ["am3dof.toml", "hex3dof.toml"])
def test_the_allocation_is_its_reference(vehicle):
    rotors = load_vehicle(VEHICLES / vehicle).rotors
    alloc = Allocation(rotors)
    rng = np.random.default_rng(2)
    saturated = 0
    for scale in (0.05, 0.3, 1.0, 3.0):
        for _ in range(2000):
            roll, pitch, yaw = (scale * rng.normal(size=3)).tolist()
            thrust = float(rng.uniform(-0.2, 1.3))
            case = (roll, pitch, yaw, thrust)
            ref = reference_allocate(alloc, *case)
            got, thrusts = alloc.allocate_thrusts(*case)
            assert got == alloc.allocate(*case), case
            assert _close(got.outputs, ref.outputs), case
            assert _close(got.allocated, ref.allocated) and _close(got.unallocated, ref.unallocated), case
            if all(abs(abs(u) - SATURATION_TOL) > TOL for u in ref.unallocated):
                assert got.saturated == ref.saturated and got.saturated_axes == ref.saturated_axes, case
            f_max = rotors.thrust_max()
            assert all(abs(f - u * m) <= TOL * m for f, u, m in zip(thrusts, ref.outputs, f_max)), case
            saturated += ref.saturated
        tau = (scale * rng.normal(size=3)).tolist()
        w = alloc.allocate_wrench(20.0 * scale, tau)
        ref = reference_allocate(alloc, *alloc.normalized(20.0 * scale, tau))
        assert _close(w.allocation.outputs, ref.outputs)
        F, t = alloc.wrench(w.rotor_thrusts_n)
        assert w.force_B_n == F and w.tau_B_nm == t
    assert 1000 < saturated < 7000  # both branches taken many times


def test_a_wrong_step_is_seen():
    """The comparison can fail: a reference whose yaw desaturation is left out differs from the
    allocation on saturated commands by far more than the tolerance."""
    from . import reference_allocation as ref

    alloc = Allocation(load_vehicle(VEHICLES / "am3dof.toml").rotors)
    case = (0.4, -0.3, 2.5, 0.9)  # yaw far beyond what the rotors give at this thrust
    good = ref.allocate(alloc, *case)
    assert _close(alloc.allocate(*case).outputs, good.outputs)
    original = ref._desaturate
    try:
        ref._desaturate = lambda out, v, lo, hi, thrust_down_only=False: out  # no desaturation at all
        bad = ref.allocate(alloc, *case)
    finally:
        ref._desaturate = original
    assert max(abs(x - y) for x, y in zip(bad.outputs, good.outputs)) > 1e-3
