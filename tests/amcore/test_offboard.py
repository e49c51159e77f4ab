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
from amcore.offboard import Applied, OffboardMemory, OffboardParams, offboard_step
from amcore.task import task_terms

from . import reference_offboard
from .reference_offboard import body_torque_estimate, filtered_body_torque_estimate, joint_torques_for_body_torque
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


def _one_period(model, mission, params, rng, t, f, tau_b, tau_q, F_e, h=1e-6):
    """The state after a short period h under tau = [0, 0, f, tau_b, tau_q] from a state near
    the reference at t, and the controller's step there."""
    st = near_reference(mission, model, t, rng, scale=0.5)
    tau = np.concatenate([[0.0, 0.0, f], tau_b, tau_q])
    Vdot = forward_dynamics(model, create_data(model), st.pin_q(), st.pin_v(), tau, F_e)
    st2 = AmState.from_pin(pin.integrate(model.pin_model, st.pin_q(), st.pin_v() * h), st.pin_v() + Vdot * h)
    res = step(model, create_data(model), params, st2, mission.reference(t + h), F_e,
               steady_memory(model, st2, F_e, t + h), t + h)
    return st, st2, res


def test_a_lost_setpoint_no_longer_changes_the_torque_estimate(model, mission, params):
    """The companion's last setpoint was lost: the vehicle flew the one before (f, tau_q) while
    the companion remembers what it sent (f', tau_q'). With the reported inputs the estimate is
    the applied body torque whatever was sent; with the sent ones it is off by K (f' - f, tau_q' - tau_q)."""
    rng = np.random.default_rng(60)
    h, t, F_e = 1e-6, 4.0, _wrench(rng)
    f, tau_b, tau_q = 19.0, rng.normal(size=3), rng.normal(size=model.n)
    st, st2, res = _one_period(model, mission, params, rng, t, f, tau_b, tau_q, F_e, h)
    applied = Applied(f, tau_q)
    estimates = []
    for f_sent, tau_q_sent in ((f, tau_q), (f + 2.0, tau_q + 1.5), (f - 1.0, -tau_q)):
        mem = OffboardMemory(res.memory, t, tuple(st.w_B), f_sent, tau_q_sent)
        reported = body_torque_estimate(params, res, mem, st2, t + h, applied)
        np.testing.assert_allclose(reported, tau_b, atol=1e-4)
        estimates.append(reported)
        sent = body_torque_estimate(params, res, mem, st2, t + h)
        if f_sent != f:
            assert np.abs(sent - tau_b).max() > 0.05  # the literal law's error, which the option removes
    np.testing.assert_array_equal(estimates[1], estimates[2])  # nothing of what was sent enters


def test_missing_reports_fall_back_to_what_was_sent(model, mission, params):
    rng = np.random.default_rng(61)
    h, t, F_e = 1e-6, 4.0, _wrench(rng)
    f, tau_b, tau_q = 19.0, rng.normal(size=3), rng.normal(size=model.n)
    st, st2, res = _one_period(model, mission, params, rng, t, f, tau_b, tau_q, F_e, h)
    mem = OffboardMemory(res.memory, t, tuple(st.w_B), f, tau_q)
    ref = body_torque_estimate(params, res, mem, st2, t + h)
    for applied in (Applied(), Applied(f, None), Applied(None, tau_q)):
        np.testing.assert_array_equal(body_torque_estimate(params, res, mem, st2, t + h, applied), ref)


def _filtered_run(params, oparams, res, st, mem, w_of_t, dt, steps):
    out = []
    for k in range(1, steps + 1):
        t = mem.t_s + dt
        st_k = st._replace(w_B=w_of_t(t))
        est, w_f, r_f = filtered_body_torque_estimate(params, oparams, res, mem, st_k, t)
        mem = dataclasses.replace(mem, t_s=t, w_B=tuple(st_k.w_B), w_filter=w_f, r_filter=r_f)
        out.append(est)
    return out


def test_the_filtered_estimate_converges_to_the_backward_difference_on_a_constant_acceleration(model, mission,
                                                                                             params):
    """w_b ramping at a constant rate, everything else held: after a few of the filter's time
    constants the filtered estimate is the backward difference's."""
    rng = np.random.default_rng(62)
    t0, F_e, dt = 4.0, _wrench(rng), 0.004
    st = near_reference(mission, model, t0, rng, scale=0.5)
    res = step(model, create_data(model), params, st, mission.reference(t0), F_e, steady_memory(model, st, F_e, t0), t0)
    a = np.array([10.0, -20.0, 4.0])  # rad/s^2
    w = lambda t: st.w_B + a * (t - t0)  # noqa: E731
    oparams = OffboardParams("sent", 40.0)
    est0, w_f, _ = filtered_body_torque_estimate(params, oparams, res, OffboardMemory(), st, t0)
    assert est0 is None
    mem = OffboardMemory(res.memory, t0, tuple(st.w_B), 18.0, np.zeros(model.n), w_f, None)
    est = _filtered_run(params, oparams, res, st, mem, w, dt, 60)
    raw = body_torque_estimate(params, res, dataclasses.replace(mem, t_s=t0 + 59 * dt, w_B=tuple(w(t0 + 59 * dt))),
                               st._replace(w_B=w(t0 + 60 * dt)), t0 + 60 * dt)
    La = np.abs(res.diagnostics.terms.Lambda_w @ a).max()
    assert np.abs(est[-1] - raw).max() < 1e-6 * La
    assert np.abs(est[0] - raw).max() > 0.3 * La  # it starts elsewhere: the filter does act


def test_the_filtered_estimate_attenuates_gyro_noise_as_its_bandwidth_says(model, mission, params):
    """White noise on w_b: the backward difference amplifies it by ~sqrt(2)/dt; the estimate
    through a 40 Hz Butterworth at 250 Hz far less (measured ratio of the two RMS errors)."""
    rng = np.random.default_rng(63)
    t0, F_e, dt = 4.0, _wrench(rng), 0.004
    st = near_reference(mission, model, t0, rng, scale=0.5)
    res = step(model, create_data(model), params, st, mission.reference(t0), F_e, steady_memory(model, st, F_e, t0), t0)
    noise = {}
    w = lambda t: st.w_B + noise.setdefault(round(t / dt), 1e-3 * rng.standard_normal(3))  # noqa: E731
    oparams = OffboardParams("sent", 40.0)
    _, w_f, _ = filtered_body_torque_estimate(params, oparams, res, OffboardMemory(), st._replace(w_B=w(t0)), t0)
    mem = OffboardMemory(res.memory, t0, tuple(w(t0)), 18.0, np.zeros(model.n), w_f, None)
    est = np.array(_filtered_run(params, oparams, res, st, mem, w, dt, 2000)[200:])
    raw = []
    for k in range(201, 2001):
        t = t0 + k * dt
        m = dataclasses.replace(mem, t_s=t - dt, w_B=tuple(w(t - dt)))
        raw.append(body_torque_estimate(params, res, m, st._replace(w_B=w(t)), t))
    raw = np.array(raw)
    ratio = (est - est.mean(axis=0)).std() / (raw - raw.mean(axis=0)).std()
    assert ratio < 0.5


@pytest.mark.parametrize("inputs,cutoff_hz", [("sent", 0.0), ("reported", 0.0), ("sent", 40.0), ("reported", 40.0)])
@pytest.mark.parametrize("comp,damped", [(True, False), (False, False), (True, True)])
def test_the_compiled_step_is_its_numpy_reference_to_rounding(model, mission, params, inputs, cutoff_hz, comp, damped):
    """offboard_step (amcore.law.attitude_mode_torques) and its numpy reference
    (tests/amcore/reference_offboard.py), fed the same sequence (reports missing on some steps, the arm's
    inversion damped or not): the same tau, u = T^-T tau, estimate and filter states."""
    params = dataclasses.replace(params, force_compensation=comp, **({"sigma_damping": 1e3} if damped else {}))
    oparams = OffboardParams(inputs, cutoff_hz)
    rng = np.random.default_rng(61)
    mems = [OffboardMemory(), OffboardMemory()]
    for k in range(12):
        t = 4.0 + 4e-3 * k
        st, F_e = near_reference(mission, model, t, rng, scale=0.5), _wrench(rng)
        applied = Applied(20.0 + rng.normal(), rng.normal(size=model.n)) if k % 3 else Applied()
        out = [f(model, create_data(model), params, st, mission.reference(t), F_e, mem, t, oparams=oparams,
                 applied=applied) for mem, f in zip(mems, (offboard_step, reference_offboard.offboard_step))]
        fast, slow = (o.result.diagnostics for o in out)
        assert (fast.damping > 0.0) == damped
        assert (out[0].tau_b_hat is None) == (out[1].tau_b_hat is None) == (k == 0)
        np.testing.assert_allclose(fast.tau, slow.tau, rtol=1e-12, atol=1e-12 * np.abs(slow.tau).max())
        np.testing.assert_allclose(fast.u, slow.u, rtol=1e-12, atol=1e-12 * np.abs(slow.u).max())
        np.testing.assert_array_equal(out[0].result.command.tau_q_nm, fast.tau[6:])
        for a, b in ((out[0].memory.w_filter, out[1].memory.w_filter), (out[0].memory.r_filter, out[1].memory.r_filter)):
            assert (a is None) == (b is None)
            if a is not None:
                np.testing.assert_allclose(np.array(a), np.array(b), rtol=1e-12, atol=1e-12)
        mems = [o.memory for o in out]


@pytest.mark.parametrize("cutoff_hz", [0.0, 40.0])
@pytest.mark.parametrize("damped", [False, True])
def test_the_packed_reader_hands_the_kernel_the_steps_terms_bit_for_bit(model, mission, params, cutoff_hz, damped):
    """amcore.law.attitude_mode_torques_of_packed reads the step's terms from control_law's
    packed result at amcore.control.packed_offsets: the same bits as attitude_mode_torques
    handed the Diagnostics' named fields."""
    from amcore import law
    from amcore.control import packed_offsets
    from amcore.offboard import _TERMS_READ

    params = dataclasses.replace(params, **({"sigma_damping": 1e3} if damped else {}))
    rng = np.random.default_rng(62)
    for k in range(6):
        t = 4.0 + 4e-3 * k
        st, F_e = near_reference(mission, model, t, rng, scale=0.5), _wrench(rng)
        res = step(model, create_data(model), params, st, mission.reference(t), F_e, steady_memory(model, st, F_e, t), t)
        c, d, n = res.command, res.diagnostics, model.n
        assert (d.damping > 0.0) == damped
        Phi = OffboardParams("reported", cutoff_hz).torque_filter.transition(4e-3) if cutoff_hz else np.zeros((0, 0))
        w_filter = rng.normal(size=(2, 3)) if cutoff_hz else np.zeros((0, 3))
        r_filter = rng.normal(size=(2, 3)) if cutoff_hz else np.zeros((0, 3))
        rest = (c.thrust_n, c.tau_B_nm, c.tau_q_nm, 19.5, rng.normal(size=n), st.w_B, st.w_B + 0.01, 4e-3, Phi,
                w_filter, r_filter)
        tm = d.terms
        named = law.attitude_mode_torques(tm.Lambda_w, tm.Gamma_xi_xi, tm.T_inv, tm.J_e_xi, d.wrench_E_filtered, 1.0,
                                          tm.J_y, tm.M_inv, d.Lambda_y, d.damping, *rest)
        packed = law.attitude_mode_torques_of_packed(d.packed, packed_offsets(n, _TERMS_READ), n, 1.0, *rest)
        for a, b in zip(packed, named):
            np.testing.assert_array_equal(a, b)
