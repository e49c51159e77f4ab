"""Smooth rest-to-rest reference trajectories.

The desired attitude R_b,d (eq. Rd) is built from f_d, whose second derivative contains
the CoM reference's fourth derivative, so CoM references must be C3 or smoother. Each
move here follows the minimum-snap rest-to-rest profile
    s(tau) = 35 tau^4 - 84 tau^5 + 70 tau^6 - 20 tau^7,  tau in [0, 1],
whose velocity, acceleration and jerk vanish at both ends (C3 across segments).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

_S = np.array([0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0])  # coefficients of tau^0..tau^7


def _derivative_coefficients(order: int) -> tuple[float, ...]:
    """Coefficients of d^order s / d tau^order, highest power first (Horner order)."""
    c = _S.copy()
    for _ in range(order):
        c = c[1:] * np.arange(1, len(c))
    return tuple(c[::-1].tolist())


_S_HORNER = tuple(_derivative_coefficients(k) for k in range(len(_S)))


def _smoothstep(tau: float, order: int) -> float:
    """d^order s / d tau^order at tau (tau is clamped to [0, 1]); Horner's scheme, as np.polyval."""
    if tau <= 0.0 or tau >= 1.0:
        return (1.0 if tau >= 1.0 else 0.0) if order == 0 else 0.0
    if order >= len(_S_HORNER):
        return 0.0
    y = 0.0
    for c in _S_HORNER[order]:
        y = y * tau + c
    return y


def _smoothstep_derivs(tau: float, orders: int) -> list[float]:
    """[s, ds/dtau, ..., d^orders s / dtau^orders] at tau (clamped to [0, 1]).

    Up to the snap these are _smoothstep's Horner evaluations written out (bit for bit the
    same: the trailing zero coefficients become bare multiplications by tau).
    """
    if orders > 4 or tau <= 0.0 or tau >= 1.0:
        return [_smoothstep(tau, k) for k in range(orders + 1)]
    t = tau
    s3 = ((-4200.0 * t + 8400.0) * t - 5040.0) * t + 840.0
    s2 = ((-840.0 * t + 2100.0) * t - 1680.0) * t + 420.0
    s1 = ((-140.0 * t + 420.0) * t - 420.0) * t + 140.0
    s0 = ((-20.0 * t + 70.0) * t - 84.0) * t + 35.0
    return [s0 * t * t * t * t, s1 * t * t * t, s2 * t * t, s3 * t,
            ((-16800.0 * t + 25200.0) * t - 10080.0) * t + 840.0][0:orders + 1]


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
        return list(self.eval_array(t, orders))

    def eval_array(self, t: float, orders: int) -> np.ndarray:
        """Rows p, pdot, ..., p^(orders) at time t [s], as one (orders + 1, dim) array."""
        return np.array(self.eval_flat(t, orders)).reshape(orders + 1, -1)

    def eval_flat(self, t: float, orders: int) -> list[float]:
        """p, pdot, ..., p^(orders) at time t [s], concatenated, on Python floats (numpy's
        per-call cost exceeds the arithmetic here). Row 0 is p0 + s d, row k (s^(k) / T^k) d.

        The last move that has started gives the value (the ones before it have ended).
        """
        current = None
        for seg in self._segments:
            if t < seg[0]:
                break
            current = seg
        if current is None:
            return self._start + [0.0] * (orders * len(self._start))
        t0, T, p0, d = current
        s = _smoothstep_derivs((t - t0) / T, orders)
        s0 = s[0]
        out = [a + b * s0 for a, b in zip(p0, d)]
        for k in range(1, orders + 1):
            sk = s[k] / T**k
            out += [b * sk for b in d]
        return out

    @cached_property
    def _start(self) -> list[float]:
        return np.asarray(self.start, dtype=float).ravel().tolist()

    @cached_property
    def _segments(self) -> tuple[tuple[float, float, list[float], list[float]], ...]:
        """(t0, duration, p0, p1 - p0) of each move, the points as lists of floats."""
        return tuple((mv.t0, mv.t1 - mv.t0, np.asarray(mv.p0, dtype=float).tolist(),
                      np.asarray(mv.p1 - mv.p0, dtype=float).tolist()) for mv in self.moves)

    def transformed(self, R: np.ndarray, p: np.ndarray) -> "SmoothPath":
        """The path of R x + p (every derivative turns with R)."""
        def f(x):
            return R.dot(x) + p
        return SmoothPath(f(self.start), tuple(Move(mv.t0, mv.t1, f(mv.p0), f(mv.p1)) for mv in self.moves))


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
