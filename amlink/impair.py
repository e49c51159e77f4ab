"""Deterministic link impairment in simulation time (pure: numpy only, no sockets, no clock).

The lockstep sockets stay reliable (retransmission, :mod:`amlink.lockstep`); what
a *flight controller* receives is impaired here, in whole simulation steps, so
that loss and delay affect control reproducibly.  Per vehicle and step::

    link = ImpairedLink(LinkImpairment(loss=0.05, delay_s=0.004, jitter_s=0.002, rate_hz=1000.0, seed=1),
                        stream=sysid)
    ...
    setpoint = server.exchange(frames)[sysid]      # computed for step k
    command = link.step(k, setpoint)               # what the flight controller applies at step k
    # None until the first setpoint arrives; afterwards the newest one that arrived (zero-order hold)

Model, per setpoint sent at step k (five uniform draws per setpoint, always, so
the schedule depends only on the seed, the stream and the steps):

* lost with probability ``loss`` (nothing arrives);
* else it arrives at step ``k + D + J + R``: ``D = round(delay_s * rate_hz)``,
  ``J`` uniform in ``0 .. round(jitter_s * rate_hz)``, ``R`` = 0, or with
  probability ``reorder`` uniform in ``1 .. reorder_max_steps`` (held back, so a
  later setpoint overtakes it);
* with probability ``duplicate`` a second copy arrives one step after the first.

A setpoint that arrives at the step it was sent is applied at that step (zero
delay equals the reliable lockstep).  The flight controller applies the newest
*step* it has seen: an arrival older than what it holds is ignored (counted),
so a command is never replaced by an older one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Generic, TypeVar

import numpy as np

T = TypeVar("T")

_BLOCK = 256  # setpoints whose draws a channel takes from its stream at once


@dataclass(frozen=True)
class LinkImpairment:
    """Impairment of the companion -> flight controller path, in simulation time.

    Attributes:
        loss: probability a setpoint never arrives.
        delay_s: fixed latency [s], rounded to whole steps.
        jitter_s: extra latency uniform in [0, jitter_s] [s], in whole steps.
        reorder: probability a setpoint is held back 1..reorder_max_steps extra steps.
        reorder_max_steps: the longest such hold [steps].
        duplicate: probability a setpoint arrives twice (the copy one step later).
        rate_hz: simulation step rate [Hz].
        seed: base seed; each vehicle draws from its own stream ``(seed, stream)``.
    """

    loss: float = 0.0
    delay_s: float = 0.0
    jitter_s: float = 0.0
    reorder: float = 0.0
    reorder_max_steps: int = 3
    duplicate: float = 0.0
    rate_hz: float = 1000.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("loss", "reorder", "duplicate"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"LinkImpairment.{name} must be in [0, 1], got {v}")
        for name in ("delay_s", "jitter_s"):
            v = getattr(self, name)
            if not (v >= 0.0 and math.isfinite(v)):
                raise ValueError(f"LinkImpairment.{name} must be finite and >= 0, got {v}")
        if not (self.rate_hz > 0.0 and math.isfinite(self.rate_hz)):
            raise ValueError(f"LinkImpairment.rate_hz must be positive, got {self.rate_hz}")
        if self.reorder_max_steps < 1:
            raise ValueError(f"LinkImpairment.reorder_max_steps must be >= 1, got {self.reorder_max_steps}")

    @property
    def delay_steps(self) -> int:
        return round(self.delay_s * self.rate_hz)

    @property
    def jitter_steps(self) -> int:
        return round(self.jitter_s * self.rate_hz)

    @property
    def is_ideal(self) -> bool:
        """True if every setpoint arrives once, at the step it was sent."""
        return self.loss == self.delay_s == self.jitter_s == self.reorder == self.duplicate == 0.0

    @classmethod
    def for_scenario(cls, spec) -> LinkImpairment:
        """From a loaded scenario's ``[link]`` table (``amcore.config.ScenarioSpec``, duck-typed)."""
        ln = spec.link
        return cls(loss=ln.loss, delay_s=ln.delay_s, jitter_s=ln.jitter_s, reorder=ln.reorder,
                   duplicate=ln.duplicate, rate_hz=spec.rate_hz, seed=spec.seed)  # fmt: skip

    def rng(self, stream: int = 0) -> np.random.Generator:
        """The generator of vehicle ``stream`` (e.g. its sysid)."""
        return np.random.default_rng([self.seed, stream])


@dataclass
class ChannelStats:
    sent: int = 0
    lost: int = 0
    delayed: int = 0  # arrived at least one step after it was sent
    reordered: int = 0  # held back by the reorder draw
    duplicated: int = 0
    delivered: int = 0  # arrivals, copies included


class ImpairedChannel(Generic[T]):
    """Which setpoints arrive at which step (see the module docstring for the model)."""

    def __init__(self, impairment: LinkImpairment, rng: np.random.Generator) -> None:
        self.impairment = impairment
        self.stats = ChannelStats()
        self._rng = rng
        self._draws: list[float] = []  # a block of the stream's uniform draws (`_draw5`), used up to _at
        self._at = 0
        self._pending: dict[int, list[tuple[int, T]]] = {}  # arrival step -> [(sent step, item)]
        self._now = -1
        self._ideal = impairment.is_ideal
        self._delay_steps, self._jitter_steps = impairment.delay_steps, impairment.jitter_steps

    def _draw5(self) -> list[float]:
        """The next five uniform draws of the channel's stream, as Python floats: the numbers
        `rng.random(5)` would give, read from a block of _BLOCK setpoints' draws (one draw
        per element, in order, so a block holds the same numbers as its calls one by one)."""
        i = self._at
        if i == len(self._draws):
            self._draws, i = self._rng.random(5 * _BLOCK).tolist(), 0
        self._at = i + 5
        return self._draws[i:i + 5]

    def send(self, step: int, item: T) -> None:
        """The setpoint ``item`` for step ``step`` leaves the companion at that step."""
        if step < self._now:
            raise ValueError(f"send at step {step} after deliver({self._now}): time goes forward")
        imp, st = self.impairment, self.stats
        if self._ideal:  # arrives at once, no draws: the per-step path of an unimpaired link
            st.sent += 1
            self._pending.setdefault(step, []).append((step, item))
            return
        u_loss, u_jitter, u_reorder, u_hold, u_dup = self._draw5()
        st.sent += 1
        if u_loss < imp.loss:
            st.lost += 1
            return
        arrival = step + self._delay_steps + int(u_jitter * (self._jitter_steps + 1))
        if u_reorder < imp.reorder:
            arrival += 1 + int(u_hold * imp.reorder_max_steps)
            st.reordered += 1
        st.delayed += arrival > step
        self._pending.setdefault(arrival, []).append((step, item))
        if u_dup < imp.duplicate:
            self._pending.setdefault(arrival + 1, []).append((step, item))
            st.duplicated += 1

    def deliver(self, step: int) -> list[tuple[int, T]]:
        """Arrivals at ``step`` as ``(sent step, item)``, in arrival order; call once per step."""
        if step <= self._now:
            raise ValueError(f"deliver({step}) after deliver({self._now}): one call per step, in order")
        pending = self._pending
        if len(pending) == 1 and step in pending:  # the usual case: this step's arrivals alone
            out = pending.pop(step)
        else:
            due = [s for s in pending if s <= step]  # steps skipped by the caller deliver late, not never
            out = []
            for s in sorted(due):
                out.extend(pending.pop(s))
        self._now = step
        self.stats.delivered += len(out)
        return out

    @property
    def in_flight(self) -> int:
        return sum(len(v) for v in self._pending.values())


class ZeroOrderHold(Generic[T]):
    """A flight controller's command register: the newest step it has seen, held until replaced."""

    def __init__(self) -> None:
        self.step = -1  # step of the held command (-1: none yet)
        self.command: T | None = None
        self.stale = 0  # arrivals older than (or as old as) the held command, ignored

    def update(self, arrivals: list[tuple[int, T]]) -> T | None:
        for sent_step, item in arrivals:
            if sent_step > self.step:
                self.step, self.command = sent_step, item
            else:
                self.stale += 1
        return self.command


@dataclass
class ImpairedLink(Generic[T]):
    """Channel + zero-order hold of one vehicle: ``step(k, setpoint) -> command applied at k``."""

    impairment: LinkImpairment
    stream: int = 0
    channel: ImpairedChannel[T] = field(init=False)
    hold: ZeroOrderHold[T] = field(init=False)

    def __post_init__(self) -> None:
        self.channel = ImpairedChannel(self.impairment, self.impairment.rng(self.stream))
        self.hold = ZeroOrderHold()

    last_arrival: int = field(init=False, default=-1)  # step of the last arrival (-1: none yet)

    def step(self, step: int, setpoint: T | None) -> T | None:
        """Send ``setpoint`` (None: nothing computed this step) and return the command held at ``step``."""
        if setpoint is not None:
            self.channel.send(step, setpoint)
        arrivals = self.channel.deliver(step)
        if arrivals:
            self.last_arrival = step
        return self.hold.update(arrivals)

    def silent_for(self, step: int) -> int:
        """Steps since the last arrival at ``step`` (0 before the first: nothing to miss yet)."""
        return 0 if self.last_arrival < 0 else step - self.last_arrival
