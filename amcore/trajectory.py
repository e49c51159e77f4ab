"""Smooth rest-to-rest reference trajectories.

The desired attitude R_b,d (eq. Rd) is built from f_d, whose second derivative contains
the CoM reference's fourth derivative, so CoM references must be C3 or smoother. Each
move here follows the minimum-snap rest-to-rest profile
    s(tau) = 35 tau^4 - 84 tau^5 + 70 tau^6 - 20 tau^7,  tau in [0, 1],
whose velocity, acceleration and jerk vanish at both ends (C3 across segments).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_S = np.array([0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0])  # coefficients of tau^0..tau^7


def _smoothstep(tau: float, order: int) -> float:
    """d^order s / d tau^order at tau (tau is clamped to [0, 1])."""
    if tau <= 0.0 or tau >= 1.0:
        return (1.0 if tau >= 1.0 else 0.0) if order == 0 else 0.0
    c = _S.copy()
    for _ in range(order):
        c = c[1:] * np.arange(1, len(c))
    return float(np.polyval(c[::-1], tau))


@dataclass(frozen=True)
class Move:
    """Rest-to-rest move from p0 at t0 to p1 at t1."""

    t0: float
    t1: float
    p0: np.ndarray
    p1: np.ndarray


@dataclass(frozen=True)
class SmoothPath:
    """A sequence of rest-to-rest moves; holds between and after them."""

    start: np.ndarray
    moves: tuple[Move, ...]

    def eval(self, t: float, orders: int) -> list[np.ndarray]:
        """[p, pdot, ..., p^(orders)] at time t [s]."""
        out = [np.array(self.start, dtype=float)] + [np.zeros_like(self.start, dtype=float) for _ in range(orders)]
        for mv in self.moves:
            if t < mv.t0:
                break
            T = mv.t1 - mv.t0
            tau = (t - mv.t0) / T
            d = mv.p1 - mv.p0
            out[0] = mv.p0 + d * _smoothstep(tau, 0)
            for k in range(1, orders + 1):
                out[k] = d * (_smoothstep(tau, k) / T**k)
        return out


def path_through(start: np.ndarray, moves: list[tuple[float, float, np.ndarray]]) -> SmoothPath:
    """Build a SmoothPath from (t0, t1, target) triples; each move starts where the last ended."""
    p = np.array(start, dtype=float)
    out = []
    for t0, t1, target in moves:
        target = np.array(target, dtype=float)
        if not t1 > t0:
            raise ValueError(f"move must have t1 > t0, got {t0}..{t1}")
        if out and t0 < out[-1].t1:
            raise ValueError("moves overlap")
        out.append(Move(t0, t1, p, target))
        p = target
    return SmoothPath(np.array(start, dtype=float), tuple(out))
