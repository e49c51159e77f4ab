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

   Two options ([options], `OffboardParams`) go beyond the law as first written:

   - offboard_inputs = "reported": f^- and tau_q^- are what the vehicle applied over the
     last period, not what the companion sent: the thrust of the attitude target the
     autopilot reports flying (ATTITUDE_TARGET, thrust x thrust_max_n) and the joint torques
     the servos measured (AM_JOINT_STATE.effort_nm). A setpoint lost on the link leaves the
     vehicle flying the previous one; with "sent" the equation then subtracts a thrust and
     joint torques nobody applied, and the error feeds back through tau_q (the arm's
     reaction is in K_q tau_q^-). Where a report is missing, the sent value stands in.
   - offboard_torque_cutoff_hz = f_c > 0: tau_b^ through a 2nd-order Butterworth low-pass
     at f_c (`amcore.filters`, zeta = 1/sqrt(2)). The filter runs on w_b, and the backward
     difference of the filtered rate is the angular acceleration; the same filter runs on the
     rest of the equation, r = Gamma_wb w_b + Gamma_wb,rho rho - s F_wb^ - K_f f^- - K_q tau_q^-,
     so that tau_b^ = Lambda_wb (LP(w_b)_k - LP(w_b)_k-1) / dt + LP(r) is the backward
     difference's estimate through LP (the filter is linear; Lambda_wb changes slowly): an
     estimate of the body torque with a stated bandwidth, its noise and its lag the filter's.
     (The filter's own derivative, sampled at the control steps, would read a ramp ~8 % low
     at 40 Hz and 250 Hz: its input is held over each period.)
   - offboard_latency_s = L > 0 (off by default): the link's one-way latency, from a
     setpoint leaving the companion to the vehicle acting on it, as measured on the vehicle's
     link. The command computed at t_k acts from t_k + L, so eq. u3 is evaluated at the task
     error predicted for then (a Smith predictor in task space): from the measured y~, y~' at
     t_k, with y~'' piecewise constant, each command j sent at t_j making
         a_j = Lambda_y^-1 (F_y - D_y y~'_j - K_y sat(y~_j))        (eq. desired_task_behavior)
     from t_j + L until the next one acts (`predicted_task_error`). The prediction enters as a
     shift of the task reference, y_d - (y^~ - y~) and y_d' - (y^~' - y~'), so the law itself
     is unchanged; it costs a second evaluation of `step` (the first gives y~' at t_k). The
     base's loops are not predicted (their bandwidth is some ten times lower). A lost setpoint
     leaves its predecessor acting where the prediction assumed it arrived.

2. The wrench bookkeeping. Eq. ori_controller's -F_wb is applied by no one now (the
   autopilot's integrator takes up a steady external moment); the measured wrench enters
   the base's rotation only through tau_b^ above, and F_y, F_rc as before. The step's
   `command.tau_B_nm` and the diagnostics' `tau` and `u = T^-T tau` hold tau_b^ and the
   joint torques sent: what the companion believes the vehicle received, never a setpoint.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from . import law
from .config import VehicleParams
from .control import Command, ControllerMemory, ControllerParams, Reference, StepResult, packed_offsets, step
from .filters import FilterState, LowPass2, lowpass_update
from .model import AmModel, AmState
from .task import TaskFrame

BUTTERWORTH_ZETA = 1.0 / math.sqrt(2.0)


@dataclass(frozen=True)
class OffboardParams:
    """The attitude-mode options (module doc): inputs "sent" or "reported"; torque_cutoff_hz
    0 (backward difference) or the estimate's bandwidth [Hz]; latency_s 0 (no prediction) or
    the link's one-way latency [s]."""

    inputs: str = "sent"
    torque_cutoff_hz: float = 0.0
    latency_s: float = 0.0  # > 0: eq. u3 at the task error predicted this far ahead [s] (module doc)

    @staticmethod
    def from_vehicle(v: VehicleParams) -> "OffboardParams":
        o = v.options
        return OffboardParams(o.offboard_inputs, o.offboard_torque_cutoff_hz, o.offboard_latency_s)

    @cached_property
    def torque_filter(self) -> LowPass2 | None:
        return LowPass2(self.torque_cutoff_hz, BUTTERWORTH_ZETA) if self.torque_cutoff_hz > 0.0 else None


class Applied(NamedTuple):
    """What the vehicle reports it applied over the last control period: the thrust of the
    target the autopilot flies [N] (None: not reported) and the measured joint torques [N m]
    (None: not reported)."""

    thrust_n: float | None = None
    tau_q_nm: np.ndarray | None = None


@dataclass(frozen=True)
class OffboardMemory:
    """What the attitude-mode law carries from one control step to the next."""

    controller: ControllerMemory = ControllerMemory()
    t_s: float | None = None
    w_B: tuple[float, float, float] | None = None  # measured body rate [rad/s]
    thrust_n: float = 0.0  # the thrust sent [N]
    tau_q_nm: np.ndarray | None = None  # the joint torques sent [N m]
    w_filter: FilterState | None = None  # offboard_torque_cutoff_hz > 0: LP(w_b)
    r_filter: FilterState | None = None  # ... and LP(r) (module doc)
    # offboard_latency_s > 0: (t_j [s], a_j) of the commands that may still act in the window
    # [t, t + L], oldest first, a_j the task-error acceleration each commanded (module doc)
    pending: tuple[tuple[float, np.ndarray], ...] = ()


@dataclass
class OffboardResult:
    """`StepResult` of attitude mode, and the body torque estimate (None on the first step)."""

    result: StepResult
    memory: OffboardMemory
    tau_b_hat: np.ndarray | None


def last_inputs(memory: OffboardMemory, applied: Applied | None) -> tuple[float, np.ndarray]:
    """(f^-, tau_q^-): the reported ones where given, else what the companion sent."""
    thrust, tau_q = memory.thrust_n, memory.tau_q_nm
    if applied is not None:
        if applied.thrust_n is not None:
            thrust = applied.thrust_n
        if applied.tau_q_nm is not None:
            tau_q = np.asarray(applied.tau_q_nm)
    return thrust, tau_q


def predicted_task_error(y_err: np.ndarray, ydot_err: np.ndarray, pending, t_s: float, latency_s: float
                         ) -> tuple[np.ndarray, np.ndarray]:
    """(y~, y~') at t_s + latency_s [task units, per s], from the measured ones at t_s and the
    commands `pending`, (t_j, a_j) oldest first: a_j [per s^2] acts from t_j + latency_s until the
    next command acts (zero before the first). Exact for that piecewise-constant y~''."""
    y, v = np.array(y_err, dtype=float), np.array(ydot_err, dtype=float)
    end = t_s + latency_s
    starts = [t_j + latency_s for t_j, _ in pending]
    cuts = sorted({t_s, end, *(t for t in starts if t_s < t < end)})
    for t0, t1 in zip(cuts, cuts[1:]):
        acting = [a_j for (_, a_j), start in zip(pending, starts) if start <= t0]
        h = t1 - t0
        if acting:
            a = np.asarray(acting[-1])
            y += v * h + 0.5 * a * (h * h)
            v += a * h
        else:
            y += v * h
    return y, v


def commanded_task_acceleration(params: ControllerParams, res: StepResult, ydot_err: np.ndarray) -> np.ndarray:
    """a = Lambda_y^-1 (F_y - D y~' - K_y sat(y~)) [per s^2]: the task-error acceleration the
    step's command makes (eq. desired_task_behavior), D the damping eq. u3 used (D_y, or its
    discretized form with [options].discrete_damping)."""
    d = res.diagnostics
    L = d.Lambda_y
    D = law.discrete_damping(L, params.D_y, params.damping_dt) if params.damping_dt > 0.0 else params.D_y
    spring = params.K_y.dot(np.clip(d.y_err, -params.y_err_max, params.y_err_max))
    return np.linalg.solve(L, d.F_y - D.dot(ydot_err) - spring)


def offboard_step(model: AmModel, data: pin.Data, params: ControllerParams, state: AmState, ref: Reference,
                  wrench_E: np.ndarray, memory: OffboardMemory, t_s: float,
                  task_frame: TaskFrame | None = None, oparams: OffboardParams = OffboardParams(),
                  applied: Applied | None = None) -> OffboardResult:
    """One attitude-mode control step: torque mode's step (with `task_frame` as there), then
    the joint torques for the estimated body torque (module doc), both in one compiled call
    (`amcore.law.attitude_mode_torques`). The command's thrust, R_d and w_b,d (diagnostics)
    go to the autopilot, its joint torques to the arm. `oparams` and `applied`: the options
    and, with offboard_inputs = "reported", what the vehicle reports it applied. The readable
    reference of the estimate, in numpy, is tests/amcore/reference_offboard.py."""
    res, pending = predicted_step(model, data, params, state, ref, wrench_E, memory, t_s, task_frame, oparams)
    reported = applied if oparams.inputs == "reported" else None
    tau, u, w_f, r_f, estimated = _estimate(params, oparams, res, memory, state, t_s, reported)
    return offboard_result(res, state, t_s, tau, u, w_f, r_f, estimated, pending)


def predicted_step(model: AmModel, data: pin.Data, params: ControllerParams, state: AmState, ref: Reference,
                   wrench_E: np.ndarray, memory: OffboardMemory, t_s: float, task_frame: TaskFrame | None,
                   oparams: OffboardParams) -> tuple[StepResult, tuple]:
    """Torque mode's step, at the task error predicted for when the command acts where
    offboard_latency_s > 0 (module doc), and the commands still pending then."""
    res = step(model, data, params, state, ref, wrench_E, memory.controller, t_s, task_frame)
    if not oparams.latency_s > 0.0:
        return res, ()
    d0 = res.diagnostics  # eq. u3 at the error predicted for when this command acts
    y_d, y_err, ydot_err = ref.y, d0.y_err.copy(), d0.ydot - ref.y_d1
    y_p, v_p = predicted_task_error(y_err, ydot_err, memory.pending, t_s, oparams.latency_s)
    res = step(model, data, params, state, ref._replace(y=y_d - (y_p - y_err), y_d1=ref.y_d1 - (v_p - ydot_err)),
               wrench_E, memory.controller, t_s, task_frame)
    acting = [p for p in memory.pending if p[0] + oparams.latency_s <= t_s][-1:]  # the one acting at t_s
    coming = [p for p in memory.pending if p[0] + oparams.latency_s > t_s]
    pending = tuple(acting + coming + [(t_s, commanded_task_acceleration(params, res, v_p))])
    res.diagnostics.y_d, res.diagnostics.y_err = y_d, y_err  # the reports keep the measured error
    return res, pending


def offboard_result(res: StepResult, state: AmState, t_s: float, tau: np.ndarray, u: np.ndarray, w_f, r_f,
                    estimated: bool, pending: tuple) -> OffboardResult:
    """The step's result with tau = [0, 0, f, tau_b^, tau_q] and u = T^-T tau in its diagnostics
    (what the vehicle received, module doc), and the memory for the next step."""
    c, d = res.command, res.diagnostics
    d.tau, d.u = tau, u
    cmd = Command(c.thrust_n, tau[3:6], tau[6:])
    mem = OffboardMemory(res.memory, t_s, tuple(state.w_B.tolist()), c.thrust_n, cmd.tau_q_nm, w_f, r_f, pending)
    return OffboardResult(StepResult(cmd, d, res.memory), mem, cmd.tau_B_nm if estimated else None)


_NO_ROWS = np.zeros((0, 3))  # a filter not started yet (amcore.law.attitude_mode_torques)
_NO_PHI = np.zeros((0, 0))  # no filter: the plain backward difference
# what law.attitude_mode_torques_of_packed reads from the step's packed result, in its order
_TERMS_READ = ("Lambda_w", "Gamma_xi_xi", "T_inv", "J_e_xi", "wrench_E_filtered", "J_y", "M_inv", "Lambda_y", "guard")


def _estimate(params: ControllerParams, oparams: OffboardParams, res: StepResult, memory: OffboardMemory,
                       state: AmState, t_s: float, applied: Applied | None):
    """(tau, u = T^-T tau, LP(w_b)'s state, LP(r)'s state, whether tau_b^ was estimated) of
    `offboard_step` by amcore.law.attitude_mode_torques; on the first step (nothing measured
    yet) torque mode's answer, and the filter of w_b started."""
    c, d = res.command, res.diagnostics
    filtered = oparams.torque_cutoff_hz > 0.0
    measured = memory.w_filter is not None if filtered else memory.w_B is not None
    if memory.t_s is None or not measured or memory.tau_q_nm is None or not t_s > memory.t_s:
        tau = np.concatenate(([0.0, 0.0, c.thrust_n], c.tau_B_nm, c.tau_q_nm))
        w_f = lowpass_update(oparams.torque_filter, None, state.w_B, 0.0) if filtered else None
        return tau, d.terms.T_inv.T.dot(tau), w_f, None, False
    dt, w = t_s - memory.t_s, np.array(state.w_B, dtype=float)
    if filtered:
        Phi, w_prev = oparams.torque_filter.transition(dt), w  # w_prev unused: the filter's state has it
        w_filter = np.array(memory.w_filter)
        r_filter = _NO_ROWS if memory.r_filter is None else np.array(memory.r_filter)
    else:
        Phi, w_prev, w_filter, r_filter = _NO_PHI, np.array(memory.w_B), _NO_ROWS, _NO_ROWS
    thrust, tau_q = last_inputs(memory, applied)
    n = c.tau_q_nm.shape[0]
    tau, u, w_filter, r_filter = law.attitude_mode_torques_of_packed(  # the step's terms read in the kernel
        d.packed, packed_offsets(n, _TERMS_READ), n, 1.0 if params.force_compensation else 0.0, c.thrust_n,
        c.tau_B_nm, c.tau_q_nm, float(thrust), np.array(tau_q, dtype=float), w, w_prev, dt, Phi, w_filter, r_filter)
    if not filtered:
        return tau, u, None, None, True
    return tau, u, FilterState(w_filter[0], w_filter[1]), FilterState(r_filter[0], r_filter[1]), True
