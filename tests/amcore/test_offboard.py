"""Attitude mode's companion law (amcore.offboard) against pinocchio's forward dynamics: the
joint torques realize eq. desired_task_behavior for whatever body torque the autopilot
applies, and the body torque is recovered from the measured angular acceleration."""
from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from amcore.control import step
from amcore.ideal import forward_dynamics
from amcore.model import AmState, create_data, decoupled_terms
from amcore.offboard import OffboardMemory, body_torque_estimate, joint_torques_for_body_torque, offboard_step
from amcore.task import task_terms

from .test_control import near_reference, steady_memory


def _wrench(rng):
    return rng.normal(size=6) * np.array([8, 8, 8, 0.5, 0.5, 0.5])


@pytest.mark.parametrize("comp", [True, False])
def test_joint_torques_realize_the_impedance_for_any_body_torque(model, mission, params, comp):
    """Eq. desired_task_behavior, Lambda_y y~dd + D_y y~d + K_y y~ = F_y, holds with
    tau = [0, 0, f, tau_b, tau_q(tau_b)] for body torques unrelated to eq. ori_controller."""
    params = dataclasses.replace(params, force_compensation=comp)
    rng = np.random.default_rng(30 + comp)
    for t in (1.0, 7.0, 12.0):
        st = near_reference(mission, model, t, rng, scale=0.5)
        F_e, ref = _wrench(rng), mission.reference(t)
        res = step(model, create_data(model), params, st, ref, F_e, steady_memory(model, st, F_e, t), t)
        dg = res.diagnostics
        assert not dg.y_err_saturated and dg.damping == 0.0
        for tau_b in (rng.normal(size=3), 3.0 * rng.normal(size=3)):
            tau_q = joint_torques_for_body_torque(res, tau_b)
            tau = np.concatenate([[0.0, 0.0, res.command.thrust_n], tau_b, tau_q])
            Vdot = forward_dynamics(model, create_data(model), st.pin_q(), st.pin_v(), tau, F_e)
            d2 = create_data(model)
            tk = task_terms(model, d2, decoupled_terms(model, d2, st), params.task_frame, params.components)
            yddot = tk.J_y @ Vdot + tk.Jdot_y_V
            lhs = dg.Lambda_y @ (yddot - ref.y_d2) + params.D_y @ (dg.ydot - ref.y_d1) + params.K_y @ dg.y_err
            assert np.abs(lhs - dg.F_y).max() < 1e-8 * (1 + np.abs(dg.F_y).max())
            assert np.abs(tau_q - res.command.tau_q_nm).max() > 1e-3  # the arm did take something up
        # the body torque of torque mode gives torque mode's joint torques
        np.testing.assert_allclose(joint_torques_for_body_torque(res, res.command.tau_B_nm), res.command.tau_q_nm,
                                   atol=1e-12)


@pytest.mark.parametrize("comp", [True, False])
def test_body_torque_is_recovered_from_the_measured_angular_acceleration(model, mission, params, comp):
    """One short period under a known tau = [0, 0, f, tau_b, tau_q]: the estimate returns
    tau_b; with compensation off the wrench's moment is unknown and is left at zero here."""
    params = dataclasses.replace(params, force_compensation=comp)
    rng = np.random.default_rng(40 + comp)
    h = 1e-6
    for t in (2.0, 12.0):
        st = near_reference(mission, model, t, rng, scale=0.5)
        F_e = _wrench(rng) if comp else np.zeros(6)
        f, tau_b, tau_q = 20.0 + rng.normal(), rng.normal(size=3), rng.normal(size=model.n)
        tau = np.concatenate([[0.0, 0.0, f], tau_b, tau_q])
        Vdot = forward_dynamics(model, create_data(model), st.pin_q(), st.pin_v(), tau, F_e)
        st2 = AmState.from_pin(pin.integrate(model.pin_model, st.pin_q(), st.pin_v() * h), st.pin_v() + Vdot * h)
        mem = OffboardMemory(steady_memory(model, st2, F_e, t + h), t, tuple(st.w_B), f, tau_q)
        res = step(model, create_data(model), params, st2, mission.reference(t + h), F_e, mem.controller, t + h)
        est = body_torque_estimate(params, res, mem, st2, t + h)
        np.testing.assert_allclose(est, tau_b, atol=1e-4)


def test_first_step_is_torque_modes_then_the_bookkeeping_holds_the_estimate(model, mission, params):
    rng = np.random.default_rng(50)
    t, F_e = 6.0, _wrench(rng)
    st = near_reference(mission, model, t, rng, scale=0.5)
    ref = mission.reference(t)
    torque = step(model, create_data(model), params, st, ref, F_e, steady_memory(model, st, F_e, t), t)
    first = offboard_step(model, create_data(model), params, st, ref, F_e,
                          OffboardMemory(steady_memory(model, st, F_e, t)), t)
    assert first.tau_b_hat is None
    np.testing.assert_array_equal(first.result.command.tau_q_nm, torque.command.tau_q_nm)
    np.testing.assert_array_equal(first.result.command.tau_B_nm, torque.command.tau_B_nm)
    # a later step with a measured angular acceleration: tau and u = T^-T tau hold the estimate
    mem = dataclasses.replace(first.memory, w_B=tuple(st.w_B - 0.01), t_s=t - 1e-3)
    later = offboard_step(model, create_data(model), params, st, ref, F_e, mem, t)
    d, c = later.result.diagnostics, later.result.command
    np.testing.assert_array_equal(c.tau_B_nm, later.tau_b_hat)
    np.testing.assert_array_equal(d.tau, np.concatenate([[0.0, 0.0, c.thrust_n], c.tau_B_nm, c.tau_q_nm]))
    tm = decoupled_terms(model, create_data(model), st)
    np.testing.assert_allclose(tm.T.T @ d.u, d.tau, atol=1e-9)
    assert c.thrust_n == torque.command.thrust_n
