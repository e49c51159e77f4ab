"""Byte-stream transports of a MAVLink link: TCP (client and listening) and serial ports.

Each has the interface :mod:`amlink.transport` describes.  Bytes are cut back into whole
frames (:class:`amlink.wire.StreamFramer`); writes never block: a stream that cannot take
the data now keeps it, whole frames in order, and past ``MAX_BACKLOG`` bytes drops and
counts it.  A TCP client connects without blocking and retries every ``RECONNECT_S``; a
listening TCP endpoint serves any number of connections (a client end keeps the newest);
a serial port that fails (unplugged, the far end of a pty gone) is reopened every
``RECONNECT_S``.
"""

from __future__ import annotations

import errno
import os
import select
import socket
import time

from amlink.endpoint import Endpoint
from amlink.protocol import LinkStats
from amlink.wire import StreamFramer

MAX_BACKLOG = 1 << 20  # bytes a stream keeps for a far end that does not read [B]
RECONNECT_S = 0.5  # a TCP client or a failed serial port tries again after this long [s]
_READ_SIZE = 1 << 16


def resolve(host: str, port: int, kind: int) -> tuple:
    """``(family, type, proto, canonname, sockaddr)`` of ``host``, IPv4 first as mavutil (a name
    such as localhost may resolve to ::1 too; an IPv6 literal resolves to IPv6 only)."""
    infos = socket.getaddrinfo(host, port, type=kind)
    return next((i for i in infos if i[0] == socket.AF_INET), infos[0])


class StreamPeer:
    """The far end of one stream connection; a ``send`` address, compared by identity."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return f"StreamPeer({self.name})"


class _Stream:
    """One open byte stream (a connected socket or a serial fd): whole frames in, no blocking out."""

    def __init__(self, fd: int, peer: StreamPeer, stats: LinkStats, read, write, close) -> None:
        self.fd, self.peer, self.stats = fd, peer, stats
        self._read, self._write, self._close = read, write, close
        self._framer = StreamFramer()
        self._out = bytearray()
        self.closed = False

    @property
    def pending(self) -> bool:
        return bool(self._out)

    def read(self) -> bytes:
        """The whole frames that the bytes now readable complete (b"" if none)."""
        try:
            chunk = self._read(_READ_SIZE)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:  # reset, EIO of a serial port whose far end went away
            chunk = b""
        if not chunk:
            self.close()
            return b""
        junk = self._framer.junk_bytes
        frames = self._framer.feed(chunk)
        self.stats.junk_bytes += self._framer.junk_bytes - junk
        return frames

    def write(self, data: bytes) -> None:
        if self.closed or len(self._out) + len(data) > MAX_BACKLOG:
            self.stats.send_drops += 1
            return
        self._out += data
        self.stats.datagrams_tx += 1
        self.flush()

    def flush(self) -> None:
        while self._out:
            try:
                n = self._write(self._out)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self.close()
                return
            if n <= 0:
                return
            del self._out[:n]

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            self._out.clear()
            try:
                self._close()
            except OSError:
                pass


def _socket_stream(sock: socket.socket, stats: LinkStats) -> _Stream:
    sock.setblocking(False)
    if sock.family in (socket.AF_INET, socket.AF_INET6):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # a lockstep answer must not wait
    try:
        far = sock.getpeername()
    except OSError:
        far = None
    name = f"tcp:{far[0]}:{far[1]}" if isinstance(far, tuple) else "stream"
    return _Stream(sock.fileno(), StreamPeer(name), stats, sock.recv, sock.send, sock.close)


class _Waiting:
    """``recv`` from ``fds``/``wfds``/``poll``; ``wakeup_s`` bounds the wait for a retry timer."""

    stream = True
    wakeup_s: float | None = None

    def recv(self, timeout_s: float) -> list[tuple[bytes, object]]:
        r, w = self.fds(), self.wfds()
        t = max(0.0, timeout_s)
        if self.wakeup_s is not None:
            t = min(t, max(0.0, self.wakeup_s - time.monotonic()))
        if r or w:
            ready_r, ready_w, _ = select.select(r, w, [], t)
        else:
            time.sleep(t)
            ready_r = ready_w = []
        return self.poll(set(ready_r), set(ready_w))

    def _poll_conn(self, readable, writable) -> list[tuple[bytes, object]]:
        """One connected stream (``self._conn``): flush, read, and after a close retry in
        RECONNECT_S (the client and the serial port alike)."""
        conn = self._conn
        if conn is None:
            return []
        if conn.fd in writable:
            conn.flush()
        out = []
        if conn.fd in readable:
            data = conn.read()
            if data:
                self.stats.datagrams_rx += 1
                out.append((data, conn.peer))
        if conn.closed:
            self._conn, self.wakeup_s = None, time.monotonic() + RECONNECT_S
        return out


class TcpServer(_Waiting):
    """A listening TCP socket and its connections (``newest_only``: a client end keeps one)."""

    def __init__(self, listener: socket.socket, stats: LinkStats, newest_only: bool = False) -> None:
        self._listener, self.stats, self._newest_only = listener, stats, newest_only
        self._conns: dict[StreamPeer, _Stream] = {}

    @property
    def local_address(self) -> tuple:
        return self._listener.getsockname()

    @property
    def peer(self) -> StreamPeer | None:
        return next(reversed(self._conns), None) if self._conns else None

    def peers(self) -> list[StreamPeer]:
        return list(self._conns)

    def fds(self) -> list[int]:
        return [self._listener.fileno(), *(c.fd for c in self._conns.values())]

    def wfds(self) -> list[int]:
        return [c.fd for c in self._conns.values() if c.pending]

    def poll(self, readable, writable) -> list[tuple[bytes, object]]:
        if self._listener.fileno() in readable:
            self._accept()
        out = []
        for c in list(self._conns.values()):
            if c.fd in writable:
                c.flush()
            if c.fd in readable and not c.closed:
                data = c.read()
                if data:
                    self.stats.datagrams_rx += 1
                    out.append((data, c.peer))
            if c.closed:
                del self._conns[c.peer]
        return out

    def _accept(self) -> None:
        while True:
            try:
                sock, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # e.g. out of file descriptors: try again on the next wake-up
                return
            conn = _socket_stream(sock, self.stats)
            if self._newest_only:
                for old in self._conns.values():
                    old.close()
                self._conns.clear()
            self._conns[conn.peer] = conn

    def send(self, addr, data: bytes) -> None:
        conn = self._conns.get(addr)
        if conn is None:
            self.stats.send_drops += 1
            return
        conn.write(data)

    def close(self) -> None:
        for c in self._conns.values():
            c.close()
        self._conns.clear()
        self._listener.close()


class TcpClient(_Waiting):
    """A TCP connection to ``address``, made without blocking and remade when it breaks."""

    def __init__(self, endpoint: Endpoint, stats: LinkStats) -> None:
        self.endpoint, self.stats = endpoint, stats
        self._conn: _Stream | None = None
        self._connecting: socket.socket | None = None
        self.wakeup_s: float | None = 0.0  # when to try connecting next (None: connected or trying)
        self.last_error = ""

    @property
    def peer(self) -> StreamPeer | None:
        return self._conn.peer if self._conn is not None else None

    def peers(self) -> list[StreamPeer]:
        return [self._conn.peer] if self._conn is not None else []

    def _attempt(self) -> None:
        if self._conn is not None or self._connecting is not None or time.monotonic() < (self.wakeup_s or 0.0):
            return
        try:
            family, kind, proto, _, addr = resolve(self.endpoint.host, self.endpoint.port, socket.SOCK_STREAM)
            sock = socket.socket(family, kind, proto)
        except OSError as exc:
            self._failed(None, exc)
            return
        sock.setblocking(False)
        err = sock.connect_ex(addr)
        if err in (0, errno.EINPROGRESS, errno.EWOULDBLOCK, errno.EALREADY):
            self._connecting, self.wakeup_s = sock, None
        else:
            self._failed(sock, OSError(err, os.strerror(err)))

    def _failed(self, sock: socket.socket | None, exc: OSError) -> None:
        if sock is not None:
            sock.close()
        self._connecting = None
        self.last_error = str(exc)
        self.wakeup_s = time.monotonic() + RECONNECT_S

    def fds(self) -> list[int]:
        self._attempt()
        return [self._conn.fd] if self._conn is not None else []

    def wfds(self) -> list[int]:
        if self._connecting is not None:
            return [self._connecting.fileno()]
        return [self._conn.fd] if self._conn is not None and self._conn.pending else []

    def poll(self, readable, writable) -> list[tuple[bytes, object]]:
        sock = self._connecting
        if sock is not None and sock.fileno() in writable:
            err = sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err:
                self._failed(sock, OSError(err, os.strerror(err)))
            else:
                self._connecting, self._conn = None, _socket_stream(sock, self.stats)
        return self._poll_conn(readable, writable)

    def send(self, addr, data: bytes) -> None:
        if self._conn is None or addr is not self._conn.peer:
            self.stats.send_drops += 1
            return
        self._conn.write(data)

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._connecting is not None:
            self._connecting.close()
            self._connecting = None


class SerialPort(_Waiting):
    """A serial device in raw mode (8N1, no flow control) at ``endpoint.baud``; POSIX only."""

    def __init__(self, endpoint: Endpoint, stats: LinkStats) -> None:
        self.endpoint, self.stats = endpoint, stats
        self._conn: _Stream | None = None
        self.wakeup_s: float | None = None
        self._peer = StreamPeer(endpoint.device)  # the same route across reopenings

    @property
    def peer(self) -> StreamPeer:
        return self._peer

    def peers(self) -> list[StreamPeer]:
        return [self._peer] if self._conn is not None else []

    def open(self) -> None:
        """Open and configure the device; OSError if it cannot be."""
        fd = os.open(self.endpoint.device, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            _configure_raw(fd, self.endpoint.baud)
        except BaseException:
            os.close(fd)
            raise
        self._conn = _Stream(fd, self._peer, self.stats, lambda n: os.read(fd, n), lambda b: os.write(fd, b),
                             lambda: os.close(fd))
        self.wakeup_s = None

    def fds(self) -> list[int]:
        if self._conn is None and time.monotonic() >= (self.wakeup_s or 0.0):
            try:
                self.open()
            except OSError:
                self.wakeup_s = time.monotonic() + RECONNECT_S
        return [self._conn.fd] if self._conn is not None else []

    def wfds(self) -> list[int]:
        return [self._conn.fd] if self._conn is not None and self._conn.pending else []

    def poll(self, readable, writable) -> list[tuple[bytes, object]]:
        return self._poll_conn(readable, writable)

    def send(self, addr, data: bytes) -> None:
        if self._conn is None:
            self.stats.send_drops += 1
            return
        self._conn.write(data)

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None


def _configure_raw(fd: int, baud: int) -> None:
    """Raw 8N1 without flow control at ``baud`` (what pyserial does, with termios)."""
    import termios

    speed = getattr(termios, f"B{baud}", None)
    if speed is None:
        raise OSError(errno.EINVAL, f"baud rate {baud} is not supported on this system")
    iflag, oflag, cflag, lflag, _, _, cc = termios.tcgetattr(fd)
    iflag &= ~(termios.IGNBRK | termios.BRKINT | termios.PARMRK | termios.ISTRIP | termios.INLCR | termios.IGNCR
               | termios.ICRNL | termios.IXON | termios.IXOFF | termios.IXANY)
    oflag &= ~termios.OPOST
    lflag &= ~(termios.ECHO | termios.ECHONL | termios.ICANON | termios.ISIG | termios.IEXTEN)
    cflag &= ~(termios.CSIZE | termios.PARENB | termios.CSTOPB | getattr(termios, "CRTSCTS", 0))
    cflag |= termios.CS8 | termios.CLOCAL | termios.CREAD
    cc[termios.VMIN], cc[termios.VTIME] = 0, 0
    termios.tcsetattr(fd, termios.TCSANOW, [iflag, oflag, cflag, lflag, speed, speed, cc])
