"""The allocation (amcore.allocation_kernels, through `Allocation`) against its readable
reference (tests/amcore/reference_allocation.py), inside the limits and desaturated, for the
quad and the canted hexarotor.

Tolerance: 1e-12 on every normalized output and control, 1e-12 N per newton of a rotor's most
thrust. Both sides take the same steps on IEEE doubles; what may differ is only the order
numba's compiler gives a sum (a few ulps, ~1e-16 here), which the tolerance leaves room for
while a wrong step (a desaturation along the wrong axis, a missed clip) moves outputs by
1e-3 or more. Saturation flags must agree exactly away from SATURATION_TOL's edge. Beside
that, the kernel's named records (`result_dtype`, `constants_dtype`) and `read_result`."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from amcore.allocation import SATURATION_TOL, WEAK_EFFECTIVENESS, YAW_MARGIN, Allocation
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


@pytest.mark.parametrize("vehicle", ["am3dof.toml", "hex3dof.toml"])
def test_the_records_name_their_fields_per_rotor_count(vehicle):
    """The kernel's constants and result are records of the rotor count, made once per count;
    the constants are the set-up's numbers, by name."""
    from amcore import allocation_kernels as ak

    alloc = Allocation(load_vehicle(VEHICLES / vehicle).rotors)
    n = alloc.count
    dt = ak.result_dtype(n)
    assert dt is ak.result_dtype(n) and ak.constants_dtype(n) is ak.constants_dtype(n)
    assert dt.names == ("outputs", "allocated", "unallocated", "desaturated", "thrusts_n")
    assert [dt[f].shape for f in dt.names] == [(n,), (4,), (4,), (), (n,)]
    r = ak.new_result(n)
    assert r.shape == (1,) and r.dtype is dt and not r.view(np.float64).any()
    c = alloc.kernel_constants()[0]
    for k, name in enumerate(("roll", "pitch", "yaw", "thrust")):
        assert c[name].tolist() == alloc.mix[:, k].tolist()
    assert c["out_min"].tolist() == list(alloc.out_min)
    assert c["effectiveness"].tolist() == alloc.effectiveness_normalized.tolist()
    assert c["thrust_max_n"].tolist() == list(alloc.rotor_thrust_max_n)
    assert (c["out_max"], c["weak"], c["yaw_margin"]) == (alloc.out_max, WEAK_EFFECTIVENESS, YAW_MARGIN)


def test_a_result_written_elsewhere_reads_as_the_allocation():
    """`read_result` of a record the kernel wrote outside `Allocation` (as a compiled loop over
    several vehicles will) is what `allocate_thrusts` gives, in both branches, also when the
    reads alternate between that record and the allocation's own; a record of another rotor
    count is refused."""
    from amcore import allocation_kernels as ak

    alloc = Allocation(load_vehicle(VEHICLES / "hex3dof.toml").rotors)
    mine = ak.new_result(alloc.count)
    for case in ((0.01, -0.02, 0.005, 0.5), (0.4, -0.3, 2.5, 0.9)):
        ak.allocate(alloc.kernel_constants(), *case, mine)
        expected = alloc.allocate_thrusts(*case)
        assert alloc.read_result(mine, *case) == expected
        assert mine[0]["desaturated"] == (1.0 if expected[0].saturated else 0.0)
        assert mine[0]["thrusts_n"].tolist() == list(expected[1])
    with pytest.raises(ValueError, match="6 rotors"):
        alloc.read_result(ak.new_result(4), 0.0, 0.0, 0.0, 0.5)


def test_the_allocation_loads_its_kernel_only_when_asked():
    """Importing amcore.allocation imports no numba; building an `Allocation` and reading its
    scales do not load the kernel module; `kernel_constants` loads it."""
    code = ("import sys; import amcore.allocation; assert 'numba' not in sys.modules; "
            "from amcore.config import load_vehicle; "
            f"a = amcore.allocation.Allocation(load_vehicle({str(VEHICLES / 'am3dof.toml')!r}).rotors); "
            "a.normalized(1.0, (0, 0, 0)); assert 'amcore.allocation_kernels' not in sys.modules; "
            "c = a.kernel_constants(); assert 'amcore.allocation_kernels' in sys.modules and c is a.kernel_constants()")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=Path(__file__).resolve().parents[2])
