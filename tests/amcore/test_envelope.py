"""The static loaded hover (amcore.authority) against pinocchio's own statics, and the team's
envelope (amcore.envelope) at its edge, both ways."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from amcore.authority import operating_point
from amcore.config import load_vehicle
from amcore.envelope import (Envelope, Margins, buckling_squeeze_n, pad_side_stiffness_n_per_m, required_squeeze_n,
                             verdict_line)
from amcore.model import build_model

VEHICLES = Path(__file__).resolve().parents[2] / "configs" / "vehicles"


@pytest.fixture(scope="module")
def hexa():
    return load_vehicle(VEHICLES / "hex3dof.toml")


@pytest.fixture(scope="module")
def env(hexa):
    return Envelope(hexa)


@pytest.mark.parametrize("squeeze_n,load_kg", [(0.0, 0.0), (9.0, 0.5), (20.0, 0.3)])
def test_the_loaded_hover_balances_every_generalized_force(hexa, squeeze_n, load_kg):
    """Whole-body statics by pinocchio: g(q) - J_E^T W must be the rotors' wrench (0, 0, T,
    tau_B) on the base, in its own frame, and the joint torques the point reports."""
    model = build_model(hexa)
    op = operating_point(hexa, model, np.array(hexa.q_nominal_rad), squeeze_n, load_kg)
    assert op.feasible
    # rebuild the pose: base pitched by op.pitch_rad; the arm angles are not returned, so
    # recover them by the same balance: the pad where it was, seen from the turned base
    from amcore.authority import _hold_pad
    c, s = math.cos(op.pitch_rad), math.sin(op.pitch_rad)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    data = model.pin_model.createData()
    q = _hold_pad(model, data, np.array(hexa.q_nominal_rad), R)
    q_pin = np.concatenate([[0.0, 0.0, 0.0], pin.Quaternion(R).coeffs(), q])
    g = pin.computeGeneralizedGravity(model.pin_model, data, q_pin)
    J = pin.computeFrameJacobian(model.pin_model, data, q_pin, model.ee_frame_id, pin.LOCAL_WORLD_ALIGNED)
    W = np.array([-squeeze_n, 0.0, -load_kg * hexa.gravity_mps2, 0.0, 0.0, 0.0])
    need = g - J.T @ W
    np.testing.assert_allclose(need[0:3], [0.0, 0.0, op.thrust_n], atol=1e-9)
    np.testing.assert_allclose(need[3:6], op.tau_B_nm, atol=1e-9)
    np.testing.assert_allclose(need[6:], op.joint_torques_nm, atol=1e-12)
    # and the pad is where it was: only the base turned
    pin.framesForwardKinematics(model.pin_model, data, q_pin)
    pad = data.oMf[model.ee_frame_id]
    pin.framesForwardKinematics(model.pin_model, data, np.concatenate([[0, 0, 0, 0, 0, 0, 1.0], hexa.q_nominal_rad]))
    assert np.allclose(pad.translation, data.oMf[model.ee_frame_id].translation, atol=1e-8)


def test_the_required_squeeze_is_friction_with_its_margin():
    assert required_squeeze_n(2.5, 4, 0.5, 1.0, 9.81) == pytest.approx(2.5 * 9.81 / 2.0)
    assert required_squeeze_n(1.0, 2, 0.5, 1.2, 9.81) == pytest.approx(11.772)


def test_the_payload_is_the_envelope_edge_both_ways(env):
    m = env.payload_kg(2, 0.5, 1.2)
    assert 1.0 < m < 3.0
    assert env.fit(m - 0.02, 2, 0.5, 1.2).holds
    assert not env.fit(m + 0.02, 2, 0.5, 1.2).holds
    assert env.payload_kg(4, 0.5, 1.2) > m  # more AMs hold more
    assert env.payload_kg(2, 1.0, 1.2) >= m  # and more friction


def test_outside_the_envelope_the_line_names_the_smallest_team(env):
    heavy = 2.0 * env.payload_kg(2, 0.5, 1.2)
    line = verdict_line(env, heavy, 2, 0.5, 1.2)
    n = env.smallest_team(heavy, 0.5, 1.2)
    assert n is not None and n > 2 and f": use {n} AMs" in line and "needs" in line
    assert not env.fit(heavy, n - 1, 0.5, 1.2).holds and env.fit(heavy, n, 0.5, 1.2).holds
    assert verdict_line(env, 1.0, 2, 0.5, 1.2).endswith("inside the envelope")


def test_the_quad_has_no_yaw_reserve_for_a_grasp():
    quad = load_vehicle(VEHICLES / "am3dof.toml")
    assert Envelope(quad).capacity_n(0.5) == 0.0  # 0.25 N m of yaw at hover < the 0.3 N m reserve
    assert Envelope(quad, Margins(yaw_reserve_nm=0.05)).capacity_n(0.5) > 5.0


def test_the_pitch_reserve_refuses_the_hover_that_saturated_and_keeps_the_one_that_held(hexa, env):
    """Flown with every device on: 1.42 kg squeezed with 17.2 N saturated its rear rotors on
    9.7 % of the steps (0.56 N m of pitch left in the static point); 1.29 kg with 16.9 N held
    (0.71 N m left). The reserve tells them apart, and without it neither is refused."""
    why = env.broken_margin(17.2, 1.42 / 2)
    assert why is not None and "of pitch left, under the 0.7 N m reserve" in why
    assert env.broken_margin(16.9, 1.29 / 2) is None
    assert Envelope(hexa, Margins(pitch_reserve_nm=0.0)).broken_margin(17.2, 1.42 / 2) is None


@pytest.mark.parametrize("load_kg", [0.3, 0.6, 0.73])
def test_the_capacity_is_the_first_edge_every_smaller_squeeze_keeps_the_margins(env, load_kg):
    cap = env.capacity_n(load_kg)
    assert all(env._ok(n, load_kg) for n in np.linspace(0.0, cap, 41))
    assert cap == 200.0 or not env._ok(cap + 0.05, load_kg)


def test_a_margin_that_recovers_at_a_larger_squeeze_does_not_move_the_edge(env):
    # at 0.73 kg the pitch reserve breaks at a few newtons and comes back as the base tilts
    # further: a bisection over the whole range could land on the far edge
    load = 0.73
    cap = env.capacity_n(load)
    far = [n for n in np.arange(cap + 1.0, 60.0, 1.0) if env._ok(n, load)]
    assert far and cap < min(far) - 1.0


def _rolling_energy(theta, a, R, K, N):
    """Potential of a box (faces a from its axis) turned by theta between two crowns of radius R
    that roll on its faces without slipping and keep their orientation, each held sideways by
    a spring K and pushed in by a constant squeeze N (exact trigonometry, no small angles)."""
    c, s = math.cos(theta), math.sin(theta)
    V = 0.0
    for side in (1.0, -1.0):  # the crown's axis: (a + R) out along the face normal, R theta back along the face
        x_b, y_b = side * (a + R), -side * R * theta
        x, y = c * x_b - s * y_b, s * x_b + c * y_b
        V += 0.5 * K * y * y - N * (a + R - side * x)  # the squeeze's work as the crown closes in
    return V


@pytest.mark.parametrize("a,R", [(0.089, 0.05), (0.12, 0.05), (0.07, 0.05), (0.1, 0.02)])
def test_the_buckling_squeeze_is_where_the_rolling_box_stops_being_a_minimum(a, R):
    K, h = 54.0, 1e-4
    n_cr = buckling_squeeze_n(a, R, K)
    assert n_cr == pytest.approx(K * a * a / (a - R))
    for N, stable in ((0.97 * n_cr, True), (1.03 * n_cr, False)):
        curvature = (_rolling_energy(h, a, R, K, N) - 2 * _rolling_energy(0.0, a, R, K, N)
                     + _rolling_energy(-h, a, R, K, N)) / h**2
        assert (curvature > 0.0) == stable


def test_crowns_as_wide_as_the_box_never_buckle_and_the_worst_box_is_twice_the_crown():
    K, R = 54.0, 0.05
    assert buckling_squeeze_n(0.05, R, K) == math.inf and buckling_squeeze_n(0.04, R, K) == math.inf
    assert all(_rolling_energy(0.01, 0.05, R, K, N) > _rolling_energy(0.0, 0.05, R, K, N) for N in (1.0, 100.0))
    worst = min(buckling_squeeze_n(a, R, K) for a in np.linspace(0.051, 0.5, 2000))
    assert worst == pytest.approx(4.0 * K * R, rel=1e-4) == pytest.approx(buckling_squeeze_n(2 * R, R, K))


def test_the_pads_side_stiffness_is_the_com_in_series_with_the_heading(hexa, env):
    import dataclasses
    K = pad_side_stiffness_n_per_m(hexa, env.model)
    assert 0.0 < K < min(hexa.gains.K_t[:2])
    stiffer = dataclasses.replace(hexa, gains=dataclasses.replace(hexa.gains, K_t=(160.0, 160.0, 80.0)))
    K2 = pad_side_stiffness_n_per_m(stiffer, env.model)
    # 1/K = 1/K_t + L^2/k_psi: doubling K_t takes 1/80 - 1/160 off the compliance, nothing else
    assert 1.0 / K - 1.0 / K2 == pytest.approx(1.0 / 80.0 - 1.0 / 160.0)
    yawstiff = dataclasses.replace(hexa, gains=dataclasses.replace(hexa.gains, k_R=2 * hexa.gains.k_R))
    K3 = pad_side_stiffness_n_per_m(yawstiff, env.model)
    assert (1.0 / K3 - 1.0 / 80.0) == pytest.approx(0.5 * (1.0 / K - 1.0 / 80.0))
