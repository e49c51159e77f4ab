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
from functools import cached_property

import numpy as np
import pinocchio as pin

from . import linalg3
from . import vec3 as v3
from .attitude import desired_attitude_cols
from .config import VehicleParams
from .filters import FilterState, LowPass2, lowpass_update_floats
from .model import AmModel, AmState, DecoupledTerms, decoupled_terms
from .task import TaskFrame, TaskTerms, task_terms

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

    @cached_property
    def DK_y(self) -> np.ndarray:
        """[D_y, K_y] side by side (eq. u3 applies both in one product)."""
        return np.hstack((self.D_y, self.K_y))

    @cached_property
    def float_gains(self) -> "_FloatGains":
        """The constant 3x3 gains and the task error limits as Python floats (amcore.vec3),
        converted once per instance rather than every step."""
        return _FloatGains(self.gains_K_t.tolist(), self.gains_D_t.tolist(), self.Lambda_wb_d_inv.tolist(),
                           self.y_err_max.tolist())


@dataclass(frozen=True)
class _FloatGains:
    K_t: list  # nested lists (rows)
    D_t: list
    Lambda_wb_d_inv: list
    y_err_max: list


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
    # the model and task terms this step evaluated, for laws built on it (amcore.offboard)
    decoupled: DecoupledTerms | None = None
    task: TaskTerms | None = None


@dataclass
class StepResult:
    command: Command
    diagnostics: Diagnostics
    memory: ControllerMemory


def _saturation(e, limit: float) -> tuple[float, list | None]:
    """Radial saturation sat(e) = e min(1, limit/|e|) of a 3-vector (floats): returns (scale, P)
    with P = d sat / d e (nested lists) where saturated (None otherwise). Derivatives of sat(e)
    are taken as P e^(k): exact for the first, the saturation's curvature is dropped in higher
    ones (feed-forward only)."""
    e0, e1, e2 = e
    nn = e0 * e0 + e1 * e1 + e2 * e2
    n = math.sqrt(nn)
    if n <= limit:
        return 1.0, None
    s = limit / n
    return s, [[(1.0 - e0 * e0 / nn) * s, -e0 * e1 / nn * s, -e0 * e2 / nn * s],
               [-e1 * e0 / nn * s, (1.0 - e1 * e1 / nn) * s, -e1 * e2 / nn * s],
               [-e2 * e0 / nn * s, -e2 * e1 / nn * s, (1.0 - e2 * e2 / nn) * s]]


def _feedforward_pd(m: float, a, K, x, D, xd, f) -> v3.Vec:
    """m a - K x - D xd - f on 3-vectors (K, D nested lists): the pattern of eq. Com_controller
    and of its time derivatives."""
    (k00, k01, k02), (k10, k11, k12), (k20, k21, k22) = K
    (d00, d01, d02), (d10, d11, d12), (d20, d21, d22) = D
    x0, x1, x2 = x
    y0, y1, y2 = xd
    a0, a1, a2 = a
    f0, f1, f2 = f
    return (m * a0 - (k00 * x0 + k01 * x1 + k02 * x2) - (d00 * y0 + d01 * y1 + d02 * y2) - f0,
            m * a1 - (k10 * x0 + k11 * x1 + k12 * x2) - (d10 * y0 + d11 * y1 + d12 * y2) - f1,
            m * a2 - (k20 * x0 + k21 * x1 + k22 * x2) - (d20 * y0 + d21 * y1 + d22 * y2) - f2)


def step(model: AmModel, data: pin.Data, params: ControllerParams, state: AmState,
         ref: Reference, wrench_E: np.ndarray, memory: ControllerMemory, t_s: float,
         task_frame: TaskFrame | None = None) -> StepResult:
    """One evaluation of eqs. Com_controller, Rd, ori_controller and u3 at time t_s [s].

    wrench_E: the wrench [f_e; tau_e] the environment applies on the end-effector,
    expressed in {e} (an F/T sensor's reading) [N, N m]. task_frame: this step's task frame
    if it moves (amcore.adapt turns it with the heading), else params.task_frame.

    The 3-vector chains (wrench filter, CoM law, eq. Rd, orientation law) run on Python
    floats (amcore.vec3); the matrix work of eq. u3 on numpy.
    """
    p = params
    fg = p.float_gains
    m, g, n = model.mass_kg, model.gravity_mps2, model.n
    need_full = p.compensate_Lambda_y_dot
    tm = decoupled_terms(model, data, state, full=need_full)
    tk = task_terms(model, data, tm, p.task_frame if task_frame is None else task_frame, p.components,
                    full=need_full)
    R = state.R_WB
    comp = p.force_compensation
    s = 1.0 if comp else 0.0

    # --- measured wrench: world-aligned at {e}, low-pass filtered (exact derivatives)
    (e00, e01, e02, _), (e10, e11, e12, _), (e20, e21, e22, _), _ = tk.H_WE.tolist()  # R_WE's rows
    f0, f1, f2, t0, t1, t2 = np.asarray(wrench_E, dtype=float).tolist()
    raw_W = [e00 * f0 + e01 * f1 + e02 * f2, e10 * f0 + e11 * f1 + e12 * f2, e20 * f0 + e21 * f1 + e22 * f2,
             e00 * t0 + e01 * t1 + e02 * t2, e10 * t0 + e11 * t1 + e12 * t2, e20 * t0 + e21 * t1 + e22 * t2]  # [R_e f_e; R_e tau_e]
    dt = 0.0 if memory.t_s is None else t_s - memory.t_s
    x_W, xd_W = lowpass_update_floats(p.wrench_filter, memory.wrench, raw_W, dt)
    f0, f1, f2, t0, t1, t2 = x_W
    wrench_E_f = [e00 * f0 + e10 * f1 + e20 * f2, e01 * f0 + e11 * f1 + e21 * f2, e02 * f0 + e12 * f1 + e22 * f2,
                  e00 * t0 + e10 * t1 + e20 * t2, e01 * t0 + e11 * t1 + e21 * t2, e02 * t0 + e12 * t1 + e22 * t2]  # [R_e^T f; R_e^T tau]
    F_xi = np.array(wrench_E_f).dot(tk.J_e_xi)  # (J_e T^-1)^T F = T^-T J_e^T F
    sF_W = (s * f0, s * f1, s * f2)  # the filtered force, if compensated
    if p.force_rate_feedforward:
        sF_W_d = v3.scale(s, xd_W[0:3])
        wf, zeta = p.wrench_filter.omega, p.wrench_filter.zeta
        sF_W_dd = tuple(s * (wf * wf * (raw_W[i] - x_W[i]) - 2.0 * zeta * wf * xd_W[i]) for i in range(3))  # lowpass_accel
    else:  # F_e treated as slowly varying in f_d's derivatives (see ControllerOptions)
        sF_W_d = sF_W_dd = (0.0, 0.0, 0.0)

    # --- CoM law, eq. Com_controller, and its first two time derivatives
    Rl = R.tolist()
    (R00, R01, R02), (R10, R11, R12), (R20, R21, R22) = Rl
    w0, w1, w2 = state.w_B.tolist()
    b3 = (R02, R12, R22)
    b3_d = (R00 * w1 - R01 * w0, R10 * w1 - R11 * w0, R20 * w1 - R21 * w0)  # R (w x e3)
    rdot_c = tm.rdot_c.tolist()
    e = v3.sub(tm.r_c.tolist(), ref.r_c.tolist())
    ed = v3.sub(rdot_c, ref.r_c_d1.tolist())
    scale, P = _saturation(e, p.com_err_max)
    K, D = fg.K_t, fg.D_t
    r_d2, r_d3, r_d4 = ref.r_c_d2.tolist(), ref.r_c_d3.tolist(), ref.r_c_d4.tolist()
    mg = m * g
    f_d = _feedforward_pd(m, r_d2, K, v3.scale(scale, e), D, ed, (sF_W[0], sF_W[1], sF_W[2] - mg))
    u1 = v3.dot(f_d, b3)
    if comp:  # the model's CoM acceleration (u_1 b_3 + F_rc)/m - g e_3, less r_c,d''
        edd = ((u1 * R02 + sF_W[0]) / m - r_d2[0], (u1 * R12 + sF_W[1]) / m - r_d2[1],
               ((u1 * R22 + sF_W[2]) / m - g) - r_d2[2])
    else:  # without an F/T sensor the CoM acceleration is unknown under contact (see module doc)
        edd = (0.0, 0.0, 0.0)
    f_d_d = _feedforward_pd(m, r_d3, K, ed if P is None else v3.mv(P, ed), D, edd, sF_W_d)
    u1_d = v3.dot(f_d_d, b3) + v3.dot(f_d, b3_d)
    if comp:
        eddd = ((u1_d * R02 + u1 * b3_d[0] + sF_W_d[0]) / m - r_d3[0],
                (u1_d * R12 + u1 * b3_d[1] + sF_W_d[1]) / m - r_d3[1],
                (u1_d * R22 + u1 * b3_d[2] + sF_W_d[2]) / m - r_d3[2])
    else:
        eddd = (0.0, 0.0, 0.0)
    f_d_dd = _feedforward_pd(m, r_d4, K, edd if P is None else v3.mv(P, edd), D, eddd, sF_W_dd)

    # --- desired attitude, eq. Rd
    c, sn = math.cos(ref.psi), math.sin(ref.psi)
    pd1, pd2 = ref.psi_d1, ref.psi_d2
    b1 = (c, sn, 0.0)
    b1_d = (pd1 * -sn, pd1 * c, 0.0)
    b1_dd = (pd2 * -sn - pd1**2 * c, pd2 * c - pd1**2 * sn, 0.0)
    (d1, d2, d3), Om_d, Omd_d = desired_attitude_cols(f_d, f_d_d, f_d_dd, b1, b1_d, b1_dd)

    # --- orientation law, eq. ori_controller, through Q = R_b^T R_d (Q_ij = b_i . d_j):
    # e_R = vee(R_d^T R_b - R_b^T R_d) / 2 = vee(Q^T - Q) / 2, w_bd = Q Omega_d and
    # d/dt w_bd = Q Omegadot_d - w x w_bd
    (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = d1, d2, d3
    Q00, Q01, Q02 = R00 * x0 + R10 * x1 + R20 * x2, R00 * y0 + R10 * y1 + R20 * y2, R00 * z0 + R10 * z1 + R20 * z2
    Q10, Q11, Q12 = R01 * x0 + R11 * x1 + R21 * x2, R01 * y0 + R11 * y1 + R21 * y2, R01 * z0 + R11 * z1 + R21 * z2
    Q20, Q21, Q22 = R02 * x0 + R12 * x1 + R22 * x2, R02 * y0 + R12 * y1 + R22 * y2, R02 * z0 + R12 * z1 + R22 * z2
    e_R = (0.5 * (Q12 - Q21), 0.5 * (Q20 - Q02), 0.5 * (Q01 - Q10))
    o0, o1, o2 = Om_d
    w_bd = wb0, wb1, wb2 = (Q00 * o0 + Q01 * o1 + Q02 * o2, Q10 * o0 + Q11 * o1 + Q12 * o2,
                            Q20 * o0 + Q21 * o1 + Q22 * o2)
    e_w = (w0 - wb0, w1 - wb1, w2 - wb2)
    o0, o1, o2 = Omd_d
    wdot_bd = (Q00 * o0 + Q01 * o1 + Q02 * o2 - (w1 * wb2 - w2 * wb1),
               Q10 * o0 + Q11 * o1 + Q12 * o2 - (w2 * wb0 - w0 * wb2),
               Q20 * o0 + Q21 * o1 + Q22 * o2 - (w0 * wb1 - w1 * wb0))
    Gxi = tm.Gamma_xi_xi.tolist()
    G_w = Gxi[3:6]
    k_R, k_w = p.k_R, p.k_w
    k_e = v3.mv(fg.Lambda_wb_d_inv, (k_R * e_R[0] + k_w * e_w[0], k_R * e_R[1] + k_w * e_w[1],
                                     k_R * e_R[2] + k_w * e_w[2]))
    L_w = v3.mv(tm.Lambda_w.tolist(), v3.sub(wdot_bd, k_e))
    F_w = F_xi.tolist()[3:6]
    u2 = (L_w[0] + G_w[0] - s * F_w[0], L_w[1] + G_w[1] - s * F_w[1], L_w[2] + G_w[2] - s * F_w[2])

    # --- end-effector impedance law, eq. u3
    # With J = J_y T^-1 and Lambda_xi^-1 = T M^-1 T^T: J Lambda_xi^-1 = J_y M^-1 T^T and
    # Lambda_y^-1 = J Lambda_xi^-1 J^T = J_y M^-1 J_y^T (T cancels)
    J_y = tk.J_y
    JyMi = J_y.dot(tm.M_inv)
    Lambda_y = linalg3.inv_sym(JyMi.dot(J_y.T))
    Jbar = Lambda_y.dot(JyMi.dot(tm.T.T))  # (J^{Lambda+})^T = Lambda_y J Lambda_xi^-1
    y_err_l = list(map(float.__sub__, tk.y.tolist(), ref.y.tolist()))
    y_err_s = [lim if x > lim else (-lim if x < -lim else x) for x, lim in zip(y_err_l, fg.y_err_max)]  # np.clip
    ydot = tk.ydot  # J_y V = J xi
    yd_err = list(map(float.__sub__, ydot.tolist(), ref.y_d1.tolist()))
    # Jbar (u - Gamma_xi xi - zeta) = rhs, rhs = -(Lambda_y (Jdot xi - y_d'') + D_y y~d + K_y sat(y~)),
    # where the known part of u - Gamma_xi xi - zeta is z = [u_1 b_3 - m g e_3; u_2 - G_w; 0]:
    # Jbar_3 (u_3 - G_3) = -r, r = [Lambda_y, Jbar, D_y, K_y] [Jdot xi - y_d''; z; y~d; sat(y~)]
    # (one product: numpy's cost is per call).
    u1_b3 = (u1 * R02, u1 * R12, u1 * R22)
    z = [u1_b3[0], u1_b3[1], u1_b3[2] - mg, u2[0] - G_w[0], u2[1] - G_w[1], u2[2] - G_w[2], *(0.0,) * n]
    a = list(map(float.__sub__, tk.Jdot_xi.tolist(), ref.y_d2.tolist()))
    r = np.concatenate((Lambda_y, Jbar, p.DK_y), axis=1).dot(np.fromiter(a + z + yd_err + y_err_s, float, 6 + 4 * n))
    Lambda_y_dot = None
    if p.compensate_Lambda_y_dot:
        Lxi_dot = tm.Gamma_xi + tm.Gamma_xi.T
        Jd = tk.Jdot
        LiJt = tm.Lambda_xi_inv @ tk.J.T
        inner = Jd @ LiJt + LiJt.T @ Jd.T - LiJt.T @ Lxi_dot @ LiJt
        Lambda_y_dot = -Lambda_y @ inner @ Lambda_y
        r = r + 0.5 * Lambda_y_dot @ np.array(yd_err)
    J3 = Jbar[:, 6:]
    sigma_min, J3_inv_r = linalg3.sigma_min_and_solve(J3, r, as_list=True)
    damping = 0.0
    if sigma_min >= p.sigma_damping:
        if J3_inv_r is None:
            raise np.linalg.LinAlgError("eq. u3: Jbar_3 is singular")
        u3_G3 = J3_inv_r  # -(u_3 - G_3)
    else:
        damping = p.damping_max**2 * (1.0 - (sigma_min / p.sigma_damping) ** 2)
        u3_G3 = (J3.T @ np.linalg.solve(J3 @ J3.T + damping * np.eye(n), r)).tolist()

    u3 = list(map(float.__sub__, Gxi[6:], u3_G3))
    # u and the diagnostics' vectors (and R_d's rows) as views of one array: numpy's cost is per
    # call (the memory's filter state too: its own, non-overlapping slices)
    v = np.fromiter([*f_d, *e_R, *e_w, *w_bd, *wdot_bd, *Om_d, d1[0], d2[0], d3[0], d1[1], d2[1], d3[1],
                     d1[2], d2[2], d3[2], *e, *x_W, *wrench_E_f, *x_W, *xd_W, *y_err_l,
                     *u1_b3, *u2, *u3], float, 60 + 2 * n)
    u = v[54 + n:]
    tau = u.dot(tm.T)  # T^T u
    F_y = Jbar.dot(F_xi)
    tau_cmd = tau.copy()  # the command does not share memory with the diagnostics
    cmd = Command(tau.item(2), tau_cmd[3:6], tau_cmd[6:])  # (thrust_n, tau_B_nm, tau_q_nm); positional: half the cost
    diag = Diagnostics(  # positional, in field order: matching 28 keywords would cost ~1.4 us more
        tm.r_c, ref.r_c, v[27:30], tm.rdot_c,  # r_c, r_c_d, r_c_err, rdot_c
        v[3:6], v[6:9], R, v[18:27].reshape(3, 3),  # e_R, e_w, R_WB, R_d
        v[9:12], v[12:15], v[15:18], v[0:3],  # w_bd, wdot_bd, Omega_d, f_d
        tk.y, ref.y, v[54:54 + n], ydot, F_y,  # y, y_d, y_err, ydot, F_y
        v[30:33], v[36:42],  # F_rc, wrench_E_filtered
        sigma_min, damping, P is not None,  # sigma_min_J3, damping, com_err_saturated
        any(map(float.__ne__, y_err_s, y_err_l)),  # y_err_saturated: the clip changed something
        u, tau, Lambda_y, Lambda_y_dot, v[30:36],  # u, tau, Lambda_y, Lambda_y_dot, wrench_W_filtered
        tm, tk,  # decoupled, task
    )
    return StepResult(cmd, diag, ControllerMemory(t_s, FilterState(v[42:48], v[48:54])))
