"""The companion's law when a stock autopilot flies the base (attitude mode).

The companion computes what it does in torque mode (`amcore.control.step`: eq.
Com_controller, eq. Rd, eq. u3) and sends the autopilot R_b,d, w_b,d and the thrust u_1;
eq. ori_controller's torque is the autopilot's business now, and the body torque tau_b the
vehicle actually receives is unknown to the companion. Two things change.

1. The arm law. Eq. u_bar needs the base's rotational input, its J̄_2 block
   u_2 - Gamma_wb w_b - Gamma_wb,rho rho. In torque mode the companion knows it (eq.
   ori_controller); whoever applies the torque, row 2 of eq. new_dynamics says what it is:

       u_2 - Gamma_wb w_b - Gamma_wb,rho rho = Lambda_wb wdot_b - F_wb,

   and u = T^-T tau gives u_2 = K tau with K = Lambda_wb (M^-1)_(w,:) (T^-T's middle block
   row; K's body-torque block is I). So the body torque of the last control period follows
   from the measured angular acceleration (the gyro's backward difference) and the
   companion's own last thrust f^- and joint torques tau_q^-:

       tau_b^ = Lambda_wb wdot_b^ + Gamma_wb w_b + Gamma_wb,rho rho - s F_wb^ - K_f f^- - K_q tau_q^-,

   F_wb^ the filtered wrench's part with force compensation (s = 1); without an F/T sensor
   (s = 0) the wrench is unknown and its moment stays in tau_b^. The companion holds tau_b^
   over the next period (the rotors' lag makes the autopilot's torque smooth) and solves eq.
   u_bar for the joint torques with tau_b = tau_b^. Since J̄ T^-T = Lambda_y J_y M^-1, its
   solution differs from torque mode's, tau^p = [0, 0, f, tau_b^p, tau_q^p] (same thrust), by

       (J_y M^-1)_q (tau_q - tau_q^p) = -(J_y M^-1)_w (tau_b^ - tau_b^p):

   the arm takes up whatever the base does differently from eq. ori_controller, and the
   task error still obeys eq. desired_task_behavior up to the estimate's error. Why not
   keep torque mode's u_2: it assumes the body torque compensates the arm's reaction
   (tau_b^p contains N_1^T u_3); no autopilot does, so the arm would push the base and
   ignore that it did. Why not feed wdot_b^ straight into the J̄_2 block: u_2 contains the
   arm's own reaction -K_q tau_q, so that would close a one-period loop through the arm's
   torque; with tau_b^ held, the reaction of this period's torque is in the equation.
   First step (nothing measured yet): tau_b^ = tau_b^p, the torque-mode answer.

2. The wrench bookkeeping. Eq. ori_controller's -F_wb is applied by no one now (the
   autopilot's integrator takes up a steady external moment); the measured wrench enters
   the base's rotation only through tau_b^ above, and F_y, F_rc as before. The step's
   `command.tau_B_nm` and the diagnostics' `tau` and `u = T^-T tau` hold tau_b^ and the
   joint torques sent: what the companion believes the vehicle received, never a setpoint.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import linalg3
from .control import Command, ControllerMemory, ControllerParams, Reference, StepResult, step
from .model import AmModel, AmState
from .task import TaskFrame


@dataclass(frozen=True)
class OffboardMemory:
    """What the attitude-mode law carries from one control step to the next."""

    controller: ControllerMemory = ControllerMemory()
    t_s: float | None = None
    w_B: tuple[float, float, float] | None = None  # measured body rate [rad/s]
    thrust_n: float = 0.0  # the thrust sent [N]
    tau_q_nm: np.ndarray | None = None  # the joint torques sent [N m]


@dataclass
class OffboardResult:
    """`StepResult` of attitude mode, and the body torque estimate (None on the first step)."""

    result: StepResult
    memory: OffboardMemory
    tau_b_hat: np.ndarray | None


def body_torque_estimate(params: ControllerParams, res: StepResult, memory: OffboardMemory, state: AmState,
                         t_s: float) -> np.ndarray | None:
    """tau_b^ [N m]: the body torque of the last control period, from row 2 of eq. new_dynamics
    with the measured angular acceleration (module doc). None if nothing was measured yet."""
    if memory.t_s is None or memory.w_B is None or memory.tau_q_nm is None or not t_s > memory.t_s:
        return None
    d = res.diagnostics
    tm = d.terms
    wdot = (state.w_B - np.asarray(memory.w_B)) / (t_s - memory.t_s)
    u2 = tm.Lambda_w.dot(wdot) + tm.Gamma_xi_xi[3:6]
    if params.force_compensation:  # F_wb from the filtered F/T reading (F_xi = (J_e T^-1)^T F_e)
        u2 = u2 - d.wrench_E_filtered.dot(tm.J_e_xi[:, 3:6])
    K = tm.T_inv[:, 3:6].T  # T^-T's middle block row: u_2 = K tau
    return u2 - K[:, 2] * memory.thrust_n - K[:, 6:].dot(memory.tau_q_nm)


def joint_torques_for_body_torque(res: StepResult, tau_b: np.ndarray) -> np.ndarray:
    """tau_q [N m] solving eq. u_bar with the body torque tau_b in place of torque mode's
    (module doc): tau_q^p - (J_y M^-1)_q^-1 (J_y M^-1)_w (tau_b - tau_b^p), damped like eq. u3
    where the controller damped it."""
    d, c = res.diagnostics, res.command
    JyMi = d.terms.J_y.dot(d.terms.M_inv)
    A, B = JyMi[:, 6:], JyMi[:, 3:6]
    rhs = B.dot(tau_b - c.tau_B_nm)
    if d.damping > 0.0:  # near the arm's singularity: the same damped least squares, in Lambda_y's metric
        A, rhs = d.Lambda_y.dot(A), d.Lambda_y.dot(rhs)
        return c.tau_q_nm - A.T.dot(np.linalg.solve(A.dot(A.T) + d.damping * np.eye(A.shape[0]), rhs))
    return c.tau_q_nm - linalg3.solve(A, rhs)


def offboard_step(model: AmModel, data: pin.Data, params: ControllerParams, state: AmState, ref: Reference,
                  wrench_E: np.ndarray, memory: OffboardMemory, t_s: float,
                  task_frame: TaskFrame | None = None) -> OffboardResult:
    """One attitude-mode control step: torque mode's step (with `task_frame` as there), then
    the joint torques for the estimated body torque (module doc). The command's thrust, R_d and w_b,d (diagnostics)
    go to the autopilot, its joint torques to the arm."""
    res = step(model, data, params, state, ref, wrench_E, memory.controller, t_s, task_frame)
    c, d = res.command, res.diagnostics
    tau_b = body_torque_estimate(params, res, memory, state, t_s)
    if tau_b is None:
        tau_b, tau_q = c.tau_B_nm, c.tau_q_nm
    else:
        tau_q = joint_torques_for_body_torque(res, tau_b)
    tau = np.concatenate(([0.0, 0.0, c.thrust_n], tau_b, tau_q))
    d.tau, d.u = tau, d.terms.T_inv.T.dot(tau)  # the bookkeeping: what the vehicle received
    cmd = Command(c.thrust_n, tau[3:6], tau[6:])
    mem = OffboardMemory(res.memory, t_s, tuple(state.w_B.tolist()), c.thrust_n, cmd.tau_q_nm)
    return OffboardResult(StepResult(cmd, d, res.memory), mem, None if tau_b is c.tau_B_nm else tau_b)
