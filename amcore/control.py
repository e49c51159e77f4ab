"""Decentralized passivity-based controller of one AM (paper Sec. III-B).

One call of `step` evaluates, at one measured state:
- the CoM law with force compensation (eq. Com_controller): f_d, u_1 = f_d . R_b e_3;
- the desired attitude (eq. Rd) with Omega_d and Omegadot_d from f_d's derivatives;
- the orientation law (eq. ori_controller) with e_R, e_w (eq. ori_error, ori_vel_error);
- the end-effector impedance law (eq. u3), which makes the task error obey
      Lambda_y y~dd + D_y y~d + K_y y~ = F_y          (eq. desired_task_behavior);
- tau = T^T u, whose first two entries vanish (thrust acts along body z only).

Details the paper leaves implicit, as implemented here:
- Gamma_xi uses pinocchio's skew-consistent C (see amcore.model).
- w_b,d = R_b^T R_d Omega_d, so d/dt w_b,d = -hat(w_b) w_b,d + R_b^T R_d Omegadot_d.
- f_d's derivatives use the model's CoM acceleration r_c_dd = (u_1 b_3 + F_rc)/m - g e_3
  and the measured wrench after a 2nd-order low-pass whose derivatives are exact.
- Without force compensation (options.force_compensation = false) the controller needs
  no F/T sensor: F_rc leaves f_d, F_wb leaves u_2, and the measured wrench does not
  influence the command at all. The CoM acceleration is then unknown under contact (the
  free-flight model's prediction is off by F_e/m; in PyBullet that made Omega_d spurious
  by D_t F_e / (m |f_d|) ~ 6 rad/s and the grasp fell), so f_d's derivatives keep only
  what is measured or known: f_d' = m r_d''' - K_t e', f_d'' = m r_d''''.
- Singularity guard (beyond the paper): the CoM error entering f_d's spring is saturated at
  safety.com_err_max_m, each task error at safety.y_err_max, and Jbar_3 is inverted by
  damped least squares once its smallest singular value drops below safety.sigma_damping.
  Away from those limits the law is exactly the paper's.
- Option compensate_Lambda_y_dot adds 1/2 dLambda_y/dt y~d to the damping, which the
  paper's storage argument (Theorem 2) drops; with it the storage balance is exact.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import linalg3
from . import vec3 as v3
from .attitude import desired_attitude_cols
from .config import VehicleParams
from .filters import FilterState, LowPass2, lowpass_accel, lowpass_update
from .model import AmModel, AmState, decoupled_terms
from .task import TaskFrame, task_terms

E3 = np.array([0.0, 0.0, 1.0])
_ZERO3 = np.zeros(3)


@dataclass(frozen=True)
class Reference:
    """Desired trajectories at one instant.

    r_c: CoM position in {w} [m] with derivatives up to snap (r_c_d4); the heading psi of
    b_1d = [cos psi, sin psi, 0] [rad] with two derivatives; y_d in the task frame with two.
    """

    r_c: np.ndarray
    r_c_d1: np.ndarray
    r_c_d2: np.ndarray
    r_c_d3: np.ndarray
    r_c_d4: np.ndarray
    psi: float
    psi_d1: float
    psi_d2: float
    y: np.ndarray
    y_d1: np.ndarray
    y_d2: np.ndarray


@dataclass(frozen=True)
class ControllerParams:
    """Everything constant about one AM's controller."""

    gains_K_t: np.ndarray
    gains_D_t: np.ndarray
    k_R: float
    k_w: float
    Lambda_wb_d_inv: np.ndarray
    K_y: np.ndarray
    D_y: np.ndarray
    com_err_max: float
    y_err_max: np.ndarray
    sigma_damping: float
    damping_max: float
    force_compensation: bool
    compensate_Lambda_y_dot: bool
    force_rate_feedforward: bool
    wrench_filter: LowPass2
    task_frame: TaskFrame
    components: tuple[str, ...]

    @staticmethod
    def from_vehicle(v: VehicleParams, task_frame: TaskFrame) -> "ControllerParams":
        g, s, o = v.gains, v.safety, v.options
        n = v.n_joints
        return ControllerParams(
            gains_K_t=np.diag(g.K_t), gains_D_t=np.diag(g.D_t), k_R=g.k_R, k_w=g.k_w,
            Lambda_wb_d_inv=np.diag(1.0 / np.array(g.Lambda_wb_d)),
            K_y=np.diag(g.K_y), D_y=np.diag(g.D_y),
            com_err_max=s.com_err_max_m,
            y_err_max=np.array(s.y_err_max) if s.y_err_max else np.full(n, np.inf),
            sigma_damping=s.sigma_damping, damping_max=s.damping_max,
            force_compensation=o.force_compensation, compensate_Lambda_y_dot=o.compensate_Lambda_y_dot,
            force_rate_feedforward=o.force_rate_feedforward,
            wrench_filter=LowPass2(o.force_filter_hz, o.force_filter_zeta),
            task_frame=task_frame, components=v.task.components,
        )


@dataclass(frozen=True)
class ControllerMemory:
    """What the controller carries from one step to the next (passed back in)."""

    t_s: float | None = None
    wrench: FilterState | None = None  # filtered [f; m] of F_e, world-aligned at {e} [N, N m]


@dataclass(frozen=True)
class Command:
    """Torque-level setpoint: thrust along body z [N], body torque [N m], joint torques [N m]."""

    thrust_n: float
    tau_B_nm: np.ndarray
    tau_q_nm: np.ndarray


@dataclass
class Diagnostics:
    r_c: np.ndarray
    r_c_d: np.ndarray
    r_c_err: np.ndarray  # r~_c = r_c - r_c,d [m]
    rdot_c: np.ndarray
    e_R: np.ndarray
    e_w: np.ndarray
    R_WB: np.ndarray
    R_d: np.ndarray
    w_bd: np.ndarray
    wdot_bd: np.ndarray
    Omega_d: np.ndarray
    f_d: np.ndarray
    y: np.ndarray
    y_d: np.ndarray
    y_err: np.ndarray
    ydot: np.ndarray
    F_y: np.ndarray
    F_rc: np.ndarray  # filtered end-effector force in {w} [N]
    wrench_E_filtered: np.ndarray
    sigma_min_J3: float
    damping: float
    com_err_saturated: bool
    y_err_saturated: bool
    u: np.ndarray
    tau: np.ndarray
    Lambda_y: np.ndarray
    Lambda_y_dot: np.ndarray | None = None
    wrench_W_filtered: np.ndarray | None = None  # filtered [f; m] of F_e in W axes, moment about {e} [N, N m]


@dataclass
class StepResult:
    command: Command
    diagnostics: Diagnostics
    memory: ControllerMemory


def _saturation(e: np.ndarray, limit: float) -> tuple[float, np.ndarray | None]:
    """Radial saturation sat(e) = e min(1, limit/|e|): returns (scale, P) with P = d sat / d e
    where saturated (None otherwise). Derivatives of sat(e) are taken as P e^(k): exact for the
    first, the saturation's curvature is dropped in higher ones (feed-forward only)."""
    n = math.sqrt(e.dot(e))
    if n <= limit:
        return 1.0, None
    return limit / n, (np.eye(3) - np.outer(e, e) / n**2) * (limit / n)


def _feedforward_pd(m: float, a, K, x, D, xd, f) -> v3.Vec:
    """m a - K x - D xd - f on 3-vectors (K, D nested lists): the pattern of eq. Com_controller
    and of its time derivatives."""
    Kx, Dxd = v3.mv(K, x), v3.mv(D, xd)
    return (m * a[0] - Kx[0] - Dxd[0] - f[0], m * a[1] - Kx[1] - Dxd[1] - f[1], m * a[2] - Kx[2] - Dxd[2] - f[2])


def step(model: AmModel, data: pin.Data, params: ControllerParams, state: AmState,
         ref: Reference, wrench_E: np.ndarray, memory: ControllerMemory, t_s: float) -> StepResult:
    """One evaluation of eqs. Com_controller, Rd, ori_controller and u3 at time t_s [s].

    wrench_E: the wrench [f_e; tau_e] the environment applies on the end-effector,
    expressed in {e} (an F/T sensor's reading) [N, N m].

    The 3-vector chains (CoM law, eq. Rd, orientation law) run on Python floats
    (amcore.vec3); the matrix work of eq. u3 on numpy.
    """
    p = params
    m, g = model.mass_kg, model.gravity_mps2
    need_full = p.compensate_Lambda_y_dot
    tm = decoupled_terms(model, data, state, full=need_full)
    tk = task_terms(model, data, tm, p.task_frame, p.components, full=need_full)
    R = state.R_WB
    xi = tm.xi

    # --- measured wrench: world-aligned at {e}, low-pass filtered (exact derivatives)
    R_WE = tk.R_WE.tolist()
    f_E = np.asarray(wrench_E, dtype=float).tolist()
    raw_W = np.array(v3.mv(R_WE, f_E[0:3]) + v3.mv(R_WE, f_E[3:6]))  # [R_e f_e; R_e tau_e]
    dt = 0.0 if memory.t_s is None else t_s - memory.t_s
    filt = lowpass_update(p.wrench_filter, memory.wrench, raw_W, dt)
    F_W = filt.x[0:3]
    x_W = filt.x.tolist()
    wrench_E_f = np.array(v3.mtv(R_WE, x_W[0:3]) + v3.mtv(R_WE, x_W[3:6]))  # [R_e^T f; R_e^T tau]
    F_xi = tm.T_inv.T.dot(tk.J_e.T.dot(wrench_E_f))
    s = 1.0 if p.force_compensation else 0.0
    sF_W = v3.scale(s, x_W[0:3])
    if p.force_rate_feedforward:
        sF_W_d = v3.scale(s, filt.xdot.tolist()[0:3])
        sF_W_dd = v3.scale(s, lowpass_accel(p.wrench_filter, filt, raw_W).tolist()[0:3])
    else:  # F_e treated as slowly varying in f_d's derivatives (see ControllerOptions)
        sF_W_d = sF_W_dd = (0.0, 0.0, 0.0)

    # --- CoM law, eq. Com_controller
    Rl = R.tolist()
    w = state.w_B.tolist()
    b1_B, b2_B, b3 = (Rl[0][0], Rl[1][0], Rl[2][0]), (Rl[0][1], Rl[1][1], Rl[2][1]), (Rl[0][2], Rl[1][2], Rl[2][2])
    b3_d = v3.mv(Rl, (w[1], -w[0], 0.0))  # R (w x e3)
    e = tm.r_c - ref.r_c
    ed = (xi[0:3] - ref.r_c_d1).tolist()
    scale, P = _saturation(e, p.com_err_max)
    Pl = None if P is None else P.tolist()
    sat = (lambda x: x) if P is None else (lambda x: v3.mv(Pl, x))
    K, D = p.gains_K_t.tolist(), p.gains_D_t.tolist()
    r_d2, r_d3, r_d4 = ref.r_c_d2.tolist(), ref.r_c_d3.tolist(), ref.r_c_d4.tolist()
    mg_e3 = (0.0, 0.0, m * g)
    f_d = _feedforward_pd(m, r_d2, K, v3.scale(scale, e.tolist()), D, ed, v3.sub(sF_W, mg_e3))
    u1 = v3.dot(f_d, b3)
    a_c = v3.sub(v3.div(v3.add(v3.scale(u1, b3), sF_W), m), (0.0, 0.0, g))  # model CoM acceleration
    # without an F/T sensor the CoM acceleration is unknown under contact (see module doc)
    edd = v3.sub(a_c, r_d2) if p.force_compensation else (0.0, 0.0, 0.0)
    f_d_d = _feedforward_pd(m, r_d3, K, sat(ed), D, edd, sF_W_d)
    u1_d = v3.dot(f_d_d, b3) + v3.dot(f_d, b3_d)
    a_c_d = v3.div(v3.add(v3.add(v3.scale(u1_d, b3), v3.scale(u1, b3_d)), sF_W_d), m)
    eddd = v3.sub(a_c_d, r_d3) if p.force_compensation else (0.0, 0.0, 0.0)
    f_d_dd = _feedforward_pd(m, r_d4, K, sat(edd), D, eddd, sF_W_dd)
    com_sat = P is not None

    # --- desired attitude, eq. Rd
    c, sn = math.cos(ref.psi), math.sin(ref.psi)
    pd1, pd2 = ref.psi_d1, ref.psi_d2
    b1 = (c, sn, 0.0)
    b1_d = (pd1 * -sn, pd1 * c, 0.0)
    b1_dd = (pd2 * -sn - pd1**2 * c, pd2 * c - pd1**2 * sn, 0.0)
    (d1, d2, d3), Om_d, Omd_d = desired_attitude_cols(f_d, f_d_d, f_d_dd, b1, b1_d, b1_dd)

    # --- orientation law, eq. ori_controller: e_R = vee(R_d^T R_b - R_b^T R_d) / 2
    e_R = v3.vee_RtX((d1, d2, d3), (b1_B, b2_B, b3))
    w_bd = v3.mtv(Rl, v3.cols_mv(d1, d2, d3, Om_d))  # R_b^T R_d Omega_d
    e_w = v3.sub(w, w_bd)
    wdot_bd = v3.sub(v3.mtv(Rl, v3.cols_mv(d1, d2, d3, Omd_d)), v3.cross(w, w_bd))
    Gxi = tm.Gamma_xi_xi
    G_w = Gxi.tolist()[3:6]
    k_e = v3.mv(p.Lambda_wb_d_inv.tolist(), v3.add(v3.scale(p.k_R, e_R), v3.scale(p.k_w, e_w)))
    u2 = v3.sub(v3.add(v3.mv(tm.Lambda_xi[3:6, 3:6].tolist(), v3.sub(wdot_bd, k_e)), G_w),
                v3.scale(s, F_xi.tolist()[3:6]))

    # --- end-effector impedance law, eq. u3
    J = tk.J
    LiJt = tm.Lambda_xi_inv.dot(J.T)
    Lambda_y = linalg3.inv(J.dot(LiJt))
    Jbar = Lambda_y.dot(LiJt.T)  # (J^{Lambda+})^T = Lambda_y J Lambda_xi^-1
    y_err = tk.y - ref.y
    y_err_l = y_err.tolist()
    y_err_s = [min(max(x, -lim), lim) for x, lim in zip(y_err_l, p.y_err_max.tolist())]  # np.clip
    ydot = J.dot(xi)
    yd_err = ydot - ref.y_d1
    rhs = -(Lambda_y.dot(tk.Jdot_xi - ref.y_d2) + p.D_y.dot(yd_err) + p.K_y.dot(y_err_s))
    Lambda_y_dot = None
    if p.compensate_Lambda_y_dot:
        Lxi_dot = tm.Gamma_xi + tm.Gamma_xi.T
        Jd = tk.Jdot
        inner = Jd @ LiJt + LiJt.T @ Jd.T - LiJt.T @ Lxi_dot @ LiJt
        Lambda_y_dot = -Lambda_y @ inner @ Lambda_y
        rhs = rhs - 0.5 * Lambda_y_dot @ yd_err
    u1_b3 = v3.scale(u1, b3)
    known = Jbar[:, 0:6].dot(v3.sub(u1_b3, mg_e3) + v3.sub(u2, G_w))
    J3 = Jbar[:, 6:]
    sigma_min, J3_inv_b = linalg3.sigma_min_and_solve(J3, rhs - known)
    damping = 0.0
    if sigma_min >= p.sigma_damping:
        if J3_inv_b is None:
            raise np.linalg.LinAlgError("eq. u3: Jbar_3 is singular")
        u3 = Gxi[6:] + J3_inv_b
    else:
        damping = p.damping_max**2 * (1.0 - (sigma_min / p.sigma_damping) ** 2)
        n = J3.shape[0]
        u3 = Gxi[6:] + J3.T @ np.linalg.solve(J3 @ J3.T + damping * np.eye(n), rhs - known)

    u = np.array(u1_b3 + u2 + tuple(u3.tolist()))
    tau = tm.T.T.dot(u)
    F_y = Jbar.dot(F_xi)
    cmd = Command(thrust_n=tau.item(2), tau_B_nm=tau[3:6].copy(), tau_q_nm=tau[6:].copy())
    # one array for the 3-vectors and R_d's rows (numpy's cost is per call, a flat list is cheapest)
    vecs = np.array(f_d + e_R + e_w + w_bd + wdot_bd + Om_d + (d1[0], d2[0], d3[0], d1[1], d2[1], d3[1],
                                                             d1[2], d2[2], d3[2])).reshape(9, 3)
    diag = Diagnostics(
        r_c=tm.r_c, r_c_d=ref.r_c, r_c_err=e, rdot_c=xi[0:3].copy(), e_R=vecs[1], e_w=vecs[2], R_WB=R,
        R_d=vecs[6:9], w_bd=vecs[3], wdot_bd=vecs[4], Omega_d=vecs[5], f_d=vecs[0], y=tk.y,
        y_d=ref.y, y_err=y_err, ydot=ydot, F_y=F_y, F_rc=F_W.copy(), wrench_E_filtered=wrench_E_f,
        wrench_W_filtered=filt.x.copy(),
        sigma_min_J3=sigma_min, damping=damping, com_err_saturated=com_sat,
        y_err_saturated=any(map(float.__ne__, y_err_s, y_err_l)),  # the clip changed something
        u=u, tau=tau, Lambda_y=Lambda_y,
        Lambda_y_dot=Lambda_y_dot,
    )
    return StepResult(cmd, diag, ControllerMemory(t_s=t_s, wrench=filt))
