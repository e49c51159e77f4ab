"""Second-order low-pass filter with exact derivatives.

The measured wrench enters f_d (eq. Com_controller) and, through f_d's first and second
time derivatives, the desired angular velocity and acceleration of eq. Rd. Filtering with
    xddot = w^2 (u - x) - 2 zeta w xdot
gives a smooth signal whose first and second derivatives are known exactly from the
filter state, so no numerical differentiation of a noisy measurement is needed.
The update is the exact zero-order-hold discretisation for the step dt.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

import numpy as np


def _expm2_entries(a: float, b: float, c: float, d: float) -> tuple[float, float, float, float]:
    """exp([[a, b], [c, d]]) row by row, on Python floats (numpy costs ~10x at 2x2)."""
    s = 0.5 * (a + d)
    det = a * d - b * c
    disc = s * s - det
    es = math.exp(s)
    if abs(disc) < 1e-14:
        p, q = es, es
    elif disc > 0:
        r = math.sqrt(disc)
        p, q = es * math.cosh(r), es * (math.sinh(r) / r)
    else:
        r = math.sqrt(-disc)
        p, q = es * math.cos(r), es * (math.sin(r) / r)
    # exp(A) = p I + q (A - s I)
    return p + q * (a - s), q * b, q * c, p + q * (d - s)


@dataclass(frozen=True)
class LowPass2:
    """Filter constants for cutoff `cutoff_hz` and damping ratio `zeta`."""

    cutoff_hz: float
    zeta: float = 1.0

    @property
    def omega(self) -> float:
        return 2.0 * np.pi * self.cutoff_hz

    def transition(self, dt: float) -> np.ndarray:
        """exp(A dt) of the filter's state matrix A = [[0, 1], [-w^2, -2 zeta w]] (cached per dt:
        treat it as read-only)."""
        return _transition_matrix(self.cutoff_hz, self.zeta, dt)

    def _transition_entries(self, dt: float) -> tuple[float, float, float, float]:
        return _transition_entries(self.cutoff_hz, self.zeta, dt)


@lru_cache(maxsize=64)  # a controller steps with a handful of distinct dt values
def _transition_entries(cutoff_hz: float, zeta: float, dt: float) -> tuple[float, float, float, float]:
    """exp(A dt) of the filter's state matrix A = [[0, 1], [-w^2, -2 zeta w]], row by row."""
    w = 2.0 * np.pi * cutoff_hz
    return _expm2_entries(0.0, dt, -w * w * dt, -2.0 * zeta * w * dt)


@lru_cache(maxsize=64)
def _transition_matrix(cutoff_hz: float, zeta: float, dt: float) -> np.ndarray:
    return np.array(_transition_entries(cutoff_hz, zeta, dt)).reshape(2, 2)


class FilterState(NamedTuple):
    """x: filtered value, xdot: its rate (arrays of the signal's shape)."""

    x: np.ndarray
    xdot: np.ndarray


def lowpass_update(f: LowPass2, state: FilterState | None, u: np.ndarray, dt: float) -> FilterState:
    """Advance the filter by dt with input u held constant over the interval."""
    if state is None:
        return FilterState(np.array(u, dtype=float), np.zeros_like(u, dtype=float))
    if dt <= 0.0:
        return state
    if np.ndim(u) != 1:
        p00, p01, p10, p11 = f._transition_entries(dt)
        e = state.x - u
        return FilterState(u + p00 * e + p01 * state.xdot, p10 * e + p11 * state.xdot)
    x, xd = lowpass_update_floats(f, state, np.asarray(u).tolist(), dt)
    return FilterState(np.array(x), np.array(xd))


def lowpass_update_floats(f: LowPass2, state: FilterState | None, u, dt: float) -> tuple[list, list]:
    """lowpass_update of a vector signal on Python floats (a 6-vector costs numpy ~8 calls of
    ~0.7 us): the new (x, xdot) as lists, for u a sequence of floats."""
    if state is None:
        return list(u), [0.0] * len(u)
    x, xdot = state.x.tolist(), state.xdot.tolist()
    if dt <= 0.0:
        return x, xdot
    p00, p01, p10, p11 = f._transition_entries(dt)
    x_new, xd_new = [], []
    for xi, xdi, ui in zip(x, xdot, u):
        e = xi - ui
        x_new.append(ui + p00 * e + p01 * xdi)
        xd_new.append(p10 * e + p11 * xdi)
    return x_new, xd_new


def lowpass_accel(f: LowPass2, state: FilterState, u: np.ndarray) -> np.ndarray:
    """Second derivative of the filtered signal given the current input u."""
    w = f.omega
    return w * w * (u - state.x) - 2.0 * f.zeta * w * state.xdot
