"""UDP plumbing shared by both ends of the lockstep link: ids, timing constants, counters.

``Udp.send`` and ``Udp.recv`` are the only places datagrams leave and enter a
process.  ``Udp.send`` passes every datagram through an optional *send shim*
(``shim(addr, data) -> [(addr, data), ...]``, e.g. :class:`amlink.shim.LossyShim`)
that may drop, duplicate or hold it back -- how the tests impair the real socket
path.
"""

from __future__ import annotations

import select
import socket
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from amlink.codec import mav

SIM_SYSID = 1
SIM_COMPID = mav.MAV_COMP_ID_AUTOPILOT1
COMPANION_COMPID = mav.MAV_COMP_ID_ONBOARD_COMPUTER
HEARTBEAT_PERIOD_S = 0.5  # the companion's HEARTBEAT while it connects [s]
RUN_HEARTBEAT_PERIOD_S = 1.0  # ... and once connected, as a companion computer does [s]
COMMAND_RETRY_S = 0.25
SENSOR_RETRY_S = 0.025  # first re-send of an unanswered sensor batch [s wall]; doubles up to 4x
REJOIN_QUIET_S = 1.0  # signing off: a HEARTBEAT moves a peer only after this long silent [s]
SHUTDOWN_COPIES = 3  # the last datagram of a run is sent this many times (loss)
STATUSTEXT_MAX = 50  # bytes in STATUSTEXT.text
# While the simulator gathers its companions (HEARTBEAT, then ARM from every sysid), it tells
# those already there whom it waits for, every WAITING_NOTICE_PERIOD_S, in a STATUSTEXT that
# begins with WAITING_NOTICE_PREFIX; a companion waits for its first frame as long as these come.
WAITING_NOTICE_PERIOD_S = 2.0
WAITING_NOTICE_PREFIX = "waiting "
_MAX_DATAGRAM = 65535
_MAX_DRAIN = 256  # datagrams read per wake-up before checking the clock again
_DONTWAIT = getattr(socket, "MSG_DONTWAIT", None)


@dataclass
class LinkStats:
    """Counters of one endpoint (MAVLink packets unless noted)."""

    datagrams_rx: int = 0
    datagrams_tx: int = 0
    bad_frames: int = 0  # CRC errors, unknown message ids, truncated frames, junk
    unknown_sysid: int = 0  # packets from a sysid we do not talk to
    stale_setpoints: int = 0  # setpoint for a step older than the one awaited
    duplicate_setpoints: int = 0  # second setpoint for the awaited step
    wrong_step_setpoints: int = 0  # setpoint for a step not yet sent
    ignored: int = 0  # valid packets of types this endpoint does not use
    # bad values (amlink.limits): counted, never returned or applied
    rejected_setpoints: int = 0  # server: non-finite, out of range or wrong joint count
    rejected_frames: int = 0  # companion: sensor batch / AM_SCENARIO invalid, wrong scenario_id
    nonfinite_values: int = 0  # of the two above, those rejected for a NaN or infinity
    # signing on (amlink.wire.Decoder)
    unsigned: int = 0  # unsigned packets
    bad_signature: int = 0  # signed with another key, or altered after signing
    replayed: int = 0  # not newer than its stream's last authentic packet (checked before the signature)
    # addresses and peers
    wrong_address: int = 0  # signing off: a known sysid from an address other than its peer's
    address_changes: int = 0  # server: a peer moved to a new address (rejoin or NAT rebinding)
    rejoins: int = 0  # server: HEARTBEAT from a known peer at a new address
    peers_lost: int = 0  # server, exchange(partial=True): a peer missed a step and was marked lost
    # loss recovery
    retransmits: int = 0  # server: batches re-sent; companion: cached setpoints re-sent
    duplicate_frames: int = 0  # companion: sensor frames for a step already seen
    skipped_frames: int = 0  # companion: frames passed over for a newer one already queued (a backlog)
    # byte streams (TCP, serial) and sending
    junk_bytes: int = 0  # stream bytes skipped while finding the next whole frame (noise, a cut-off frame)
    send_drops: int = 0  # datagrams not sent: no route to the address, or a stream's backlog full or closed


Shim = Callable[[tuple[str, int], bytes], Iterable[tuple[tuple[str, int], bytes]]]


class Udp:
    """One UDP socket; ``send`` and ``recv`` are the only I/O paths (``shim``: impairment hook).

    The transport interface of :mod:`amlink.transport`; ``peer`` is where a client sends
    (the udpout destination; ``None`` on a listening socket until the caller learns it).
    """

    stream = False

    def __init__(self, sock: socket.socket, stats: LinkStats, shim: Shim | None = None,
                 peer: tuple | None = None) -> None:  # fmt: skip
        self.sock = sock
        self.stats = stats
        self.shim = shim
        self.peer = peer

    @property
    def local_address(self) -> tuple:
        return self.sock.getsockname()

    def peers(self) -> list:
        """The far ends known to this transport (the udpout destination)."""
        return [self.peer] if self.peer is not None else []

    def send(self, addr: tuple, data: bytes) -> None:
        try:
            if self.shim is None:
                self.sock.sendto(data, addr)
                self.stats.datagrams_tx += 1
                return
            for a, d in self.shim(addr, data):
                self.sock.sendto(d, a)
                self.stats.datagrams_tx += 1
        except (BlockingIOError, ConnectionRefusedError):  # a full buffer, an ICMP error of an earlier datagram
            self.stats.send_drops += 1

    def recv(self, timeout_s: float) -> list[tuple[bytes, tuple]]:
        """Datagrams available within ``timeout_s`` (waits for the first, drains the rest)."""
        ready, _, _ = select.select([self.sock], [], [], max(0.0, timeout_s))
        return self._drain() if ready else []

    def fds(self) -> list[int]:
        return [self.sock.fileno()]

    def wfds(self) -> list[int]:
        return []

    def poll(self, readable, writable) -> list[tuple[bytes, tuple]]:
        """What :meth:`recv` returns, without waiting, when the socket is in ``readable``."""
        return self._drain() if self.sock.fileno() in readable else []

    def _drain(self) -> list[tuple[bytes, tuple]]:
        out: list[tuple[bytes, tuple]] = []
        for i in range(_MAX_DRAIN):
            try:
                if i == 0:
                    data, addr = self.sock.recvfrom(_MAX_DATAGRAM)
                elif _DONTWAIT is None:
                    break
                else:
                    data, addr = self.sock.recvfrom(_MAX_DATAGRAM, _DONTWAIT)
            except BlockingIOError:
                break
            except ConnectionRefusedError:  # Linux: ICMP port unreachable of an earlier datagram
                continue
            except ConnectionResetError:  # Windows reports ICMP port unreachable here
                continue
            out.append((data, addr))
        self.stats.datagrams_rx += len(out)
        return out

    def close(self) -> None:
        self.sock.close()
