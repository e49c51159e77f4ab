"""The control law: literal agreement, closed-loop identities, force compensation, guards."""
from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from amcore.control import ControllerMemory, pinocchio_terms, step
from amcore.filters import FilterState
from amcore.ideal import forward_dynamics, full_tau
from amcore.model import AmState, create_data, decoupled_terms
from amcore.so3 import exp_so3
from amcore.task import task_terms

from .literal import controller_literal

DT = 1e-3


def near_reference(mission, model, t, rng, scale=1.0):
    """A state close to the reference at t (errors well inside every saturation)."""
    x = mission.initial_state()
    ref = mission.reference(t)
    p_WB = ref.r_c - x.R_WB @ mission.nominal.r_BC
    return AmState(
        p_WB=p_WB + scale * 0.03 * rng.normal(size=3),
        R_WB=x.R_WB @ exp_so3(scale * 0.08 * rng.normal(size=3)),
        v_B=scale * 0.3 * rng.normal(size=3),
        w_B=scale * 0.5 * rng.normal(size=3),
        q=np.array(mission.q_nominal) + scale * 0.15 * rng.normal(size=model.n),
        qdot=scale * 0.5 * rng.normal(size=model.n),
    )


def steady_memory(model, st, F_e, t):
    """Filter state at steady state for a constant reading F_e (world-aligned at {e})."""
    d = create_data(model)
    pin.framesForwardKinematics(model.pin_model, d, st.pin_q())
    R_e = d.oMf[model.ee_frame_id].rotation
    W = np.concatenate([R_e @ F_e[0:3], R_e @ F_e[3:6]])
    return ControllerMemory(t_s=t - DT, wrench=FilterState(W, np.zeros(6)))


@pytest.mark.parametrize("comp", [True, False])
def test_fast_controller_agrees_with_literal_transcription(model, mission, params, comp):
    params = dataclasses.replace(params, force_compensation=comp)
    rng = np.random.default_rng(10 + comp)
    data = create_data(model)
    for t in (0.7, 2.1, 6.0, 11.3, 12.5):
        st = near_reference(mission, model, t, rng, scale=0.5)
        F_e = rng.normal(size=6) * np.array([5, 5, 5, 0.3, 0.3, 0.3])
        ref = mission.reference(t)
        res = step(model, data, params, st, ref, F_e, steady_memory(model, st, F_e, t), t)
        assert not res.diagnostics.com_err_saturated and not res.diagnostics.y_err_saturated
        assert res.diagnostics.damping == 0.0
        tau_lit = controller_literal(model, params, st, ref, F_e)
        assert np.abs(res.diagnostics.tau - tau_lit).max() < 1e-9 * max(1.0, np.abs(tau_lit).max())


def test_thrust_acts_along_body_z_only(model, mission, params):
    """tau = T^T u has zero first two entries (eq. new_dynamics, u_1 R_b e_3)."""
    rng = np.random.default_rng(4)
    data = create_data(model)
    mem = ControllerMemory()
    for k in range(20):
        st = near_reference(mission, model, 0.5 * k, rng, scale=2.0)
        res = step(model, data, params, st, mission.reference(0.5 * k), rng.normal(size=6), mem, 0.5 * k)
        assert np.abs(res.diagnostics.tau[0:2]).max() < 1e-10
        assert res.command.thrust_n == pytest.approx(res.diagnostics.f_d @ st.R_WB[:, 2])


def _closed_loop_accel(model, params, mission, st, t, F_e, comp=True):
    params = dataclasses.replace(params, force_compensation=comp)
    data = create_data(model)
    ref = mission.reference(t)
    res = step(model, data, params, st, ref, F_e, steady_memory(model, st, F_e, t), t)
    Vdot = forward_dynamics(model, create_data(model), st.pin_q(), st.pin_v(), full_tau(res.command, model.n), F_e)
    d2 = create_data(model)
    tm = decoupled_terms(model, d2, st)
    tk = task_terms(model, d2, tm, params.task_frame, params.components)
    return res, ref, Vdot, tm, tk


@pytest.mark.parametrize("comp", [True, False])
def test_task_space_impedance_identity_under_contact(model, mission, params, comp):
    """Lambda_y y~dd + D_y y~d + K_y y~ = F_y (eq. desired_task_behavior) holds exactly, with or
    without force compensation, for an arbitrary end-effector wrench."""
    rng = np.random.default_rng(20)
    for t in (1.0, 7.0, 12.0):
        st = near_reference(mission, model, t, rng, scale=0.5)
        F_e = rng.normal(size=6) * np.array([8, 8, 8, 0.5, 0.5, 0.5])
        res, ref, Vdot, tm, tk = _closed_loop_accel(model, params, mission, st, t, F_e, comp)
        dg = res.diagnostics
        assert not dg.y_err_saturated  # the identity is the unsaturated spring's
        yddot = tk.J_y @ Vdot + tk.Jdot_y_V
        lhs = dg.Lambda_y @ (yddot - ref.y_d2) + params.D_y @ (dg.ydot - ref.y_d1) + params.K_y @ dg.y_err
        assert np.abs(lhs - dg.F_y).max() < 1e-8 * (1 + np.abs(dg.F_y).max())
        assert np.abs(dg.F_y).max() > 0.1


def test_orientation_closed_loop_identity(model, mission, params):
    """With compensation: Lambda_wb,d e_w_dot + k_w e_w + k_R e_R = 0 (eq. closed_loop)."""
    rng = np.random.default_rng(21)
    h = 1e-6
    for t in (1.0, 6.0, 12.0):
        st = near_reference(mission, model, t, rng, scale=0.5)
        F_e = rng.normal(size=6) * np.array([8, 8, 8, 0.5, 0.5, 0.5])
        res, ref, Vdot, tm, tk = _closed_loop_accel(model, params, mission, st, t, F_e)
        dg = res.diagnostics
        e_w_dot = Vdot[3:6] - dg.wdot_bd
        Ld = np.linalg.inv(params.Lambda_wb_d_inv)
        lhs = Ld @ e_w_dot + params.k_w * dg.e_w + params.k_R * dg.e_R
        assert np.abs(lhs).max() < 1e-8
        # and wdot_bd is the derivative of w_bd along the closed loop, for a contact force
        # constant in {w} (what the filter's derivatives describe at steady state)
        q2 = pin.integrate(model.pin_model, st.pin_q(), st.pin_v() * h)
        st2 = AmState.from_pin(q2, st.pin_v() + Vdot * h)
        R1, R2 = _R_e(model, st), _R_e(model, st2)
        F_e2 = np.concatenate([R2.T @ R1 @ F_e[0:3], R2.T @ R1 @ F_e[3:6]])
        res2 = step(model, create_data(model), params, st2, mission.reference(t + h), F_e2,
                    steady_memory(model, st2, F_e2, t + h), t + h)
        fd = (res2.diagnostics.w_bd - dg.w_bd) / h
        assert np.abs(fd - dg.wdot_bd).max() < 1e-3 * (1 + np.abs(dg.wdot_bd).max())


def _R_e(model, st):
    d = create_data(model)
    pin.framesForwardKinematics(model.pin_model, d, st.pin_q())
    return d.oMf[model.ee_frame_id].rotation.copy()


def test_without_compensation_the_wrench_does_not_reach_the_command(model, mission, params):
    """Force compensation off: f_d, Omega_d and the whole command ignore the F/T reading;
    Omega_d does not depend on F_e either."""
    p_off = dataclasses.replace(params, force_compensation=False)
    rng = np.random.default_rng(5)
    st = near_reference(mission, model, 6.0, rng)
    ref = mission.reference(6.0)
    zero = np.zeros(6)
    F_e = np.array([-12.0, 1.0, -4.9, 0.1, -0.2, 0.05])
    a = step(model, create_data(model), p_off, st, ref, zero, steady_memory(model, st, zero, 6.0), 6.0)
    b = step(model, create_data(model), p_off, st, ref, F_e, steady_memory(model, st, F_e, 6.0), 6.0)
    assert np.array_equal(a.diagnostics.tau, b.diagnostics.tau)
    assert np.array_equal(a.diagnostics.Omega_d, b.diagnostics.Omega_d)
    assert np.abs(b.diagnostics.F_y).max() > 1.0  # the sensor is still read for diagnostics
    # with compensation on, the same reading moves f_d by exactly -F_rc
    c = step(model, create_data(model), params, st, ref, F_e, steady_memory(model, st, F_e, 6.0), 6.0)
    d = step(model, create_data(model), params, st, ref, zero, steady_memory(model, st, zero, 6.0), 6.0)
    assert np.abs((c.diagnostics.f_d - d.diagnostics.f_d) + c.diagnostics.F_rc).max() < 1e-12
    assert not np.allclose(c.diagnostics.Omega_d, d.diagnostics.Omega_d)


def test_along_face_uncompensated_leaves_only_that_component_out_of_f_d(model, mission, params):
    """[options].compensate_along_face = false: f_d moves by -F_rc less its component along
    the task frame's y axis (the face's horizontal); a reading with no such component gives
    the paper's step exactly; the arm's and the attitude's use of the wrench are unchanged."""
    p_face = dataclasses.replace(params, compensate_along_face=False)
    y_W = params.task_frame.R_WT[:, 1]
    rng = np.random.default_rng(7)
    st = near_reference(mission, model, 6.0, rng)
    ref = mission.reference(6.0)
    zero = np.zeros(6)
    F_e = np.array([-12.0, 1.5, -4.9, 0.1, -0.2, 0.05])
    mem = steady_memory(model, st, F_e, 6.0)
    paper = step(model, create_data(model), params, st, ref, F_e, mem, 6.0)
    face = step(model, create_data(model), p_face, st, ref, F_e, mem, 6.0)
    free = step(model, create_data(model), p_face, st, ref, zero, steady_memory(model, st, zero, 6.0), 6.0)
    F_rc = paper.diagnostics.F_rc
    assert abs(F_rc @ y_W) > 1.0  # the reading pushes along the face
    expected = F_rc - (F_rc @ y_W) * y_W
    assert np.abs((face.diagnostics.f_d - free.diagnostics.f_d) + expected).max() < 1e-12
    assert np.abs(face.diagnostics.f_d - paper.diagnostics.f_d - (F_rc @ y_W) * y_W).max() < 1e-12
    np.testing.assert_array_equal(face.diagnostics.F_y, paper.diagnostics.F_y)
    # a reading without a push along the face: the same step as the paper's, bit for bit
    n_W = F_rc - (F_rc @ y_W) * y_W
    d = create_data(model)
    pin.framesForwardKinematics(model.pin_model, d, st.pin_q())
    R_e = d.oMf[model.ee_frame_id].rotation
    F_n = np.concatenate([R_e.T @ n_W, F_e[3:6]])
    mem_n = steady_memory(model, st, F_n, 6.0)
    a = step(model, create_data(model), params, st, ref, F_n, mem_n, 6.0)
    b = step(model, create_data(model), p_face, st, ref, F_n, mem_n, 6.0)
    np.testing.assert_allclose(a.diagnostics.tau, b.diagnostics.tau, rtol=0, atol=1e-9)


def test_singularity_guard_bounds_torques_near_a_straight_elbow(model, mission, params):
    """Reference far beyond reach, elbow straightening (q2 -> 0): Jbar_3 loses rank. With the
    damped inverse the joint torques stay bounded; the undamped law (sigma_damping = 0)
    demands torques that grow like 1/q2."""
    st0 = mission.initial_state()
    ref = mission.reference(5.0)
    torques = {}
    for guard in (True, False):
        p = params if guard else dataclasses.replace(params, sigma_damping=0.0)
        worst = 0.0
        for q2 in (1e-2, 3e-3, 1e-3, 1e-4, 1e-5):
            q = np.array([0.5, q2, 0.0])
            st = AmState(st0.p_WB, st0.R_WB, np.zeros(3), np.zeros(3), q, np.zeros(3))
            res = step(model, create_data(model), p, st, ref, np.zeros(6), ControllerMemory(), 5.0)
            worst = max(worst, np.abs(res.command.tau_q_nm).max())
            if guard and q2 <= 1e-3:
                assert res.diagnostics.sigma_min_J3 < params.sigma_damping
                assert res.diagnostics.damping > 0.0
        torques[guard] = worst
    assert torques[True] < 150.0
    assert torques[False] > 50 * torques[True]


def test_guard_is_inactive_across_the_working_range(model, mission, params):
    """Away from a straight elbow the law is exactly the paper's (no damping engaged)."""
    st0 = mission.initial_state()
    for q1 in np.linspace(0.2, 1.8, 9):
        for q2 in np.linspace(-2.0, -0.2, 10):
            for q3 in (-0.8, 0.0, 0.8):
                st = AmState(st0.p_WB, st0.R_WB, np.zeros(3), np.zeros(3), np.array([q1, q2, q3]), np.zeros(3))
                res = step(model, create_data(model), params, st, mission.reference(1.0), np.zeros(6),
                           ControllerMemory(), 1.0)
                assert res.diagnostics.damping == 0.0, (q1, q2, q3, res.diagnostics.sigma_min_J3)


def test_error_saturation_is_reported(model, mission, params):
    st0 = mission.initial_state()
    far = AmState(st0.p_WB + np.array([2.0, 0, 0]), st0.R_WB, st0.v_B, st0.w_B, st0.q + 0.6, st0.qdot)
    res = step(model, create_data(model), params, far, mission.reference(0.0), np.zeros(6), ControllerMemory(), 0.0)
    assert res.diagnostics.com_err_saturated and res.diagnostics.y_err_saturated
    assert np.all(np.isfinite(res.diagnostics.tau))


def test_diagnostics_fields_hold_what_their_names_say(model, mission, params):
    """step builds Diagnostics positionally: every field checked against its meaning."""
    from amcore.task import task_terms

    rng = np.random.default_rng(8)
    t = 6.0
    st = near_reference(mission, model, t, rng, scale=0.5)
    F_e = rng.normal(size=6)
    ref = mission.reference(t)
    res = step(model, create_data(model), params, st, ref, F_e, steady_memory(model, st, F_e, t), t)
    d, c = res.diagnostics, res.command
    data = create_data(model)
    tm = decoupled_terms(model, data, st)
    tk = task_terms(model, data, tm, params.task_frame, params.components)
    close = lambda a, b: np.abs(np.asarray(a) - np.asarray(b)).max() < 1e-9 * (1 + np.abs(b).max())  # noqa: E731
    assert close(d.r_c, tm.r_c) and close(d.r_c_d, ref.r_c) and close(d.r_c_err, tm.r_c - ref.r_c)
    assert close(d.rdot_c, tm.xi[0:3]) and close(d.R_WB, st.R_WB)
    assert close(d.R_d.T @ d.R_d, np.eye(3)) and close(d.R_d[:, 2], d.f_d / np.linalg.norm(d.f_d))
    assert close(d.w_bd, st.R_WB.T @ d.R_d @ d.Omega_d) and close(d.e_w, st.w_B - d.w_bd)
    E = d.R_d.T @ st.R_WB - st.R_WB.T @ d.R_d
    assert close(d.e_R, 0.5 * np.array([E[2, 1], E[0, 2], E[1, 0]]))
    assert close(d.y, tk.y) and close(d.y_d, ref.y) and close(d.y_err, tk.y - ref.y) and close(d.ydot, tk.J @ tm.xi)
    R_e = tk.R_WE
    W = np.concatenate([R_e @ F_e[0:3], R_e @ F_e[3:6]])  # the filter sits at steady state
    assert close(d.wrench_W_filtered, W) and close(d.F_rc, W[0:3])
    assert close(d.wrench_E_filtered, F_e)
    assert close(d.F_y, d.Lambda_y @ tk.J @ tm.Lambda_xi_inv @ tm.T_inv.T @ tk.J_e.T @ F_e)
    assert close(d.Lambda_y, np.linalg.inv(tk.J @ tm.Lambda_xi_inv @ tk.J.T))
    assert close(d.tau, tm.T.T @ d.u) and close(d.u[0:3], c.thrust_n * st.R_WB[:, 2])
    assert close(c.tau_B_nm, d.tau[3:6]) and close(c.tau_q_nm, d.tau[6:])
    assert d.Lambda_y_dot is None and d.damping == 0.0 and d.sigma_min_J3 > params.sigma_damping
    assert d.com_err_saturated is False and d.y_err_saturated is False
    assert res.memory.t_s == t and close(res.memory.wrench.x, W) and close(res.memory.wrench.xdot, np.zeros(6))
    # the command and the next step's memory do not share memory with the diagnostics
    assert not np.shares_memory(c.tau_q_nm, d.tau) and not np.shares_memory(res.memory.wrench.x, d.wrench_W_filtered)


def test_carried_quaternion_gives_the_same_step(model, mission, params):
    """AmState.quat_xyzw (as state_from_frame sets it) only saves recovering it from R_WB."""
    from amcore.so3 import quat_xyzw_of_R

    rng = np.random.default_rng(9)
    for t in (1.0, 7.0):
        st = near_reference(mission, model, t, rng)
        x, y, z, w = quat_xyzw_of_R(st.R_WB)
        st_q = st._replace(quat_xyzw=(-x, -y, -z, -w))  # the other sign: same rotation
        ref = mission.reference(t)
        a = step(model, create_data(model), params, st, ref, np.ones(6), ControllerMemory(), t)
        b = step(model, create_data(model), params, st_q, ref, np.ones(6), ControllerMemory(), t)
        assert np.abs(a.diagnostics.tau - b.diagnostics.tau).max() < 1e-12 * np.abs(a.diagnostics.tau).max()
        assert np.array_equal(st_q.pin_q()[3:7], [-x, -y, -z, -w])


def test_diagnostics_keep_their_field_names(model, mission, params):
    """Every field the diagnostics had before the compiled law, by name, on a real step."""
    names = ("r_c r_c_d r_c_err rdot_c e_R e_w R_WB R_d w_bd wdot_bd Omega_d f_d y y_d y_err ydot F_y F_rc "
             "wrench_E_filtered sigma_min_J3 damping com_err_saturated y_err_saturated u tau Lambda_y Lambda_y_dot "
             "wrench_W_filtered decoupled task").split()
    st = mission.initial_state()
    d = step(model, create_data(model), params, st, mission.reference(1.0), np.zeros(6), ControllerMemory(), 1.0).diagnostics
    for name in names:
        getattr(d, name)  # AttributeError names a lost field
    assert d.decoupled.T_inv.shape == (model.nv, model.nv) and d.task.J_y.shape == (model.n, model.nv)
    n = model.n
    for name, shape in (("r_c", (3,)), ("R_d", (3, 3)), ("y", (n,)), ("u", (n + 6,)), ("tau", (n + 6,)),
                        ("Lambda_y", (n, n)), ("wrench_W_filtered", (6,)), ("q_d", (4,))):
        assert np.shape(getattr(d, name)) == shape, name


def test_pinocchio_terms_equal_those_of_a_fresh_forward_kinematics(model):
    """`pinocchio_terms` reads the CoM Jacobian from the Coriolis pass's joint placements
    (pinocchio's overload without q) instead of running forward kinematics again: the six
    terms equal, bit for bit, those of each call made from q on its own data."""
    pm, fid = model.pin_model, model.ee_frame_id
    rng = np.random.default_rng(26)
    data = pm.createData()
    for _ in range(300):
        q = np.concatenate([rng.normal(size=3), rng.normal(size=4), rng.uniform(-3.0, 3.0, model.n)])
        q[3:7] /= np.linalg.norm(q[3:7])
        v = rng.normal(size=pm.nv) * rng.choice([1e-3, 1.0, 10.0])
        got = [x.copy() for x in pinocchio_terms(pm, data, fid, q, v)]
        fresh = pm.createData()
        pin.computeCoriolisMatrix(pm, fresh, q, v)  # data.dJ for the frame's time variation
        want = [pin.jacobianCenterOfMass(pm, pm.createData(), q, False), pin.computeMinverse(pm, pm.createData(), q),
                pin.computeCoriolisMatrix(pm, pm.createData(), q, v), pin.updateFramePlacement(pm, fresh, fid).homogeneous,
                pin.getFrameJacobian(pm, fresh, fid, pin.LOCAL), pin.getFrameJacobianTimeVariation(pm, fresh, fid, pin.LOCAL)]
        for name, x, y in zip(("Jcom", "M_inv", "C", "H_WE", "J_e", "Jdot_e"), got, want):
            assert np.array_equal(x, y), name
