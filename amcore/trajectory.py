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

from . import law

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
        """Rows p, pdot, ..., p^(orders) at time t [s], as one (orders + 1, dim) array
        (amcore.law.smooth_path, compiled)."""
        return law.smooth_path(float(t), *self._arrays, orders)

    @cached_property
    def _arrays(self) -> tuple[np.ndarray, ...]:
        """start, and each move's t0, duration, p0 and p1 - p0, as arrays (law.smooth_path)."""
        dim = np.asarray(self.start).size
        return (np.asarray(self.start, dtype=float).ravel().copy(),
                np.array([mv.t0 for mv in self.moves], dtype=float),
                np.array([mv.t1 - mv.t0 for mv in self.moves], dtype=float),
                np.array([np.asarray(mv.p0, dtype=float).ravel() for mv in self.moves]).reshape(-1, dim),
                np.array([np.asarray(mv.p1 - mv.p0, dtype=float).ravel() for mv in self.moves]).reshape(-1, dim))

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
