"""The baseline controller (amcore.baseline): Lee's geometric law at and near the reference,
gravity compensation of the arm, the inverse kinematics, that the F/T reading never reaches
the command, diagnostics defined as the paper law's, anti-windup, and free-flight convergence
against pinocchio's dynamics."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from amcore import baseline as bl
from amcore.attitude import desired_attitude
from amcore.control import Reference
from amcore.ideal import run_closed_loop
from amcore.model import AmState, create_data, decoupled_terms
from amcore.so3 import exp_so3
from amcore.task import task_terms

from .conftest import states

G = 9.81


@pytest.fixture()
def bparams(spec, model, mission):
    return bl.BaselineParams.from_vehicle(spec.vehicle, model, mission.frame)


def _reference(mission, t: float, acc=(0.0, 0.0, 0.0), jerk=(0.0, 0.0, 0.0), snap=(0.0, 0.0, 0.0)) -> Reference:
    """The mission's reference at t with the CoM path's acceleration, jerk and snap replaced."""
    r = mission.reference(t)
    return Reference(r.r_c, r.r_c_d1, np.array(acc, float), np.array(jerk, float), np.array(snap, float), r.psi,
                     r.psi_d1, r.psi_d2, r.y, r.y_d1, r.y_d2)


def _on_reference(bparams, ref: Reference, model, q) -> tuple[AmState, np.ndarray, np.ndarray, np.ndarray]:
    """The state exactly on the base reference (position, velocity, R = R_d, w = W_d), and
    (R_d, W_d, Wdot_d) from the reference's flat outputs."""
    m = model.mass_kg
    p_d, p_d1, p_d2, p_d3, p_d4 = bl.base_reference(bparams, ref)
    b1 = np.array([math.cos(ref.psi), math.sin(ref.psi), 0.0])
    R_d, W_d, Wdot_d = desired_attitude(m * (p_d2 + [0, 0, G]), m * p_d3, m * p_d4, b1, np.zeros(3), np.zeros(3))
    x = AmState(p_WB=p_d, R_WB=R_d, v_B=R_d.T @ p_d1, w_B=W_d, q=np.asarray(q, float), qdot=np.zeros(model.n))
    return x, R_d, W_d, Wdot_d


def test_at_the_reference_thrust_is_weight_over_cos_tilt_and_torque_is_gyroscopic(model, data, bparams, mission):
    """Zero error with a horizontal reference acceleration a: the thrust is m g / cos(tilt),
    tilt = atan(|a| / g), and the body torque is W x J W + J Wdot_d plus the arm's weight moment
    g_B(q, R) (pinocchio's generalized gravity), nothing else."""
    a, jerk, snap = np.array([1.5, -0.8, 0.0]), np.array([0.7, 0.4, 0.3]), np.array([-2.0, 1.0, 0.5])
    ref = _reference(mission, 2.0, a, jerk, snap)
    x, R_d, W_d, Wdot_d = _on_reference(bparams, ref, model, model.vehicle.q_nominal_rad)
    res = bl.step(model, data, bparams, x, ref, np.zeros(6), bl.BaselineMemory(), 2.0)
    tilt = math.atan(np.linalg.norm(a) / G)
    assert res.command.thrust_n == pytest.approx(model.mass_kg * G / math.cos(tilt), rel=1e-12)
    np.testing.assert_allclose(res.diagnostics.e_R, 0.0, atol=1e-12)
    np.testing.assert_allclose(res.diagnostics.e_w, 0.0, atol=1e-12)
    g_B = pin.computeGeneralizedGravity(model.pin_model, create_data(model), x.pin_q())[3:6]
    J = bparams.J
    np.testing.assert_allclose(res.command.tau_B_nm, np.cross(W_d, J @ W_d) + J @ Wdot_d + g_B, atol=1e-12)
    assert np.linalg.norm(W_d) > 0.05 and np.linalg.norm(Wdot_d) > 0.1  # the feed-forward terms really act


def test_attitude_error_is_sin_theta_along_the_axis(model, data, bparams, mission):
    """e_R = vee(R_d^T R - R^T R_d)/2 is zero at R = R_d and sin(theta) e for R = R_d exp(theta hat(e))."""
    ref = _reference(mission, 1.0, (0.5, 0.2, 0.0))
    x, R_d, _, _ = _on_reference(bparams, ref, model, model.vehicle.q_nominal_rad)
    v_W = x.R_WB @ x.v_B
    rng = np.random.default_rng(3)
    for theta in (1e-3, 0.3, 1.2, 2.5):
        e = rng.normal(size=3)
        e /= np.linalg.norm(e)
        R = R_d @ exp_so3(theta * e)
        xs = AmState(x.p_WB, R, R.T @ v_W, x.w_B, x.q, x.qdot)  # the same world velocity: F_d, R_d unchanged
        d = bl.step(model, data, bparams, xs, ref, np.zeros(6), bl.BaselineMemory(), 1.0).diagnostics
        np.testing.assert_allclose(d.R_d, R_d, atol=1e-12)
        np.testing.assert_allclose(d.e_R, math.sin(theta) * e, atol=1e-12)


def test_attitude_torque_derivative_is_minus_k_R_at_the_reference(model, data, bparams, mission):
    """d tau_B / d(rotation) at R = R_d is -diag(k_R) (plus the gravity moment's own change):
    Lee's spring, checked by central differences."""
    ref = _reference(mission, 1.0)
    x, R_d, _, _ = _on_reference(bparams, ref, model, model.vehicle.q_nominal_rad)
    h = 1e-6
    pd = create_data(model)

    def tau_minus_gravity(dphi):
        R = R_d @ exp_so3(dphi)
        xs = AmState(x.p_WB, R, R.T @ (x.R_WB @ x.v_B), np.zeros(3), x.q, x.qdot)
        t = bl.step(model, data, bparams, xs, ref, np.zeros(6), bl.BaselineMemory(), 1.0).command.tau_B_nm
        return t - pin.computeGeneralizedGravity(model.pin_model, pd, xs.pin_q())[3:6]

    D = np.column_stack([(tau_minus_gravity(h * e) - tau_minus_gravity(-h * e)) / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(D, -np.diag(bparams.k_R), atol=1e-5 * bparams.k_R.max())


@pytest.mark.parametrize("tilt", [0.0, 0.4])
def test_gravity_compensation_at_rest_on_the_ik_solution(model, data, bparams, mission, tilt):
    """With q = q_d and qdot = 0 the arm torque is pinocchio's generalized gravity on the arm
    joints, g_q(q, R), for a level and for a pitched base."""
    ref = mission.reference(3.0)
    x, _, _, _ = _on_reference(bparams, ref, model, model.vehicle.q_nominal_rad)
    R = x.R_WB @ exp_so3(np.array([0.1, tilt, 0.0]))
    mem = bl.step(model, data, bparams, AmState(x.p_WB, R, x.v_B, x.w_B, x.q, x.qdot), ref, np.zeros(6),
                  bl.BaselineMemory(), 3.0).memory
    xs = AmState(x.p_WB, R, x.v_B, x.w_B, mem.q_d.copy(), np.zeros(model.n))
    res = bl.step(model, data, bparams, xs, ref, np.zeros(6), mem, 3.0)
    g = pin.computeGeneralizedGravity(model.pin_model, create_data(model), xs.pin_q())
    np.testing.assert_allclose(res.command.tau_q_nm, g[6:], atol=1e-8)
    assert np.abs(g[6:]).max() > 0.04  # the arm's weight is really there


def test_inverse_kinematics_round_trip(model, data, bparams):
    """Forward kinematics of the IK solution reproduces the target (x, z, pitch in {b}) around
    the working range, from a warm start at q_nominal."""
    rng = np.random.default_rng(7)
    q_nom = np.array(model.vehicle.q_nominal_rad)
    for _ in range(10):
        q_true = q_nom + rng.uniform(-0.3, 0.3, size=model.n)
        target, _ = bl.planar_fk(model, data, q_true)
        q, sigma = bl.inverse_kinematics(model, data, target, q_nom, 50, bparams.ik_damping, bparams.q_min,
                                         bparams.q_max)
        y, _ = bl.planar_fk(model, data, q)
        np.testing.assert_allclose(y, target, atol=1e-9)
        assert sigma > 0.05


def test_ik_solution_puts_the_pad_on_y_d_from_the_base_reference_pose(model, data, bparams, mission):
    """The pad, at q_d with the base at its reference pose (p_d, R_d), sits at the mission's
    y_d in the task frame (the reference pitched in the arm's plane, as in the grasp), wherever
    the measured base is."""
    fr = mission.frame
    for t in (0.0, 4.0, 7.0, 13.0):
        ref = _reference(mission, t, acc=fr.R_WT @ np.array([2.5, 0.0, 0.0]))  # tilts R_d in the arm's plane
        x, R_d, _, _ = _on_reference(bparams, ref, model, model.vehicle.q_nominal_rad)
        R = R_d @ exp_so3(np.array([0.05, 0.2, -0.1]))
        # the measured base off its reference in the arm's plane (F_d, hence R_d, stays in it)
        measured = AmState(x.p_WB + fr.R_WT @ [0.05, 0.0, -0.04], R, R.T @ (R_d @ x.v_B), x.w_B, x.q, x.qdot)
        mem = bl.BaselineMemory()
        for k in range(3):  # warm-started Newton steps converge over a few control steps
            res = bl.step(model, data, bparams, measured, ref, np.zeros(6), mem, t)
            mem = res.memory
        R_d = res.diagnostics.R_d  # F_d, hence R_d, answers the measured base's error
        assert np.linalg.norm(R_d - x.R_WB) > 1e-3
        xs = AmState(x.p_WB, R_d, x.v_B, x.w_B, mem.q_d, np.zeros(model.n))
        d = create_data(model)
        tk = task_terms(model, d, decoupled_terms(model, d, xs), fr, bparams.components)
        np.testing.assert_allclose(tk.y, ref.y, atol=1e-9)


def test_the_wrench_reading_never_reaches_the_command(model, data, bparams, mission):
    """A practitioner's first controller has no F/T sensor: any wrench gives the same command
    (it is only filtered into the diagnostics)."""
    ref = mission.reference(6.0)
    rng = np.random.default_rng(1)
    for x in states(model, 4):
        a = bl.step(model, data, bparams, x, ref, np.zeros(6), bl.BaselineMemory(), 0.0)
        b = bl.step(model, data, bparams, x, ref, rng.normal(scale=20.0, size=6), bl.BaselineMemory(), 0.0)
        assert a.command.thrust_n == b.command.thrust_n
        np.testing.assert_array_equal(a.command.tau_B_nm, b.command.tau_B_nm)
        np.testing.assert_array_equal(a.command.tau_q_nm, b.command.tau_q_nm)
        assert not np.array_equal(a.diagnostics.F_rc, b.diagnostics.F_rc)


def test_diagnostics_measure_as_the_paper_law_does(model, data, bparams, mission):
    """r_c, rdot_c (the model's CoM), y and ydot (task values in the same task frame) equal those
    amcore.model and amcore.task compute for the paper's law, at random states; so do the errors."""
    ref = mission.reference(8.0)
    d2 = create_data(model)
    for x in states(model, 8, seed=4):
        d = bl.step(model, data, bparams, x, ref, np.zeros(6), bl.BaselineMemory(), 0.0).diagnostics
        tm = decoupled_terms(model, d2, x)
        tk = task_terms(model, d2, tm, mission.frame, bparams.components)
        np.testing.assert_allclose(d.r_c, tm.r_c, atol=1e-12)
        np.testing.assert_allclose(d.rdot_c, tm.rdot_c, atol=1e-12)
        np.testing.assert_allclose(d.r_c_err, tm.r_c - ref.r_c, atol=1e-12)
        np.testing.assert_allclose(d.y, tk.y, atol=1e-12)
        np.testing.assert_allclose(d.ydot, tk.ydot, atol=1e-10)
        np.testing.assert_allclose(d.y_err, tk.y - ref.y, atol=1e-12)
        for v in (d.F_y, d.u, d.tau, d.Lambda_y, d.wrench_W_filtered, d.wdot_bd, d.Omega_d):
            assert np.all(np.isfinite(v))


def test_integrals_are_clamped_and_the_clamp_is_reported(model, data, bparams, mission):
    """Held 0.3 m and 0.2 rad off for 20 s, the integral terms stop at their limits (anti-windup)
    and the diagnostics say so."""
    ref = mission.reference(0.0)
    x, R_d, _, _ = _on_reference(bparams, ref, model, model.vehicle.q_nominal_rad)
    xs = AmState(x.p_WB + [0.3, -0.3, 0.3], R_d @ exp_so3(np.array([0.0, 0.2, 0.0])), x.v_B, x.w_B, x.q, x.qdot)
    mem = bl.BaselineMemory()
    for k in range(200):
        res = bl.step(model, data, bparams, xs, ref, np.zeros(6), mem, 0.1 * k)
        mem = res.memory
    assert res.diagnostics.com_err_saturated
    b = model.vehicle.baseline
    np.testing.assert_allclose(np.abs(bparams.k_i * mem.i_x), b.integral_limit_n, rtol=1e-12)
    pitch = 1  # the only axis with an attitude integral in am3dof.toml
    assert abs(bparams.k_iR[pitch] * mem.i_R[pitch]) == pytest.approx(b.attitude_integral_limit_nm[pitch], rel=1e-12)


def test_composite_inertia_is_the_locked_am_about_its_com(model):
    """J: the spatial inertia of all bodies at q_nominal, shifted to the CoM (parallel-axis theorem)."""
    pm = model.pin_model
    d = pm.createData()
    q = pin.neutral(pm)
    q[7:] = model.vehicle.q_nominal_rad
    pin.forwardKinematics(pm, d, q)
    c = pin.centerOfMass(pm, d, q)
    I = np.zeros((3, 3))
    for i in range(1, pm.njoints):
        Y = d.oMi[i].act(pm.inertias[i])
        r = Y.lever - c
        I += Y.inertia + Y.mass * (r @ r * np.eye(3) - np.outer(r, r))
    np.testing.assert_allclose(bl.composite_inertia(model, model.vehicle.q_nominal_rad), I, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(I) > 0)


def test_free_flight_converges_to_a_hover_reference(model, bparams, mission):
    """Against pinocchio's dynamics (amcore.ideal), from 0.15 m and 0.1 rad off a hover reference,
    the CoM settles within 5 mm and the attitude within 5 mrad in 4 s; the arm holds the pad on y_d."""
    ref0 = mission.reference(0.0)
    hover = Reference(ref0.r_c, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), ref0.psi, 0.0, 0.0, ref0.y,
                      np.zeros(3), np.zeros(3))
    x0 = mission.initial_state()
    x0 = AmState(x0.p_WB + [0.15, -0.1, -0.05], x0.R_WB @ exp_so3(np.array([0.05, -0.05, 0.1])), x0.v_B, x0.w_B,
                 x0.q + [0.05, -0.05, 0.05], x0.qdot)
    out = run_closed_loop(model, bparams, lambda t: hover, x0, 4.0, every=100, law=bl.step,
                          memory=bl.BaselineMemory())
    first, last = out[0].result.diagnostics, out[-1].result.diagnostics
    assert np.linalg.norm(first.r_c_err) > 0.1
    assert np.linalg.norm(last.r_c_err) < 5e-3
    assert np.linalg.norm(last.e_R) < 5e-3
    assert np.abs(last.y_err).max() < 5e-3
    assert np.linalg.norm(out[-1].state.v_B) < 0.02
