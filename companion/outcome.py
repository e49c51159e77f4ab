"""Per-phase summary of one AM's controller errors, accumulated step by step (pure).

For each phase (approach, grasp, hover) it keeps the final and the largest norm of the CoM
error |r~_c| [m], the attitude error |e_R| [rad] and each task error component |y~_i|,
and in the hover window the mean of the filtered end-effector force in W [N].
"""
from __future__ import annotations

import math

import numpy as np

from amcore.control import Diagnostics


class PhaseStats:
    def __init__(self) -> None:
        self.n = 0
        self.final: dict[str, object] = {}
        self.max: dict[str, object] = {}
        self.t_first = self.t_last = None

    def add(self, t: float, values: dict[str, np.ndarray | float]) -> None:
        self.n += 1
        if self.t_first is None:
            self.t_first = t
        self.t_last = t
        mx = self.max
        for k, v in values.items():  # plain floats and lists: this runs every control step
            if isinstance(v, float):
                self.final[k] = v
                mx[k] = max(mx.get(k, 0.0), abs(v))
            else:
                v = v.tolist() if isinstance(v, np.ndarray) else list(v)
                self.final[k] = v
                old = mx.get(k)
                mx[k] = list(map(abs, v)) if old is None else list(map(max, old, map(abs, v)))

    def to_dict(self) -> dict:
        def j(x):
            x = np.asarray(x)
            return x.tolist() if x.ndim else float(x)
        return {"steps": self.n, "t_first": self.t_first, "t_last": self.t_last,
                "final": {k: j(v) for k, v in self.final.items()}, "max": {k: j(v) for k, v in self.max.items()}}


class Outcome:
    """Accumulates `Diagnostics` of every step; `hover_window` = (t0, t1) for force means."""

    def __init__(self, sysid: int, phases: tuple[str, ...], hover_window: tuple[float, float]) -> None:
        self.sysid = sysid
        self.phases = {p: PhaseStats() for p in phases}
        self.hover_window = hover_window
        self._force_sum = np.zeros(3)
        self._force_n = 0
        self.at: dict[str, dict] = {}  # snapshots at named instants
        self.steps = 0

    def add(self, t: float, phase: str, d: Diagnostics) -> None:
        self.steps += 1
        r_c_err = d.r_c_err.tolist()
        values = {"r_c_err": math.hypot(*r_c_err), "e_R": math.hypot(*d.e_R.tolist()),
                  "y_err": d.y_err, "r_c_err_vec": r_c_err, "sigma_min_J3": float(d.sigma_min_J3)}
        self.phases[phase].add(t, values)
        if self.hover_window[0] <= t <= self.hover_window[1]:
            self._force_sum += d.F_rc
            self._force_n += 1

    def snapshot(self, name: str, t: float, d: Diagnostics) -> None:
        self.at[name] = {"t": t, "r_c_err": float(np.linalg.norm(d.r_c_err)), "e_R": float(np.linalg.norm(d.e_R)),
                         "y_err": np.asarray(d.y_err).tolist()}

    def to_dict(self) -> dict:
        mean_F = (self._force_sum / self._force_n).tolist() if self._force_n else None
        return {"sysid": self.sysid, "steps": self.steps,
                "phases": {p: s.to_dict() for p, s in self.phases.items()}, "at": self.at,
                "hover_window_s": list(self.hover_window), "hover_mean_F_W_n": mean_F}
