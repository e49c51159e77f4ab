"""The lockstep schedule: what each physics step k does with the companions, for every runner.

One `Lockstep` drives a `SitlCore` through a run; a runner supplies only how frames reach the
companions and their setpoints come back (a `Transport`: the UDP simulator's `ServerTransport`
over `amlink.server.SimServer`, or `sitl.inprocess`'s companions called in-process). Each step:

    control step, no actuation delay (or the first control step):
        exchange step k's frames (each sent as soon as it is read; each accepted setpoint
        applied as it arrives, `SitlCore.on_setpoint`); the refusals noted
        (`SitlCore.note_rejected`); the flight controllers actuate what came (`actuate`)
    control step, [flight_controller].actuation_delay_steps d > 0:
        read step k's frames; what is due (the answers to step k - d's frames) acts first,
        then the frames go out and physics steps on while the companions compute
    other steps:
        the flight controllers fly on what they hold (`hold`), or on the answers that fall
        due at this step
    then physics steps (`SitlCore.step`).

Who is lost is read from the transport after the answers due are collected (as of its last
exchange or collection): a lost companion's vehicle flies its failsafe until it answers again.
Runners get two hooks: `meanwhile(k)`, work that need not delay the companions (the UDP
simulator's GCS link: after the frames are out, or after a hold step), and `after_step(k)`
(progress). The state digest depends only on this schedule and what the transport delivers:
with an ideal link the UDP simulator and the in-process runner give the same one.
"""
from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Mapping
from typing import NamedTuple, Protocol

from amlink.types import SensorFrame

from .core import Setpoint, SitlCore


class Answers(NamedTuple):
    """The setpoints that answered one batch of frames, and the refused ones as (sysid, why) in
    the frames' sysid order (each answered its step: its flight controller holds its last command)."""
    setpoints: dict[int, Setpoint]
    rejected: tuple[tuple[int, str], ...] = ()


class Transport(Protocol):
    """How frames reach the companions and their setpoints come back."""

    @property
    def lost(self) -> Collection[int]:
        """Sysids whose companion is silent, as of the last exchange or collection."""

    def exchange(self, frames: Iterable[tuple[int, SensorFrame]], while_waiting: Callable[[], None],
                 on_setpoint: Callable[[int, Setpoint], None]) -> Answers:
        """Send each frame (as `frames` yields it), call `while_waiting` once they are out, and
        return the answers; `on_setpoint(sysid, sp)` may be called for each as it arrives."""

    def send(self, frames: Mapping[int, SensorFrame]) -> None:
        """Send the frames and return at once; `collect` later takes their answers."""

    def collect(self) -> Answers:
        """The answers to the last `send`."""


class Lockstep:
    """The schedule above over `core` and `transport`. `k`: the step being run (after `run`, the
    number of steps run), so that a runner interrupted mid-run can say how far it came."""

    def __init__(self, core: SitlCore, transport: Transport, meanwhile: Callable[[int], None] | None = None,
                 after_step: Callable[[int], None] | None = None) -> None:
        self.core, self.transport = core, transport
        self.meanwhile, self.after_step = meanwhile, after_step
        self.k = 0

    def run(self, n_steps: int) -> None:
        for k in range(n_steps):
            self.k = k
            self.step(k)
        self.k = n_steps

    def step(self, k: int) -> None:
        core, link = self.core, self.transport
        if core.is_control_step(k) and (k == 0 or core.actuation_delay == 0):
            answers = link.exchange(core.iter_frames(k), lambda: self._meanwhile(k), core.on_setpoint)
            core.actuate(k, self._noted(answers), link.lost)
        elif core.is_control_step(k):  # the frames' answers act d steps later (core.due)
            frames = core.frames(k)
            setpoints = self._noted(link.collect()) if core.due(k) else {}  # due here when d is the control period
            core.actuate(k, setpoints, link.lost)
            link.send(frames)
            self._meanwhile(k)
        else:  # between control steps the flight controllers fly on their own
            setpoints = self._noted(link.collect()) if core.due(k) else None  # (before reading who is lost)
            core.hold(k, link.lost, setpoints)
            self._meanwhile(k)
        core.step()
        if self.after_step is not None:
            self.after_step(k)

    def _noted(self, answers: Answers) -> dict[int, Setpoint]:
        """The setpoints of `answers`, its refusals told to the core first (hold, count, failsafe after K)."""
        for sysid, why in answers.rejected:
            self.core.note_rejected(sysid, why)
        return answers.setpoints

    def _meanwhile(self, k: int) -> None:
        self.core.observe()  # the digest and ground truth of the frames just sent
        if self.meanwhile is not None:
            self.meanwhile(k)


class ServerTransport:
    """`Transport` over the UDP (TCP, serial) lockstep link, `amlink.server.SimServer`: partial
    exchanges, so that a silent companion is marked lost and not waited for again."""

    def __init__(self, server) -> None:
        self.server = server

    @property
    def lost(self) -> Collection[int]:
        return self.server.lost_peers

    def exchange(self, frames, while_waiting, on_setpoint) -> Answers:
        setpoints = self.server.exchange(frames, partial=True, while_waiting=while_waiting, on_setpoint=on_setpoint)
        return Answers(setpoints, self.server.last_rejected)

    def send(self, frames) -> None:
        self.server.send_frames(frames, partial=True)

    def collect(self) -> Answers:
        setpoints = self.server.collect(partial=True)
        return Answers(setpoints, self.server.last_rejected)
