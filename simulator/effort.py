"""The joint torques an arm's servos report (pure: numpy only, no I/O).

A Dynamixel-class servo reports its present current; the driver multiplies it by the torque
constant and the flight controller (or the servo bus) streams the result as
AM_JOINT_STATE.effort_nm. `JointEffortSensor` models that reading of the torque the joint
actually receives ([devices.effort], `amcore.config.JointEffortSpec`; levels and sources in
configs/randomize/default.toml and docs/flight_controller.md), once per physics step:

    x <- x + (1 - exp(-dt / lag_s)) (tau_applied - x)          first-order lag (lag_s = 0: none)
    effort = resolution_nm * round((x + noise_nm * N(0, 1)) / resolution_nm)   (resolution 0: none)

with its own seeded generator (scenario seed, sysid, its stream), so that the other devices'
draws do not depend on it.
"""
from __future__ import annotations

import math

import numpy as np

from .noise import NoiseBlock

from amcore.config import JointEffortSpec

_STREAM = 0xEFF0  # distinguishes the effort's stream from the other seeded streams of an AM


class JointEffortSensor:
    """One arm's measured joint torques; `sample(tau_applied)` once per physics step of dt_s.

    `advance(tau_applied)` is `sample` for a step whose reading may not be read: the lag and
    the draws advance (the draws taken in blocks, `simulator.noise`), and the reading is
    formed when `last` is read, from the same numbers, so that a run reads the same readings
    either way."""

    def __init__(self, spec: JointEffortSpec, scale: float, n: int, dt_s: float, seed: int, sysid: int) -> None:
        self.noise_nm = scale * spec.noise_nm
        self.resolution_nm = spec.resolution_nm
        self.alpha = 1.0 if spec.lag_s <= 0.0 else -math.expm1(-dt_s / spec.lag_s)
        self._rng = np.random.default_rng([seed, sysid, _STREAM])
        self._noise = NoiseBlock(self._rng, n) if self.noise_nm > 0.0 else None
        self._x: list[float] | None = None  # the lagged torque, on Python floats
        self._draw: np.ndarray | None = None  # the last step's draws
        self.n = n
        self._last: np.ndarray | None = np.zeros(n)

    def advance(self, tau_applied_nm) -> None:
        """One more physics step with `tau_applied_nm` acting; its reading is `last`."""
        u = np.asarray(tau_applied_nm, dtype=float).tolist()
        x = self._x
        self._x = u if x is None else [xi + self.alpha * (ui - xi) for xi, ui in zip(x, u)]
        self._draw = None if self._noise is None else self._noise.next()
        self._last = None

    def sample(self, tau_applied_nm) -> np.ndarray:
        """The reading [N m] after one more physics step with `tau_applied_nm` acting."""
        self.advance(tau_applied_nm)
        return self.last

    @property
    def last(self) -> np.ndarray:
        """The reading of the last step [N m] (zeros before the first)."""
        if self._last is None:
            x = np.array(self._x)
            y = x + self.noise_nm * self._draw if self._draw is not None else x
            if self.resolution_nm > 0.0:
                y = self.resolution_nm * np.round(y / self.resolution_nm)
            self._last = y
        return self._last
