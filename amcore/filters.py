"""Second-order low-pass filter with exact derivatives.

The measured wrench enters f_d (eq. Com_controller) and, through f_d's first and second
time derivatives, the desired angular velocity and acceleration of eq. Rd. Filtering with
    xddot = w^2 (u - x) - 2 zeta w xdot
gives a smooth signal whose first and second derivatives are known exactly from the
filter state, so no numerical differentiation of a noisy measurement is needed.
The update is the exact zero-order-hold discretisation for the step dt.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _expm2(A: np.ndarray) -> np.ndarray:
    """exp(A) for a real 2x2 matrix (closed form)."""
    s = 0.5 * (A[0, 0] + A[1, 1])
    det = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    disc = s * s - det
    B = A - s * np.eye(2)
    if abs(disc) < 1e-14:
        return np.exp(s) * (np.eye(2) + B)
    if disc > 0:
        d = np.sqrt(disc)
        return np.exp(s) * (np.cosh(d) * np.eye(2) + np.sinh(d) / d * B)
    d = np.sqrt(-disc)
    return np.exp(s) * (np.cos(d) * np.eye(2) + np.sin(d) / d * B)


@dataclass(frozen=True)
class LowPass2:
    """Filter constants for cutoff `cutoff_hz` and damping ratio `zeta`."""

    cutoff_hz: float
    zeta: float = 1.0

    @property
    def omega(self) -> float:
        return 2.0 * np.pi * self.cutoff_hz

    def transition(self, dt: float) -> np.ndarray:
        w = self.omega
        return _expm2(np.array([[0.0, 1.0], [-w * w, -2.0 * self.zeta * w]]) * dt)


@dataclass(frozen=True)
class FilterState:
    """x: filtered value, xdot: its rate (arrays of the signal's shape)."""

    x: np.ndarray
    xdot: np.ndarray


def lowpass_update(f: LowPass2, state: FilterState | None, u: np.ndarray, dt: float) -> FilterState:
    """Advance the filter by dt with input u held constant over the interval."""
    if state is None:
        return FilterState(np.array(u, dtype=float), np.zeros_like(u, dtype=float))
    if dt <= 0.0:
        return state
    Phi = f.transition(dt)
    e = state.x - u
    return FilterState(u + Phi[0, 0] * e + Phi[0, 1] * state.xdot, Phi[1, 0] * e + Phi[1, 1] * state.xdot)


def lowpass_accel(f: LowPass2, state: FilterState, u: np.ndarray) -> np.ndarray:
    """Second derivative of the filtered signal given the current input u."""
    w = f.omega
    return w * w * (u - state.x) - 2.0 * f.zeta * w * state.xdot
