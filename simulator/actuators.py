"""The actuators' own physics between a command and the world (pure Python and numpy; no I/O).
The rotors' allocation is `amcore.allocation`, built from the vehicle's rotor table.

Rotor dynamics: each rotor's thrust lags its command by a first-order lag,

    tau df_i/dt = f_c,i - f_i                                   (per rotor i)

A command is held over each physics step dt, so the exact discrete form is

    f_i <- f_i + alpha (f_c,i - f_i),   alpha = 1 - exp(-dt / tau),

and the thrust applied during a step is the one reached at its end (for tau >> dt, half a
step ahead of the step's mean: 0.5 ms against tens of ms). tau = 0 is the ideal actuator;
`World` then skips this model altogether, so ideal runs stay bit-identical to runs
without it. The rotors start at their first command (the vehicles are already flying when a
run starts). Why a thrust lag: a propeller's speed follows the ESC's command with a
mechanical time constant (PX4's Gazebo motor model lags rotor speed by 12.5 ms up and
25 ms down for an Iris-sized rotor); thrust ~ speed^2 has the same time constant for small
changes.

Joint torques: the arm's drivers clip each joint's command to its limit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


# ---------------------------------------------------------------------- rotor thrusts
class RotorLag:
    """First-order lag of `count` rotor thrusts [N] with time constant `tau_s` (one for all, or
    one per rotor; 0 for a rotor without lag), stepped every `dt_s`."""

    def __init__(self, tau_s, dt_s: float, count: int = 4) -> None:
        taus = [float(tau_s)] * count if isinstance(tau_s, (int, float)) else [float(t) for t in tau_s]
        if len(taus) != count or not (all(t >= 0.0 for t in taus) and any(t > 0.0 for t in taus) and dt_s > 0.0):
            raise ValueError(f"RotorLag needs {count} time constants >= 0 (one > 0) and dt_s > 0, got {tau_s}, {dt_s}")
        self.tau_s, self.dt_s, self.count = tau_s, dt_s, count
        self.alphas = [1.0 - math.exp(-dt_s / t) if t > 0.0 else 1.0 for t in taus]
        self.alpha = self.alphas[0]
        self.thrusts_n: list[float] | None = None  # None until the first command

    def step(self, command_n) -> list[float]:
        """Advance one physics step under `command_n` (count floats [N]); the thrusts it ends with."""
        if self.thrusts_n is None:
            self.thrusts_n = [float(c) for c in command_n]
        else:
            self.thrusts_n = [f + a * (c - f) for f, c, a in zip(self.thrusts_n, command_n, self.alphas)]
        return self.thrusts_n


# ---------------------------------------------------------------------- joint torques
@dataclass(frozen=True)
class JointTorqueResult:
    """Joint torques after limiting: applied_nm (n,) [N m]; saturated if any was clipped."""

    applied_nm: np.ndarray
    saturated: bool


def limit_joint_torques(tau_q_nm, tau_max_nm) -> JointTorqueResult:
    """Clip each joint torque to [-tau_max, tau_max] [N m]; report whether any was clipped."""
    tau = np.asarray(tau_q_nm, dtype=float)
    tau_max = np.asarray(tau_max_nm, dtype=float)
    if tau.shape != tau_max.shape:
        raise ValueError(f"got joint torques of shape {tau.shape} for {tau_max.shape[0]} joints")
    t, t_max = tau.tolist(), tau_max.tolist()  # Python floats: a few joints, per AM per step
    if not math.isfinite(sum(t)):
        raise ValueError(f"non-finite joint torque command: {tau}")
    applied = [min(max(x, -m), m) for x, m in zip(t, t_max)]
    return JointTorqueResult(applied_nm=np.array(applied), saturated=applied != t)
