"""Typed errors of the lockstep link (codec errors live in :mod:`amlink.codec`)."""

from __future__ import annotations

from collections.abc import Iterable


class LinkError(Exception):
    """Base class of lockstep link errors."""


class PeerMissingError(LinkError):
    """Simulator side: configured companions did not show up (or arm) in time."""

    def __init__(self, sysids: Iterable[int], timeout_s: float, waiting_for: str = "HEARTBEAT"):
        self.sysids = tuple(sorted(sysids))
        self.timeout_s = timeout_s
        self.waiting_for = waiting_for
        names = ", ".join(f"sysid {s}" for s in self.sysids)
        super().__init__(f"no {waiting_for} from {names} within {timeout_s:.3g} s")


class PeerTimeoutError(LinkError):
    """Simulator side: a companion did not answer step ``step`` in time.

    ``sysid`` is the lowest silent sysid; ``missing`` lists all of them.
    """

    def __init__(self, sysid: int, step: int, timeout_s: float = float("nan"), missing: Iterable[int] = ()):
        self.sysid = sysid
        self.step = step
        self.timeout_s = timeout_s
        self.missing = tuple(missing) or (sysid,)
        super().__init__(
            f"sysid {sysid} did not answer step {step} within {timeout_s:.3g} s"
            f" (silent: {', '.join(map(str, self.missing))})"
        )


class PeerProtocolError(LinkError):
    """A known companion sent an invalid setpoint (e.g. NaN torque).

    No longer raised by :meth:`SimServer.exchange`, which now drops and counts
    such setpoints (``LinkStats.rejected_setpoints``; reason in
    ``SimServer.last_rejection``); kept for callers that want to raise it.
    """

    def __init__(self, sysid: int, reason: str):
        self.sysid = sysid
        self.reason = reason
        super().__init__(f"sysid {sysid}: {reason}")


class SimulatorUnreachableError(LinkError):
    """Companion side: no AM_SCENARIO from the simulator at ``address`` in time."""

    def __init__(self, address: str, timeout_s: float, detail: str = "", listening: bool = False):
        self.address = address
        self.timeout_s = timeout_s
        self.listening = listening  # the companion waited on a listening endpoint and nobody came
        msg = (f"no simulator reached {address} within {timeout_s:.3g} s" if listening
               else f"simulator at {address} did not answer HEARTBEAT within {timeout_s:.3g} s")
        super().__init__(f"{msg}: {detail}" if detail else msg)


class SimulatorTimeoutError(LinkError):
    """Companion side: the simulator went quiet while we waited for ``waiting_for``."""

    def __init__(self, waiting_for: str, timeout_s: float):
        self.waiting_for = waiting_for
        self.timeout_s = timeout_s
        super().__init__(f"no {waiting_for} from the simulator within {timeout_s:.3g} s")


class CommandRejectedError(LinkError):
    """Companion side: a COMMAND_LONG was answered with a result other than ACCEPTED."""

    def __init__(self, command: int, result: int):
        self.command = command
        self.result = result
        super().__init__(f"command {command} rejected with MAV_RESULT {result}")
