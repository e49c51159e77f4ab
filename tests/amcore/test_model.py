"""Structure of the inertially decoupled dynamics (eq. new_coord, eq. T_structure, eq. new_dynamics)."""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from amcore.model import AmState, create_data, decoupled_terms, generalized_gravity
from amcore.so3 import exp_so3, hat

from .conftest import flow, states

TOL = 1e-9


def test_mass_matrix_is_symmetric_and_C_skew_consistent(model, data):
    for st in states(model):
        tm = decoupled_terms(model, data, st)
        assert np.abs(tm.M - tm.M.T).max() < 1e-12
        h = 1e-5
        Mp = decoupled_terms(model, create_data(model), flow(model, st, h)).M
        Mm = decoupled_terms(model, create_data(model), flow(model, st, -h)).M
        Mdot_fd = (Mp - Mm) / (2 * h)
        S = Mdot_fd - 2 * tm.C
        assert np.abs(S + S.T).max() < 1e-7


def test_N_matches_its_definition_and_has_the_paper_shape(model, data):
    """N = (Z M Z^T)^-1 Z M with Z = [-(dr_bc/dq)^T R_b, 0, I] equals [0, N_1, I]."""
    n = model.n
    for st in states(model):
        tm = decoupled_terms(model, data, st)
        dr_bc_dq = st.R_WB @ tm.J_b  # world frame
        Z = np.hstack([-dr_bc_dq.T @ st.R_WB, np.zeros((n, 3)), np.eye(n)])
        Jc = tm.T[0:3]
        Jw = tm.T[3:6]
        assert np.abs(Z @ np.vstack([Jc, Jw]).T).max() < TOL
        N = np.linalg.solve(Z @ tm.M @ Z.T, Z @ tm.M)
        assert np.abs(N[:, 0:3]).max() < TOL
        assert np.abs(N[:, 6:] - np.eye(n)).max() < TOL
        assert np.abs(N[:, 3:6] - tm.N1).max() < TOL


def test_com_jacobian_row_matches_pinocchio(model, data):
    for st in states(model):
        tm = decoupled_terms(model, data, st)
        Jcom = pin.jacobianCenterOfMass(model.pin_model, create_data(model), st.pin_q())
        assert np.abs(tm.T[0:3] - Jcom).max() < TOL
        com = pin.centerOfMass(model.pin_model, create_data(model), st.pin_q())
        assert np.abs(tm.r_c - com).max() < TOL
        r_bc = st.R_WB @ tm.r_b
        assert np.abs(tm.T[0:3, 3:6] - (-hat(r_bc) @ st.R_WB)).max() < TOL


def test_T_inverse_and_T_structure(model, data):
    for st in states(model):
        tm = decoupled_terms(model, data, st)
        assert np.abs(tm.T @ tm.T_inv - np.eye(model.nv)).max() < TOL
        TmT = np.linalg.inv(tm.T).T
        assert np.abs(TmT[0:3, 0:3] - st.R_WB).max() < TOL  # eq. T_structure
        assert np.abs(TmT[0:3, 3:]).max() < TOL


def test_Lambda_xi_block_diagonal_with_mI(model, data):
    n, m = model.n, model.mass_kg
    for st in states(model):
        tm = decoupled_terms(model, data, st)
        L = tm.Lambda_xi
        assert np.abs(L[0:3, 0:3] - m * np.eye(3)).max() < TOL
        assert np.abs(L[0:3, 3:]).max() < TOL
        assert np.abs(L[3:6, 6:]).max() < TOL
        assert np.abs(L - L.T).max() < TOL
        assert np.abs(tm.Lambda_xi_inv @ L - np.eye(6 + n)).max() < 1e-8


def test_Tdot_against_finite_differences(model, data):
    h = 1e-5
    for st in states(model):
        tm = decoupled_terms(model, data, st, full=True)
        Tp = decoupled_terms(model, create_data(model), flow(model, st, h)).T
        Tm = decoupled_terms(model, create_data(model), flow(model, st, -h)).T
        assert np.abs(tm.Tdot - (Tp - Tm) / (2 * h)).max() < 1e-7
        assert np.abs(tm.Tdot @ tm.V - tm.Tdot_V).max() < TOL


def test_Gamma_xi_zero_blocks_and_skew_symmetry(model, data):
    """Gamma_xi's first block row/column vanish; dLambda_xi/dt - 2 Gamma_xi is skew."""
    h = 1e-5
    for st in states(model):
        tm = decoupled_terms(model, data, st, full=True)
        G = tm.Gamma_xi
        assert np.abs(G[0:3]).max() < TOL
        assert np.abs(G[:, 0:3]).max() < TOL
        assert np.abs(G @ tm.xi - tm.Gamma_xi_xi).max() < TOL
        # off-diagonal blocks are Gamma_wb,rho and -Gamma_wb,rho^T (eq. new_dynamics)
        Lp = decoupled_terms(model, create_data(model), flow(model, st, h)).Lambda_xi
        Lm = decoupled_terms(model, create_data(model), flow(model, st, -h)).Lambda_xi
        Ldot = (Lp - Lm) / (2 * h)
        S = Ldot - 2 * G
        assert np.abs(S + S.T).max() < 1e-7
        assert np.abs(Ldot - (G + G.T)).max() < 1e-7


def test_transformed_dynamics_reproduce_forward_dynamics(model, data):
    """Lambda_xi xidot + Gamma_xi xi + zeta_xi = u + F_xi with u = T^-T tau (eq. new_dynamics)."""
    rng = np.random.default_rng(3)
    pm = model.pin_model
    m, g = model.mass_kg, model.gravity_mps2
    for st in states(model):
        f = 15 + rng.normal()
        tau = np.concatenate([[0, 0, f], rng.normal(size=3), rng.normal(size=model.n)])
        F_e = rng.normal(size=6)
        d2 = create_data(model)
        q, v = st.pin_q(), st.pin_v()
        pin.computeJointJacobians(pm, d2, q)
        pin.updateFramePlacements(pm, d2)
        J_e = pin.getFrameJacobian(pm, d2, model.ee_frame_id, pin.LOCAL)
        Vdot = pin.aba(pm, d2, q, v, tau + J_e.T @ F_e)
        tm = decoupled_terms(model, data, st, full=True)
        xidot = tm.T @ Vdot + tm.Tdot_V
        zeta = tm.T_inv.T @ generalized_gravity(model, create_data(model), st)
        assert np.abs(zeta - np.concatenate([[0, 0, m * g], np.zeros(3 + model.n)])).max() < 1e-8
        u = tm.T_inv.T @ tau
        assert np.abs(u[0:3] - f * st.R_WB[:, 2]).max() < TOL  # u_1 = f
        F_xi = tm.T_inv.T @ J_e.T @ F_e
        R_WE = d2.oMf[model.ee_frame_id].rotation
        assert np.abs(F_xi[0:3] - R_WE @ F_e[0:3]).max() < TOL  # F_rc = R_e f_e
        lhs = tm.Lambda_xi @ xidot + tm.Gamma_xi @ tm.xi + zeta
        assert np.abs(lhs - (u + F_xi)).max() < 1e-8


def test_blockwise_terms_equal_their_generic_forms(model, data):
    """Lambda_xi^-1 (assembled from its blocks), T^-1 (closed form) and the products Tdot V,
    Gamma_xi xi agree with generic inverses and full matrix products."""
    for st in states(model, count=24, seed=9):
        tm = decoupled_terms(model, data, st, full=True)
        Li = tm.T @ np.linalg.solve(tm.M, tm.T.T)
        assert np.abs(tm.Lambda_xi_inv - Li).max() < TOL * np.abs(Li).max()
        assert np.abs(tm.Lambda_xi_inv - np.linalg.inv(tm.Lambda_xi)).max() < TOL * np.abs(Li).max()
        T_inv = np.linalg.inv(tm.T)
        assert np.abs(tm.T_inv - T_inv).max() < TOL * np.abs(T_inv).max()
        assert np.abs(tm.Tdot @ tm.V - tm.Tdot_V).max() < TOL * (1 + np.abs(tm.Tdot_V).max())
        G = T_inv.T @ (tm.C - tm.M @ T_inv @ tm.Tdot) @ T_inv
        assert np.abs(G @ tm.xi - tm.Gamma_xi_xi).max() < TOL * (1 + np.abs(tm.Gamma_xi_xi).max())
        Lxi = T_inv.T @ tm.M @ T_inv
        assert np.abs(tm.Lambda_xi - Lxi).max() < TOL * np.abs(Lxi).max()


def test_pin_q_quaternion_is_pinocchios(model):
    """AmState.pin_q builds the quaternion as pinocchio (Eigen) does, to the last bit or one ulp."""
    rng = np.random.default_rng(4)
    for k, st in enumerate(states(model, count=200, seed=4)):
        R = st.R_WB if k % 2 else st.R_WB @ exp_so3(np.array([np.pi, 0, 0]) + 1e-3 * rng.normal(size=3))
        quat = pin.Quaternion(R)
        quat.normalize()
        q_pin = AmState(st.p_WB, R, st.v_B, st.w_B, st.q, st.qdot).pin_q()
        assert np.abs(q_pin[3:7] - quat.coeffs()).max() <= 4.5e-16
        assert np.array_equal(q_pin[0:3], st.p_WB) and np.array_equal(q_pin[7:], st.q)


def test_pin_configuration_is_the_states_configuration_and_velocity_in_one_array():
    from amcore import law
    from amcore.model import pin_configuration
    from amcore.so3 import quat_xyzw_of_R

    rng = np.random.default_rng(2)
    R = exp_so3(rng.normal(size=3))
    quat = tuple(quat_xyzw_of_R(R))
    for with_quat in (True, False):
        s = AmState(rng.normal(size=3), R, rng.normal(size=3), rng.normal(size=3), rng.normal(size=3),
                    rng.normal(size=3), quat if with_quat else None)
        q_pin, V = pin_configuration(s)
        assert q_pin.tobytes() == s.pin_q().tobytes() and V.tobytes() == s.pin_v().tobytes()
        assert q_pin.flags.c_contiguous and V.flags.c_contiguous and q_pin.flags.writeable
        if with_quat:  # as the compiled joiner gives them
            a, b = law.free_flyer_configuration(s.p_WB, quat, s.q, s.v_B, s.w_B, s.qdot)
            assert a.tobytes() == q_pin.tobytes() and b.tobytes() == V.tobytes()
