"""Allocation of the X quadrotor: exactness, geometry, saturation priority, limits."""
from __future__ import annotations

import numpy as np
import pytest

from amcore.config import RotorParams
from amcore.model import build_model
from simulator.mixer import (QuadMixer, hover_thrust_n, hover_torque_limits_nm, limit_joint_torques,
                             max_total_thrust_n, torque_limits_nm)


@pytest.fixture(scope="module")
def rotors(spec):
    return spec.vehicle.rotors


@pytest.fixture(scope="module")
def mixer(rotors):
    return QuadMixer.from_rotors(rotors)


def literal_wrench(rotors: RotorParams, f: np.ndarray) -> tuple[float, np.ndarray]:
    """Slow re-implementation: sum of r_i x (0, 0, f_i) plus drag torques, rotor by rotor."""
    d = rotors.arm_length_m / np.sqrt(2.0)
    positions = [(d, d), (-d, d), (-d, -d), (d, -d)]  # FL, RL, RR, FR
    spins = [1.0, -1.0, 1.0, -1.0]
    tau = np.zeros(3)
    for (x, y), s, fi in zip(positions, spins, f):
        tau += np.cross([x, y, 0.0], [0.0, 0.0, fi])
        tau[2] += s * rotors.yaw_moment_coeff_m * fi
    return float(np.sum(f)), tau


def test_allocation_matches_literal_geometry(mixer, rotors):
    rng = np.random.default_rng(0)
    for _ in range(20):
        f = rng.uniform(0.0, rotors.thrust_max_n, 4)
        T, tau = mixer.wrench(f)
        T_ref, tau_ref = literal_wrench(rotors, f)
        assert T == pytest.approx(T_ref, abs=1e-12)
        np.testing.assert_allclose(tau, tau_ref, atol=1e-12)


def test_feasible_request_round_trips_exactly(mixer, rotors):
    rng = np.random.default_rng(1)
    for _ in range(50):
        f = rng.uniform(rotors.thrust_min_n + 0.1, rotors.thrust_max_n - 0.1, 4)
        T, tau = mixer.wrench(f)
        r = mixer.mix(T, tau)
        assert not r.saturated
        np.testing.assert_allclose(r.rotor_thrusts_n, f, atol=1e-9)
        assert r.applied_thrust_n == T
        np.testing.assert_array_equal(r.applied_tau_B_nm, tau)


def test_positive_roll_raises_left_rotors(mixer):
    r = mixer.mix(20.0, [0.5, 0.0, 0.0])
    f = r.rotor_thrusts_n  # FL, RL, RR, FR; left is +y_B
    assert f[0] > f[3] and f[1] > f[2]


def test_thrust_beyond_limit_is_clamped_and_flagged(mixer, rotors):
    r = mixer.mix(1.5 * max_total_thrust_n(rotors), [0.0, 0.0, 0.0])
    assert r.saturated
    assert r.applied_thrust_n == pytest.approx(max_total_thrust_n(rotors))
    np.testing.assert_allclose(r.rotor_thrusts_n, rotors.thrust_max_n)


def test_yaw_is_sacrificed_first(mixer):
    T, tau = 20.0, np.array([0.8, -0.5, 5.0])  # roll/pitch fit; the yaw does not
    r = mixer.mix(T, tau)
    assert r.saturated
    assert 0.0 <= r.yaw_scale < 1.0 and r.roll_pitch_scale == 1.0
    assert r.applied_thrust_n == pytest.approx(T, abs=1e-9)
    np.testing.assert_allclose(r.applied_tau_B_nm[:2], tau[:2], atol=1e-9)
    assert 0.0 <= r.applied_tau_B_nm[2] < tau[2]
    # the kept yaw is the most that fits: a little more would break a rotor limit
    assert not mixer.feasible(T, [tau[0], tau[1], r.applied_tau_B_nm[2] + 1e-3])


def test_roll_pitch_scaled_with_direction_kept(mixer):
    T, tau = 20.0, np.array([30.0, -20.0, 0.1])
    r = mixer.mix(T, tau)
    assert r.saturated and r.roll_pitch_scale < 1.0
    assert r.applied_thrust_n == pytest.approx(T, abs=1e-9)
    np.testing.assert_allclose(r.applied_tau_B_nm[:2], r.roll_pitch_scale * tau[:2], atol=1e-9)
    assert np.all(r.rotor_thrusts_n >= mixer.rotors.thrust_min_n - 1e-12)
    assert np.all(r.rotor_thrusts_n <= mixer.rotors.thrust_max_n + 1e-12)


def test_torque_limits_match_closed_form(rotors):
    T = 17.0
    d = rotors.arm_length_m / np.sqrt(2.0)
    # two rotors on one side at a, the other two at T/2 - a, each inside [min, max]
    a = min(rotors.thrust_max_n, T / 2 - rotors.thrust_min_n)
    roll_max = 2.0 * d * (2.0 * a - T / 2)
    yaw_max = 2.0 * rotors.yaw_moment_coeff_m * (2.0 * a - T / 2)
    np.testing.assert_allclose(torque_limits_nm(rotors, T), [roll_max, roll_max, yaw_max], rtol=1e-9)
    assert np.all(torque_limits_nm(rotors, 2 * max_total_thrust_n(rotors)) == 0.0)


def test_hover_is_feasible_for_the_vehicle(spec, rotors, mixer):
    mass = build_model(spec.vehicle).mass_kg
    T = hover_thrust_n(mass, spec.vehicle.gravity_mps2)
    assert not mixer.mix(T, np.zeros(3)).saturated
    assert T < 0.5 * max_total_thrust_n(rotors)  # thrust margin for attitude and the payload
    assert np.all(hover_torque_limits_nm(rotors, mass, spec.vehicle.gravity_mps2) > [1.0, 1.0, 0.1])


def test_joint_torques_are_clipped_and_flagged(spec):
    tau_max = spec.vehicle.joint_torque_max_nm
    ok = limit_joint_torques([1.0, -2.0, 0.5], tau_max)
    assert not ok.saturated
    np.testing.assert_array_equal(ok.applied_nm, [1.0, -2.0, 0.5])
    clipped = limit_joint_torques([10.0, -20.0, 0.5], tau_max)
    assert clipped.saturated
    np.testing.assert_array_equal(clipped.applied_nm, [tau_max[0], -tau_max[1], 0.5])


def test_bad_inputs_raise(mixer, spec):
    with pytest.raises(ValueError):
        mixer.mix(float("nan"), np.zeros(3))
    with pytest.raises(ValueError):
        limit_joint_torques([1.0, 2.0], spec.vehicle.joint_torque_max_nm)
    with pytest.raises(ValueError):
        QuadMixer.from_rotors(RotorParams(arm_length_m=0.2, thrust_max_n=5.0, count=6))
