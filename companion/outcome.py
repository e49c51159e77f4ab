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
    """The steps of one phase: for each quantity its final value and its largest magnitude
    (element by element for a vector; a float's from 0). A step's values are kept as one
    flat list of floats, laid out by `layout`: (name, length, or None for a float), the same
    at every step."""

    def __init__(self) -> None:
        self.n = 0
        self.t_first = self.t_last = None
        self.layout: tuple[tuple[str, int | None], ...] | None = None
        self._final: list[float] = []
        self._max: list[float] = []

    def add(self, t: float, values: dict[str, np.ndarray | float]) -> None:
        """One step's values by name: floats, and 1-D arrays or sequences of floats."""
        layout, flat = [], []
        for k, v in values.items():
            if isinstance(v, float):
                layout.append((k, None))
                flat.append(v)
            else:
                v = v.tolist() if isinstance(v, np.ndarray) else list(v)
                layout.append((k, len(v)))
                flat.extend(v)
        self.add_flat(t, tuple(layout), flat)

    def add_flat(self, t: float, layout: tuple[tuple[str, int | None], ...], flat: list[float]) -> None:
        """`add` of the values laid out by `layout` in one list (which the stats keep as the final values)."""
        self.n += 1
        self.t_last = t
        if self.t_first is None:
            self.t_first = t
            self.layout = layout
            # a float's largest magnitude starts from 0 (max keeps its first argument on a NaN)
            self._max = [abs(x) if size else max(0.0, abs(x)) for size, x in zip(_sizes(layout), flat)]
        else:
            if layout is not self.layout and layout != self.layout:
                raise ValueError(f"phase values {layout} after {self.layout}")
            self._max = list(map(max, self._max, map(abs, flat)))  # plain floats: this runs every control step
        self._final = flat

    def to_dict(self) -> dict:
        return {"steps": self.n, "t_first": self.t_first, "t_last": self.t_last,
                "final": self._named(self._final), "max": self._named(self._max)}

    def _named(self, flat: list[float]) -> dict[str, object]:
        out, at = {}, 0
        for name, size in self.layout or ():
            if size is None:
                out[name] = float(flat[at])
                at += 1
            else:
                out[name] = [float(x) for x in flat[at:at + size]]
                at += size
        return out


def _sizes(layout) -> list[int | None]:
    """Per flat element of `layout`, its vector's length, or None for a float."""
    return [size for _, size in layout for _ in range(size if size is not None else 1)]


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
        self._layout: tuple | None = None  # the phase values' (PhaseStats.layout), formed at the first step

    def add(self, t: float, phase: str, d: Diagnostics) -> None:
        self.steps += 1
        r_c_err, y_err = d.r_c_err.tolist(), d.y_err.tolist()
        if self._layout is None or self._layout[2][1] != len(y_err):
            self._layout = (("r_c_err", None), ("e_R", None), ("y_err", len(y_err)), ("r_c_err_vec", 3),
                            ("sigma_min_J3", None))
        self.phases[phase].add_flat(t, self._layout, [math.hypot(*r_c_err), math.hypot(*d.e_R.tolist()), *y_err,
                                                      *r_c_err, float(d.sigma_min_J3)])
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
