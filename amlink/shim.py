"""A seeded lossy / duplicating / reordering send shim for :class:`amlink.transport.Udp` (no I/O).

``Udp(sock, stats, shim=LossyShim(...))`` passes every outgoing datagram through
the shim, which returns what really goes out now.  It exists to test that the
lockstep survives real packet loss (retransmission); it impairs wall-clock
delivery on the sockets.  For impairment of *control* in simulation time see
:mod:`amlink.impair`.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field

Datagram = tuple[tuple[str, int], bytes]


@dataclass
class LossyShim:
    """Drop, duplicate and reorder datagrams, deterministically from ``seed``.

    Per datagram, in this order: lost with probability ``loss``; else held back
    with probability ``reorder`` (released right after the next datagram that goes
    out, so the two swap; at most one is held); else sent, and sent a second time
    with probability ``duplicate``.  Counters say what happened.
    """

    loss: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    seed: int = 0
    dropped: int = 0
    duplicated: int = 0
    reordered: int = 0
    _rng: random.Random = field(init=False, repr=False)
    _held: Datagram | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        for name in ("loss", "duplicate", "reorder"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"LossyShim.{name} must be a probability, got {getattr(self, name)}")
        self._rng = random.Random(self.seed)

    def __call__(self, addr: tuple[str, int], data: bytes) -> list[Datagram]:
        r = self._rng.random
        u_loss, u_reorder, u_dup = r(), r(), r()  # fixed draws per datagram: same seed, same schedule
        if u_loss < self.loss:
            self.dropped += 1
            return []
        if u_reorder < self.reorder and self._held is None:
            self._held = (addr, data)
            self.reordered += 1
            return []
        out = [(addr, data)]
        if u_dup < self.duplicate:
            out.append((addr, data))
            self.duplicated += 1
        if self._held is not None:
            out.append(self._held)
            self._held = None
        return out
