"""The wall-clock loop's timer and its measurements (pure: the clock is passed in).

`DeadlineTimer` keeps a drift-free schedule: deadline k = t0 + k * period, so a late wake-up
shortens the next wait instead of pushing every later deadline back. A step that starts more
than `miss_after` of a period after its deadline is a deadline miss; the timer then skips the
deadlines already past (it does not run a burst of catch-up steps, which a controller fed the
same samples would spend on nothing) and counts how many it skipped.

`LoopStats` keeps what the loop measures about itself: the period between step starts, the
lateness of each start behind its deadline, the age of each source's sample when a step read
it, and the time from the freshest sample to the setpoint leaving. Quantiles are over a
bounded reservoir of the most recent values (`keep`), counts and maxima over the whole run.
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable

import numpy as np


class DeadlineTimer:
    def __init__(self, period_ns: int, clock: Callable[[], int], miss_after: float = 0.5) -> None:
        """period_ns: the loop's period [ns] on `clock` (monotonic ns); miss_after: the
        lateness, in periods, beyond which a step counts as a deadline miss."""
        if not period_ns > 0:
            raise ValueError(f"period must be > 0 ns, got {period_ns}")
        self.period_ns, self.clock, self.miss_after = int(period_ns), clock, miss_after
        self.t0_ns: int | None = None
        self.k = 0  # index of the next deadline
        self.misses = 0
        self.skipped = 0  # deadlines passed over after a miss
        self.worst_late_ns = 0

    def start(self, t0_ns: int | None = None) -> None:
        self.t0_ns = self.clock() if t0_ns is None else int(t0_ns)
        self.k = 0

    def set_period(self, period_ns: int) -> None:
        """A new period from the next deadline on (the autopilot's clock rate re-estimated),
        the schedule re-anchored at the next deadline so that nothing jumps."""
        if self.t0_ns is None:
            self.period_ns = int(period_ns)
            return
        nxt = self.deadline_ns()
        self.period_ns, self.t0_ns, self.k = int(period_ns), nxt, 0

    def deadline_ns(self) -> int:
        if self.t0_ns is None:
            raise RuntimeError("DeadlineTimer.start() first")
        return self.t0_ns + self.k * self.period_ns

    def wait_s(self) -> float:
        """Seconds until the next deadline (<= 0: due)."""
        return (self.deadline_ns() - self.clock()) * 1e-9

    def fire(self) -> int:
        """Marks the step that starts now as the next deadline's; returns its lateness [ns]."""
        now = self.clock()
        late = now - self.deadline_ns()
        if late > self.worst_late_ns:
            self.worst_late_ns = late
        self.k += 1
        if late > self.miss_after * self.period_ns:
            self.misses += 1
            behind = late // self.period_ns  # deadlines already past: skipped, not run in a burst
            if behind > 0:
                self.k += int(behind)
                self.skipped += int(behind)
        return late


class _Series:
    """A series of values [ns]: count, max, and quantiles over the last `keep`."""

    def __init__(self, keep: int) -> None:
        self.recent: deque[int] = deque(maxlen=keep)
        self.n, self.max = 0, None

    def add(self, v: int) -> None:
        self.recent.append(v)
        self.n += 1
        if self.max is None or v > self.max:
            self.max = v

    def summary_ms(self) -> dict:
        if not self.n:
            return {"n": 0}
        a = np.asarray(self.recent, dtype=float) * 1e-6
        return {"n": self.n, "p50": round(float(np.percentile(a, 50)), 4), "p99": round(float(np.percentile(a, 99)), 4),
                "max": round(self.max * 1e-6, 4)}


class LoopStats:
    def __init__(self, keep: int = 100_000) -> None:
        self.keep = keep
        self.period = _Series(keep)
        self.lateness = _Series(keep)
        self.latency = _Series(keep)  # freshest sample's arrival -> setpoint sent
        self.compute = _Series(keep)  # step start -> setpoint sent
        self.ages: dict[str, _Series] = {}
        self.stale: dict[str, int] = {}
        self._last_start: int | None = None

    def step_started(self, now_ns: int, late_ns: int) -> None:
        if self._last_start is not None:
            self.period.add(now_ns - self._last_start)
        self._last_start = now_ns
        self.lateness.add(max(0, late_ns))

    def sample_age(self, source: str, age_ns: int, stale: bool) -> None:
        s = self.ages.get(source)
        if s is None:
            s = self.ages[source] = _Series(self.keep)
            self.stale[source] = 0
        s.add(age_ns)
        self.stale[source] += int(stale)

    def sent(self, start_ns: int, freshest_rx_ns: int | None, now_ns: int) -> None:
        self.compute.add(now_ns - start_ns)
        if freshest_rx_ns is not None:
            self.latency.add(now_ns - freshest_rx_ns)

    def to_dict(self, timer: DeadlineTimer | None = None) -> dict:
        d = {"period_ms": self.period.summary_ms(), "lateness_ms": self.lateness.summary_ms(),
             "compute_ms": self.compute.summary_ms(), "sample_to_setpoint_ms": self.latency.summary_ms(),
             "sample_age_ms": {k: v.summary_ms() for k, v in self.ages.items()},
             "stale_steps": dict(self.stale)}
        if timer is not None:
            d["deadline_misses"] = timer.misses
            d["skipped_deadlines"] = timer.skipped
            d["worst_lateness_ms"] = round(timer.worst_late_ns * 1e-6, 4)
            d["period_target_ms"] = round(timer.period_ns * 1e-6, 4)
        return d
