"""A slow, literal transcription of the paper's equations, independent of amcore's fast path.

It shares only M, C and the kinematics with pinocchio. Everything else is written as the
paper prints it: N from its definition (Ott's dynamically consistent projector), T
stacked row by row (eq. new_coord), T^-1 by generic inversion, Tdot and Jdot by
Richardson-extrapolated central differences along the motion (not the closed forms),
Lambda_xi = (T M^-1 T^T)^-1, Gamma_xi = T^-T (C - M T^-1 Tdot) T^-1, u_2 from the blocks of
eq. ori_controller and u_3 from the blocks of eq. u3. No saturation, no damping.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from amcore.attitude import desired_attitude
from amcore.model import AmState
from amcore.so3 import vee

E3 = np.array([0.0, 0.0, 1.0])


def _richardson(fun, h=1e-3):
    """d/dt fun(t) at 0, O(h^4)."""
    d1 = (fun(h) - fun(-h)) / (2 * h)
    d2 = (fun(h / 2) - fun(-h / 2)) / h
    return (4 * d2 - d1) / 3


def _kin(model, q_pin):
    pm = model.pin_model
    d = pm.createData()
    M = pin.crba(pm, d, q_pin)
    M = np.triu(M) + np.triu(M, 1).T
    Jc = pin.jacobianCenterOfMass(pm, d, q_pin).copy()
    com = d.com[0].copy()
    pin.framesForwardKinematics(pm, d, q_pin)
    return d, M, Jc, com


def T_of(model, q_pin):
    n = model.n
    d, M, Jc, _ = _kin(model, q_pin)
    R = d.oMi[1].rotation
    dr_dq = Jc[:, 6:]
    Z = np.hstack([-dr_dq.T @ R, np.zeros((n, 3)), np.eye(n)])
    N = np.linalg.inv(Z @ M @ Z.T) @ Z @ M
    Jw = np.hstack([np.zeros((3, 3)), np.eye(3), np.zeros((3, n))])
    return np.vstack([Jc, Jw, N])


def y_of(model, q_pin, frame):
    """y = [y_x, y_z, y_theta] in the task frame (pitch: angle of the pad's z axis in x-z)."""
    pm = model.pin_model
    d = pm.createData()
    pin.framesForwardKinematics(pm, d, q_pin)
    oMe = d.oMf[model.ee_frame_id]
    p = frame.R_WT.T @ (oMe.translation - frame.p_WT)
    R_TE = frame.R_WT.T @ oMe.rotation
    return np.array([p[0], p[2], np.arctan2(R_TE[0, 2], R_TE[2, 2])])


def J_y_of(model, q_pin, frame):
    pm = model.pin_model
    cols = []
    for i in range(pm.nv):
        e = np.zeros(pm.nv)
        e[i] = 1.0
        cols.append(_richardson(lambda t: y_of(model, pin.integrate(pm, q_pin, e * t), frame), 1e-4))
    return np.column_stack(cols)


def controller_literal(model, params, st: AmState, ref, F_e: np.ndarray):
    """tau of eqs. Com_controller, Rd, ori_controller, u3 with a steady F/T reading F_e."""
    pm = model.pin_model
    n = model.n
    m, g = model.mass_kg, model.gravity_mps2
    q_pin, V = st.pin_q(), st.pin_v()
    d, M, Jc, r_c = _kin(model, q_pin)
    C = pin.computeCoriolisMatrix(pm, pm.createData(), q_pin, V)
    R = st.R_WB
    w = st.w_B

    def along(t):
        return pin.integrate(pm, q_pin, V * t)

    T = T_of(model, q_pin)
    Tdot = _richardson(lambda t: T_of(model, along(t)))
    Tinv = np.linalg.inv(T)
    TinvT = Tinv.T
    Lxi = np.linalg.inv(T @ np.linalg.inv(M) @ T.T)
    Gxi = TinvT @ (C - M @ Tinv @ Tdot) @ Tinv
    xi = T @ V
    rdot_c, rho = xi[0:3], xi[6:]
    Lw = Lxi[3:6, 3:6]
    G_w, G_wr, G_r = Gxi[3:6, 3:6], Gxi[3:6, 6:], Gxi[6:, 6:]

    pin.computeJointJacobians(pm, d, q_pin)
    pin.updateFramePlacements(pm, d)
    J_e = pin.getFrameJacobian(pm, d, model.ee_frame_id, pin.LOCAL)
    R_e = d.oMf[model.ee_frame_id].rotation
    F_xi = TinvT @ J_e.T @ F_e
    s = 1.0 if params.force_compensation else 0.0
    F_rc = R_e @ F_e[0:3]

    # eq. Com_controller and its derivatives (constant F_rc: the filter is at steady state)
    Kt, Dt = params.gains_K_t, params.gains_D_t
    e, ed = r_c - ref.r_c, rdot_c - ref.r_c_d1
    f_d = m * ref.r_c_d2 + m * g * E3 - Kt @ e - Dt @ ed - s * F_rc
    b3 = R @ E3
    u1 = f_d @ b3
    b3d = R @ np.cross(w, E3)
    rddot_c = (u1 * b3 + s * F_rc) / m - g * E3
    if params.force_compensation:
        f_dd = m * ref.r_c_d3 - Kt @ ed - Dt @ (rddot_c - ref.r_c_d2)
        u1d = f_dd @ b3 + f_d @ b3d
        r3_c = (u1d * b3 + u1 * b3d) / m
        f_ddd = m * ref.r_c_d4 - Kt @ (rddot_c - ref.r_c_d2) - Dt @ (r3_c - ref.r_c_d3)
    else:  # no F/T sensor: terms needing the CoM acceleration are unknown (amcore.control)
        f_dd = m * ref.r_c_d3 - Kt @ ed
        f_ddd = m * ref.r_c_d4
    b1 = np.array([np.cos(ref.psi), np.sin(ref.psi), 0.0])
    b1d = ref.psi_d1 * np.array([-np.sin(ref.psi), np.cos(ref.psi), 0.0])
    b1dd = ref.psi_d2 * np.array([-np.sin(ref.psi), np.cos(ref.psi), 0.0]) - ref.psi_d1**2 * b1
    Rd, Om, Omd = desired_attitude(f_d, f_dd, f_ddd, b1, b1d, b1dd)

    # eq. ori_error, ori_vel_error, ori_controller
    e_R = 0.5 * vee(Rd.T @ R - R.T @ Rd)
    w_bd = R.T @ Rd @ Om
    e_w = w - w_bd
    wdot_bd = -np.cross(w, w_bd) + R.T @ Rd @ Omd
    u2 = Lw @ (wdot_bd - params.Lambda_wb_d_inv @ (params.k_R * e_R + params.k_w * e_w)) + G_w @ w + G_wr @ rho - s * F_xi[3:6]

    # eq. jacobian_xi .. u3
    J_y = J_y_of(model, q_pin, params.task_frame)
    J = J_y @ Tinv
    Jdot = _richardson(lambda t: J_y_of(model, along(t), params.task_frame) @ np.linalg.inv(T_of(model, along(t))), 1e-3)
    Ly = np.linalg.inv(J @ np.linalg.inv(Lxi) @ J.T)
    JLp = np.linalg.inv(Lxi) @ J.T @ Ly  # J^{Lambda+}
    Jbar = JLp.T
    J1, J2, J3 = Jbar[:, 0:3], Jbar[:, 3:6], Jbar[:, 6:]
    y = y_of(model, q_pin, params.task_frame)
    ydot = J @ xi
    u3 = -np.linalg.inv(J3) @ (
        J1 @ (u1 * R @ E3 - m * g * E3) + J2 @ (u2 - G_w @ w - G_wr @ rho)
        + Ly @ (Jdot @ xi - ref.y_d2) + params.D_y @ (ydot - ref.y_d1) + params.K_y @ (y - ref.y)
    ) + G_r @ rho - G_wr.T @ w
    u = np.concatenate([u1 * R @ E3, u2, u3])
    return T.T @ u


def literal_rotor_wrench(rotors, f) -> np.ndarray:
    """The base wrench (F_B [N], tau_B [N m], about the base origin) of rotor thrusts f, rotor by
    rotor: force f a at p, moment p x (f a), drag -KM f a (KM > 0 for a ccw rotor)."""
    F, tau = np.zeros(3), np.zeros(3)
    for r, fi in zip(rotors.rotor, f):
        a = np.array(r.axis) / np.linalg.norm(r.axis)
        km = r.moment_ratio_m if r.spin == "ccw" else -r.moment_ratio_m
        F += fi * a
        tau += np.cross(r.position_m, fi * a) - km * fi * a
    return np.concatenate([F, tau])
