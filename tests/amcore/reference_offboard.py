"""Attitude mode's estimate of the body torque and the arm's torques for it, in numpy: the
readable reference of amcore.law.attitude_mode_torques (amcore.offboard's module doc gives
the equations: row 2 of eq. new_dynamics for tau_b^, eq. u_bar solved for tau_q), and
`offboard_step` with it in place of the compiled call."""
from __future__ import annotations

import numpy as np

from amcore import linalg3
from amcore.control import ControllerParams, StepResult
from amcore.filters import FilterState, lowpass_update
from amcore.model import AmState
from amcore.offboard import (Applied, OffboardMemory, OffboardParams, OffboardResult, last_inputs, offboard_result,
                             predicted_step)


def body_torque_estimate(params: ControllerParams, res: StepResult, memory: OffboardMemory, state: AmState,
                         t_s: float, applied: Applied | None = None) -> np.ndarray | None:
    """tau_b^ [N m]: the body torque of the last control period, from row 2 of eq. new_dynamics
    with the measured angular acceleration (amcore.offboard's module doc). None if nothing was measured yet.
    `applied`: the reported thrust and joint torques (offboard_inputs = "reported")."""
    if memory.t_s is None or memory.w_B is None or memory.tau_q_nm is None or not t_s > memory.t_s:
        return None
    d = res.diagnostics
    tm = d.terms
    wdot = (state.w_B - np.asarray(memory.w_B)) / (t_s - memory.t_s)
    u2 = tm.Lambda_w.dot(wdot) + tm.Gamma_xi_xi[3:6]
    if params.force_compensation:  # F_wb from the filtered F/T reading (F_xi = (J_e T^-1)^T F_e)
        u2 = u2 - d.wrench_E_filtered.dot(tm.J_e_xi[:, 3:6])
    K = tm.T_inv[:, 3:6].T  # T^-T's middle block row: u_2 = K tau
    thrust, tau_q = last_inputs(memory, applied)
    return u2 - K[:, 2] * thrust - K[:, 6:].dot(tau_q)


def _rest(params: ControllerParams, res: StepResult, memory: OffboardMemory, applied: Applied | None) -> np.ndarray:
    """r = Gamma_wb w_b + Gamma_wb,rho rho - s F_wb^ - K_f f^- - K_q tau_q^- (amcore.offboard's module doc)."""
    d = res.diagnostics
    tm = d.terms
    r = tm.Gamma_xi_xi[3:6]
    if params.force_compensation:  # F_wb from the filtered F/T reading (F_xi = (J_e T^-1)^T F_e)
        r = r - d.wrench_E_filtered.dot(tm.J_e_xi[:, 3:6])
    K = tm.T_inv[:, 3:6].T  # T^-T's middle block row: u_2 = K tau
    thrust, tau_q = last_inputs(memory, applied)
    return r - K[:, 2] * thrust - K[:, 6:].dot(tau_q)


def filtered_body_torque_estimate(params: ControllerParams, oparams: OffboardParams, res: StepResult,
                                  memory: OffboardMemory, state: AmState, t_s: float,
                                  applied: Applied | None = None
                                  ) -> tuple[np.ndarray | None, FilterState, FilterState | None]:
    """tau_b^ = Lambda_wb (LP(w_b)_k - LP(w_b)_k-1) / dt + LP(r) [N m], LP the Butterworth of
    `oparams` (amcore.offboard's module doc),
    and the filters' new states. None (and the filters started) while nothing was measured."""
    f = oparams.torque_filter
    if memory.t_s is None or memory.w_filter is None or memory.tau_q_nm is None or not t_s > memory.t_s:
        return None, lowpass_update(f, None, state.w_B, 0.0), None
    dt = t_s - memory.t_s
    w_f = lowpass_update(f, memory.w_filter, state.w_B, dt)
    r_f = lowpass_update(f, memory.r_filter, _rest(params, res, memory, applied), dt)
    wdot = (w_f.x - memory.w_filter.x) / dt
    return res.diagnostics.terms.Lambda_w.dot(wdot) + r_f.x, w_f, r_f


def joint_torques_for_body_torque(res: StepResult, tau_b: np.ndarray) -> np.ndarray:
    """tau_q [N m] solving eq. u_bar with the body torque tau_b in place of torque mode's
    (amcore.offboard's module doc): tau_q^p - (J_y M^-1)_q^-1 (J_y M^-1)_w (tau_b - tau_b^p), damped like eq. u3
    where the controller damped it."""
    d, c = res.diagnostics, res.command
    JyMi = d.terms.J_y.dot(d.terms.M_inv)
    A, B = JyMi[:, 6:], JyMi[:, 3:6]
    rhs = B.dot(tau_b - c.tau_B_nm)
    if d.damping > 0.0:  # near the arm's singularity: the same damped least squares, in Lambda_y's metric
        A, rhs = d.Lambda_y.dot(A), d.Lambda_y.dot(rhs)
        return c.tau_q_nm - A.T.dot(np.linalg.solve(A.dot(A.T) + d.damping * np.eye(A.shape[0]), rhs))
    return c.tau_q_nm - linalg3.solve(A, rhs)


def offboard_step(model, data, params: ControllerParams, state: AmState, ref, wrench_E, memory: OffboardMemory,
                  t_s: float, task_frame=None, oparams: OffboardParams = OffboardParams(),
                  applied: Applied | None = None) -> OffboardResult:
    """amcore.offboard.offboard_step with the estimate and the joint torques of the functions above."""
    res, pending = predicted_step(model, data, params, state, ref, wrench_E, memory, t_s, task_frame, oparams)
    reported = applied if oparams.inputs == "reported" else None
    c, d = res.command, res.diagnostics
    w_f = r_f = None
    if oparams.torque_cutoff_hz > 0.0:
        tau_b, w_f, r_f = filtered_body_torque_estimate(params, oparams, res, memory, state, t_s, reported)
    else:
        tau_b = body_torque_estimate(params, res, memory, state, t_s, reported)
    estimated = tau_b is not None
    if tau_b is None:
        tau_b, tau_q = c.tau_B_nm, c.tau_q_nm
    else:
        tau_q = joint_torques_for_body_torque(res, tau_b)
    tau = np.concatenate(([0.0, 0.0, c.thrust_n], tau_b, tau_q))
    return offboard_result(res, state, t_s, tau, d.terms.T_inv.T.dot(tau), w_f, r_f, estimated, pending)
