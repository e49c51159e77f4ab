"""Ideal closed loop: the controller against pinocchio's forward dynamics (no contact solver).

The plant is eq. dynamics, M Vdot + C V + g = tau + J_e^T F_e, integrated with RK4 over
each control period while the command is held (zero-order hold), as a digital controller
would see it. An optional external wrench F_e(t, state) acts on the end-effector (body
wrench, expressed in {e}); the controller may be fed the same wrench as its F/T reading.
Used by the theorem tests and by the free-flight demo.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import pinocchio as pin

from .control import ControllerMemory, ControllerParams, Reference, StepResult, step
from .model import AmModel, AmState, create_data

WrenchFn = Callable[[float, AmState], np.ndarray]


def forward_dynamics(model: AmModel, data: pin.Data, q: np.ndarray, v: np.ndarray,
                     tau: np.ndarray, wrench_E: np.ndarray | None) -> np.ndarray:
    """Vdot from eq. dynamics with the body wrench wrench_E applied at {e}."""
    pm = model.pin_model
    if wrench_E is None:
        return pin.aba(pm, data, q, v, tau)
    pin.computeJointJacobians(pm, data, q)
    pin.updateFramePlacements(pm, data)
    J_e = pin.getFrameJacobian(pm, data, model.ee_frame_id, pin.LOCAL)
    return pin.aba(pm, data, q, v, tau + J_e.T @ wrench_E)


def full_tau(cmd, n: int) -> np.ndarray:
    """tau = [0, 0, f, tau_b, tau_q] of eq. dynamics from a Command."""
    return np.concatenate([[0.0, 0.0, cmd.thrust_n], cmd.tau_B_nm, cmd.tau_q_nm])


@dataclass
class Sample:
    t: float
    state: AmState
    result: StepResult
    wrench_E: np.ndarray


def run_closed_loop(model: AmModel, params: ControllerParams, reference: Callable[[float], Reference],
                    x0: AmState, t_end: float, dt: float = 1e-3, wrench: WrenchFn | None = None,
                    sense_wrench: bool = True, every: int = 1,
                    on_step: Callable[[Sample], None] | None = None, law=step, memory=None) -> list[Sample]:
    """Simulate t in [0, t_end); returns every `every`-th sample (controller output included).

    `law` and `memory`: another controller with the same step signature and its initial memory
    (`amcore.baseline.step`, `BaselineMemory()`); by default the paper's law."""
    pm = model.pin_model
    cdata, pdata = create_data(model), create_data(model)
    q, v = x0.pin_q(), x0.pin_v()
    mem = ControllerMemory() if memory is None else memory
    out: list[Sample] = []
    steps = int(round(t_end / dt))
    zero = np.zeros(6)
    for k in range(steps):
        t = k * dt
        st = AmState.from_pin(q, v)
        F = wrench(t, st) if wrench is not None else zero
        res = law(model, cdata, params, st, reference(t), F if sense_wrench else zero, mem, t)
        mem = res.memory
        tau = full_tau(res.command, model.n)
        smp = Sample(t, st, res, F)
        if k % every == 0:
            out.append(smp)
        if on_step is not None:
            on_step(smp)
        Fw = F if wrench is not None else None

        def f(qq, vv):
            return forward_dynamics(model, pdata, qq, vv, tau, Fw)

        k1v = f(q, v)
        k1q = v
        q2 = pin.integrate(pm, q, 0.5 * dt * k1q)
        k2q = v + 0.5 * dt * k1v
        k2v = f(q2, k2q)
        q3 = pin.integrate(pm, q, 0.5 * dt * k2q)
        k3q = v + 0.5 * dt * k2v
        k3v = f(q3, k3q)
        q4 = pin.integrate(pm, q, dt * k3q)
        k4q = v + dt * k3v
        k4v = f(q4, k4q)
        q = pin.integrate(pm, q, dt / 6.0 * (k1q + 2 * k2q + 2 * k3q + k4q))
        v = v + dt / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        if not np.all(np.isfinite(v)):
            raise FloatingPointError(f"closed loop diverged at t = {t:.3f} s")
    return out
