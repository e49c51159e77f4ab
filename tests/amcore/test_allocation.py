"""Allocation from the rotor table (amcore.allocation): the effectiveness matrix against a
rotor-by-rotor literal sum, the quad table against the paper's X mixer, round trips, the
desaturation order, the canted hexarotor's zero lateral force, and authority in closed form."""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amcore.allocation import AXES, Allocation, pinv_exact
from amcore.rotors import effectiveness
from amcore.authority import vehicle_authority
from amcore.config import load_vehicle

from .literal import literal_rotor_wrench

VEHICLES = Path(__file__).resolve().parents[2] / "configs" / "vehicles"


@pytest.fixture(scope="module")
def quad():
    return load_vehicle(VEHICLES / "am3dof.toml")


@pytest.fixture(scope="module")
def hexa():
    return load_vehicle(VEHICLES / "hex3dof.toml")


def test_effectiveness_is_the_sum_of_each_rotors_wrench(quad, hexa):
    rng = np.random.default_rng(0)
    for v in (quad, hexa):
        B = effectiveness(v.rotors)
        for _ in range(20):
            f = rng.uniform(0.0, v.rotors.thrust_max_n, v.rotors.count)
            np.testing.assert_allclose(B @ f, literal_rotor_wrench(v.rotors, f), atol=1e-12)


def test_the_quad_table_reproduces_the_paper_x_mixer(quad):
    """The old mixer: rotors at 45 + 90 i deg, 0.30 m out, drag s_i k f_i about +z_B with
    s = (+1, -1, +1, -1), thrust straight up: [T, tau]^T = A f."""
    L, k = 0.30, 0.016
    az = np.deg2rad(45.0 + 90.0 * np.arange(4))
    p = L * np.stack([np.cos(az), np.sin(az)], axis=1)
    A = np.stack([np.ones(4), p[:, 1], -p[:, 0], k * np.array([1.0, -1.0, 1.0, -1.0])])
    B = effectiveness(quad.rotors)
    np.testing.assert_allclose(B[2:6], A, atol=1e-15)
    np.testing.assert_array_equal(B[0:2], 0.0)  # no lateral force from upright rotors
    alloc = Allocation(quad.rotors)
    f = alloc.allocate_wrench(20.0, [0.3, -0.2, 0.05]).rotor_thrusts_n
    np.testing.assert_allclose(f, np.linalg.solve(A, [20.0, 0.3, -0.2, 0.05]), atol=1e-12)


@pytest.mark.parametrize("name", ["quad", "hexa"])
def test_a_feasible_request_is_made_exactly_with_no_lateral_force(name, request):
    v = request.getfixturevalue(name)
    alloc = Allocation(v.rotors)
    rng = np.random.default_rng(1)
    made = 0
    for _ in range(300):
        T = rng.uniform(10.0, 40.0)
        tau = rng.uniform(-1.0, 1.0, 3) * [2.0, 2.0, 0.2 if name == "quad" else 1.5]
        a = alloc.allocate_wrench(T, tau)
        f = np.array(a.rotor_thrusts_n)
        assert np.all(f >= alloc.f_min - 1e-12) and np.all(f <= alloc.f_max + 1e-12)
        w = literal_rotor_wrench(v.rotors, f)
        if a.allocation.unallocated == (0.0, 0.0, 0.0, 0.0):  # inside every rotor's range: made exactly
            made += 1
            np.testing.assert_allclose(w, [0.0, 0.0, T, *tau], atol=1e-9)
            assert a.allocation.saturated_axes == (False, False, False, False)
        else:  # an axis short by more than PX4's tolerance is flagged, the others are made
            short = np.abs(np.array(a.allocation.unallocated)) > 1e-3
            assert a.allocation.saturated_axes == tuple(short.tolist())
            scale = np.array([*alloc.torque_scale_nm, alloc.thrust_scale_n])
            made_axes = ~short
            np.testing.assert_allclose(w[[3, 4, 5, 2]][made_axes], np.array([*tau, T])[made_axes],
                                       atol=1.01e-3 * scale.max())
    assert made > 150  # the test sampled mostly feasible requests


def test_desaturation_gives_up_yaw_first_and_keeps_thrust_roll_and_pitch(quad, hexa):
    for v, yaw in ((quad, 2.0), (hexa, 8.0)):
        alloc = Allocation(v.rotors)
        T, tau = 20.0, np.array([0.4, -0.3, yaw])  # roll and pitch fit; this yaw does not
        a = alloc.allocate_wrench(T, tau)
        assert a.saturated and a.allocation.saturated_axes == (False, False, True, False)
        assert a.force_B_n[2] == pytest.approx(T, abs=1e-9)
        np.testing.assert_allclose(a.tau_B_nm[:2], tau[:2], atol=1e-9)
        assert 0.0 < a.tau_B_nm[2] < yaw
        # nothing better was possible along yaw: a little more breaks a rotor limit
        more = alloc.mix @ alloc.normalized(T, [tau[0], tau[1], a.tau_B_nm[2] * 1.05 + 1e-3])
        assert np.any(more > 1.0 + 1e-9) or np.any(more < np.array(alloc.out_min) - 1e-9)
    # at full thrust with a roll request, PX4 (airmode off) lowers the thrust, never the roll
    alloc = Allocation(quad.rotors)
    a = alloc.allocate_wrench(0.98 * 4 * quad.rotors.thrust_max_n, [3.0, 0.0, 0.0])
    assert a.allocation.saturated_axes == (False, False, False, True)
    assert a.tau_B_nm[0] == pytest.approx(3.0, abs=1e-9) and a.force_B_n[2] < 0.98 * 48.0


def test_the_canted_hexarotor_makes_no_lateral_force_or_torque_at_equal_thrust(hexa):
    B = effectiveness(hexa.rotors)
    w = B @ np.full(6, 5.0)
    np.testing.assert_allclose(w[[0, 1, 3, 4, 5]], 0.0, atol=1e-12)
    assert w[2] == pytest.approx(6 * 5.0 * math.cos(math.radians(20.0)), rel=1e-6)
    # yet it yaws with far more than rotor drag: cant and drag add, per newton of differential thrust
    assert abs(B[5, 0]) == pytest.approx(0.243 * math.sin(math.radians(20.0)) + 0.06 * math.cos(math.radians(20.0)),
                                         rel=1e-3)
    assert np.linalg.matrix_rank(B) == 6  # fully actuated: the lateral force can be held at zero


def test_authority_matches_closed_form_for_the_quad(quad):
    """Quad X at total thrust T, no torque: each rotor at T/4. Yaw moves the diagonals by -+d
    until one reaches 0: k T; roll by the left/right pairs: 2 (T/4) (2 L / sqrt 2)."""
    alloc = Allocation(quad.rotors)
    T = 17.0
    auth = alloc.authority(T)
    assert auth["yaw"] == pytest.approx((0.016 * T, 0.016 * T), rel=1e-9)
    d = 0.30 / math.sqrt(2.0)
    assert auth["roll"][0] == pytest.approx(4 * (T / 4) * d, rel=1e-9)
    assert alloc.authority(10 * T) == {ax: (0.0, 0.0) for ax in AXES[:3]}  # infeasible operating point


def test_the_hexarotor_meets_its_targets_and_the_quad_does_not(quad, hexa):
    """The vehicle issue's targets as properties of the two vehicle files (static figures;
    the simulated loaded hover is measured in docs/vehicles.md)."""
    h, q = vehicle_authority(hexa), vehicle_authority(quad)
    assert min(h.hover.authority_nm["yaw"]) >= 1.0
    assert min(q.hover.authority_nm["yaw"]) < 0.3
    assert h.cant_loss == pytest.approx(1.0 - math.cos(math.radians(20.0)), rel=1e-6)
    loaded = vehicle_authority(hexa, squeeze_n=9.0, load_kg=0.5).loaded
    assert loaded.feasible and max(loaded.rotor_fractions) < 0.8


def _penrose_residuals(A, X):
    """The four Moore-Penrose conditions' residuals of X as A's pseudo-inverse (max |.|)."""
    return max(float(np.abs(A @ X @ A - A).max()), float(np.abs(X @ A @ X - X).max()),
               float(np.abs((A @ X).T - A @ X).max()), float(np.abs((X @ A).T - X @ A).max()))


@given(st.lists(st.floats(-2.0, 2.0, allow_nan=False).filter(lambda x: x == 0.0 or abs(x) > 1e-6),
                min_size=24, max_size=24),
       st.sampled_from([(6, 4), (4, 6), (3, 3), (6, 2)]), st.integers(0, 2))
@settings(max_examples=60, deadline=None)
def test_the_exact_pseudo_inverse_meets_penrose_and_numpys_for_any_rank(values, shape, dropped):
    """pinv_exact against the four Moore-Penrose conditions and numpy's SVD pseudo-inverse, on
    full-rank matrices and on ones with rows repeated (rank lost)."""
    m, n = shape
    A = np.array(values[: m * n]).reshape(m, n)
    for k in range(min(dropped, m - 1)):
        A[k + 1] = A[0]  # a repeated row: rank falls by one
    X = pinv_exact(A)
    if np.linalg.cond(np.linalg.pinv(A)) > 1e6:  # within rounding of another rank: LAPACK's cutoff and ours differ
        return
    assert _penrose_residuals(A, X) < 1e-9
    assert np.allclose(X, np.linalg.pinv(A), rtol=0.0, atol=1e-9 * max(1.0, float(np.abs(X).max())))


def test_the_mix_is_the_same_bits_whatever_blas_kernel_the_cpu_selects(tmp_path):
    """The allocation's set-up uses no LAPACK or BLAS reduction: a fresh process with OpenBLAS
    forced to another kernel (SkylakeX, Prescott) builds the same mix for every shipped vehicle."""
    import os
    import subprocess
    import sys

    code = ("import hashlib, pathlib; from amcore.config import load_vehicle; from amcore.allocation import Allocation;"
            "print(*[hashlib.sha256(Allocation(load_vehicle(p).rotors).mix_full.tobytes()).hexdigest()"
            f" for p in sorted(pathlib.Path({str(VEHICLES)!r}).glob('*.toml'))])")
    digests = {subprocess.run([sys.executable, "-c", code], env=os.environ | {"OPENBLAS_CORETYPE": core},
                              capture_output=True, text=True, check=True).stdout for core in ("SkylakeX", "Prescott")}
    assert len(digests) == 1
    here = " ".join(hashlib.sha256(Allocation(load_vehicle(p).rotors).mix_full.tobytes()).hexdigest()
                    for p in sorted(VEHICLES.glob("*.toml")))
    assert digests == {here + "\n"}
