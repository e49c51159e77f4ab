"""Between the lockstep loop and the GCS link (no I/O of its own).

Every ``every`` steps (:meth:`GcsSession.tick`), the flight controllers' snapshot goes to
the link (:mod:`simulator.gcs_link`, which sends it from its own thread), each change worth
telling (failsafe, landing, arming, the mission phase) goes out as STATUSTEXT, and the
commands the GCS sent since are executed (:mod:`simulator.commands`) and answered.
:meth:`GcsSession.verdict` is the one place the run's end is announced.
"""
from __future__ import annotations

from collections.abc import Callable

from amlink.codec import mav

from . import commands, gcs_messages
from .core import SitlCore
from .fcstate import FleetSnapshot
from .gcs_link import GcsLink

SNAPSHOT_HZ = 50.0  # snapshots per simulated second (the link sends at most 25 Hz of wall time)


def snapshot_every(rate_hz: float) -> int:
    """Steps between snapshots at lockstep rate ``rate_hz``."""
    return max(1, round(rate_hz / SNAPSHOT_HZ))


class GcsSession:
    def __init__(self, core: SitlCore, link: GcsLink, armed: Callable[[int], bool], every: int) -> None:
        self.core, self.link, self.armed, self.every = core, link, armed, every
        self._last: FleetSnapshot | None = None

    def snapshot(self) -> FleetSnapshot:
        return self.core.snapshot({s: self.armed(s) for s in self.core.sysids})

    def open(self) -> None:
        """Open the link, which says HEARTBEAT from the flight controllers' state now.
        OSError if its endpoint cannot be opened."""
        self._last = self.snapshot()
        self.link.open(self._last)

    def tick(self, k: int) -> None:
        """At step ``k`` (its frames read and sent, its setpoints not yet applied): an update
        every ``every`` steps.  Commands then act from step ``k`` on."""
        if k % self.every == 0:
            self.update()

    def update(self, execute: bool = True) -> None:
        """Snapshot and STATUSTEXTs to the link; then (``execute``) the GCS's commands."""
        snap = self.snapshot()
        for sysid, severity, text in gcs_messages.status_changes(self._last, snap):
            self.link.statustext(sysid, severity, text)
        self._last = snap
        self.link.publish(snap)
        if not execute:
            return
        for cmd in self.link.commands():
            answers, news = commands.execute(self.core, cmd)
            for a in answers:
                self.link.acknowledge(cmd, a.sysid, a.result)
                if a.text:
                    self.link.statustext(a.sysid, mav.MAV_SEVERITY_WARNING, a.text)
            if news:
                self.link.announce(news, mav.MAV_SEVERITY_WARNING)

    def verdict(self, text: str, ok: bool) -> None:
        """The end of the run, from every vehicle: called once, with the run's verdict.
        Commands still queued are not executed: the run is over."""
        self.update(execute=False)
        self.link.announce(text, mav.MAV_SEVERITY_NOTICE if ok else mav.MAV_SEVERITY_ERROR)
