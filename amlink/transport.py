"""Byte transports of a MAVLink link, one interface for UDP, TCP and serial.

:func:`open_transport` opens what an :class:`amlink.endpoint.Endpoint` names and returns
an object with

* ``recv(timeout_s) -> [(data, addr)]`` -- waits up to ``timeout_s`` for input and
  returns what is there: ``data`` is one datagram (UDP) or the whole frames a stream
  delivered (TCP, serial; cut by :class:`amlink.wire.StreamFramer`), ``addr`` the far
  end: a ``(host, port)`` tuple for UDP, a :class:`StreamPeer` for a stream connection;
* ``send(addr, data)`` -- never blocks.  A stream that cannot take the data now keeps it
  and writes it when it can, whole frames in order; past ``MAX_BACKLOG`` bytes, or with
  no connection to ``addr``, the data is dropped and counted (``send_drops``);
* ``peer`` -- where a client sends: the udpout destination, a stream's far end once
  connected, ``None`` while unknown (udpin until the far end speaks; tcp before it
  connects); ``peers()``: every far end connected now (a listening TCP endpoint's all);
* ``stream``; ``fds()``, ``wfds()`` and ``poll(readable, writable)`` for :class:`Mux`;
  ``close()``.

UDP is :class:`Udp`, the lockstep's fast path (one ``select``, then drain); TCP and serial
ports are in :mod:`amlink.stream`.  ``Udp.send`` and ``Udp.recv`` are the only places a
datagram leaves and enters a process.  ``Udp.send`` passes every datagram through an optional
*send shim* (``shim(addr, data) -> [(addr, data), ...]``, e.g. :class:`amlink.shim.LossyShim`)
that may drop, duplicate or hold it back: how the tests impair the real socket path.
"""

from __future__ import annotations

import select
import socket
import time
from collections.abc import Callable, Iterable, Sequence

from amlink.endpoint import SERIAL, TCP_IN, TCP_OUT, UDP_IN, UDP_OUT, Endpoint, listen_address
from amlink.stream import MAX_BACKLOG, SerialPort, StreamPeer, TcpClient, TcpServer, resolve  # noqa: F401
from amlink.protocol import LinkStats

_MAX_DATAGRAM = 65535
_MAX_DRAIN = 256  # datagrams read per wake-up before checking the clock again
_DONTWAIT = getattr(socket, "MSG_DONTWAIT", None)
_ROUTES_MAX = 4096  # Mux: addresses remembered (datagrams from many ports cannot grow it without bound)


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



def udp_socket(host: str, port: int, bind: bool) -> tuple[socket.socket, tuple]:
    """A UDP socket of the family of ``host`` and the address it resolves to; bound to it
    (listen) or to a free port (send). OSError (socket.gaierror: a host that does not resolve)
    if it cannot be."""
    family, kind, proto, _, addr = resolve(host, port, socket.SOCK_DGRAM)
    sock = socket.socket(family, kind, proto)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        sock.bind(addr if bind else (("::", 0) if family == socket.AF_INET6 else ("0.0.0.0", 0)))
    except OSError:
        sock.close()
        raise
    return sock, addr


class UdpListener:
    """A device's server end on one bound, non-blocking UDP socket (the simulator's motion
    capture stream and Net F/T): `open` binds ``endpoint`` (``udpin:HOST:PORT``; port 0: a free
    one, see `address`), `close` closes it and calls `_forget`, `fds` is for a caller's select.
    ``name`` begins its errors."""

    def __init__(self, endpoint: str, name: str) -> None:
        self.endpoint, self._name, self._bind = endpoint, name, listen_address(endpoint, UDP_IN, name)
        self._sock: socket.socket | None = None

    def open(self) -> None:
        try:
            s, _ = udp_socket(*self._bind, bind=True)
        except OSError as e:
            raise OSError(e.errno, f"{self._name}: cannot bind {self.endpoint}: {e.strerror}") from None
        s.setblocking(False)
        self._sock = s

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
        self._sock = None
        self._forget()

    def _forget(self) -> None:
        """What a closed server forgets of its clients (a subclass's)."""

    @property
    def address(self) -> tuple[str, int] | None:
        return None if self._sock is None else self._sock.getsockname()[:2]

    def fds(self) -> list[int]:
        return [] if self._sock is None else [self._sock.fileno()]


def open_transport(endpoint: Endpoint, stats: LinkStats, *, shim: Shim | None = None, client: bool = False):
    """Open ``endpoint``.  OSError if it cannot be (a port in use, no such device).

    ``client``: the companion's end, which talks to one flight controller (a listening
    TCP endpoint keeps only its newest connection).  A TCP client is not connected yet
    when this returns; it connects while ``recv`` waits."""
    kind = endpoint.kind
    if kind in (UDP_IN, UDP_OUT):
        sock, addr = udp_socket(endpoint.host, endpoint.port, bind=kind == UDP_IN)
        return Udp(sock, stats, shim, peer=addr if kind == UDP_OUT else None)
    if kind == TCP_IN:
        family, kind_, proto, _, addr = resolve(endpoint.host, endpoint.port, socket.SOCK_STREAM)
        sock = socket.socket(family, kind_, proto)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(addr)
            sock.listen(16)
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        return TcpServer(sock, stats, newest_only=client)
    if kind == TCP_OUT:
        return TcpClient(endpoint, stats)
    if kind == SERIAL:
        port = SerialPort(endpoint, stats)
        port.open()
        return port
    raise ValueError(f"unknown endpoint kind {kind!r}")  # pragma: no cover - Endpoint guards it


class Mux:
    """Several transports behind one ``recv``/``send`` (the simulator's ``--bind`` list).

    ``send(addr, ...)`` goes out through the transport that ``addr`` last came in on (or
    was registered with :meth:`route`).  With one transport, both calls go straight to
    it: the UDP lockstep path is unchanged."""

    def __init__(self, transports: Sequence) -> None:
        self.transports = list(transports)
        self._single = self.transports[0] if len(self.transports) == 1 else None
        self._owner: dict[object, object] = {}

    def route(self, addr, transport) -> None:
        self._owner[addr] = transport

    def recv(self, timeout_s: float) -> list[tuple[bytes, object]]:
        if self._single is not None:
            return self._single.recv(timeout_s)
        r: list[int] = []
        w: list[int] = []
        wake = None
        for t in self.transports:
            r += t.fds()
            w += t.wfds()
            wt = getattr(t, "wakeup_s", None)
            if wt is not None:
                wake = wt if wake is None else min(wake, wt)
        timeout = max(0.0, timeout_s)
        if wake is not None:
            timeout = min(timeout, max(0.0, wake - time.monotonic()))
        ready_r, ready_w, _ = select.select(r, w, [], timeout)
        readable, writable = set(ready_r), set(ready_w)
        out: list[tuple[bytes, object]] = []
        for t in self.transports:
            got = t.poll(readable, writable)
            if got:
                owner = self._owner
                for _, addr in got:  # most recently heard last: a flood of other addresses evicts them first
                    owner.pop(addr, None)
                    owner[addr] = t
                while len(owner) > _ROUTES_MAX:
                    del owner[next(iter(owner))]
                out += got
        return out

    def send(self, addr, data: bytes) -> None:
        t = self._single or self._owner.get(addr)
        if t is None:
            self.transports[0].stats.send_drops += 1
            return
        t.send(addr, data)

    @property
    def stats(self) -> LinkStats:
        return self.transports[0].stats

    def close(self) -> None:
        for t in self.transports:
            t.close()


def close_all(transports: Iterable) -> None:
    for t in transports:
        try:
            t.close()
        except OSError:
            pass
