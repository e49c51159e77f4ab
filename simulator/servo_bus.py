"""One vehicle's arm as a DYNAMIXEL Protocol 2.0 servo bus: n emulated X-series servos
(`simulator.dxl_servo`; IDs 1..n, joint j -> ID j + 1) reached as the real bus is, over raw
bytes, by ROBOTIS's dynamixel-sdk or any Protocol 2.0 master.

Transports (both optional, both served at once, each its own parser):
- TCP: listens on ``tcpin:HOST:PORT`` (default 127.0.0.1:7200 + vehicle index,
  `amlink.dxl_protocol.servo_bus_port`); the stream carries the bus's bytes unchanged (what a
  serial-to-TCP bridge such as ser2net passes). One client at a time: while one is
  connected, a second connection is accepted and closed at once (it reads end-of-file);
  counted in `stats.refused_clients`.
- pty: `os.openpty()` in raw mode; `pty_link` (a path) becomes a symlink to its device
  (/dev/pts/N), which dynamixel-sdk's PortHandler opens as a serial port (the baud rate is
  ignored by a pty; use any the SDK accepts).

The runner drives it (all non-blocking, on the caller's thread):
  `open()`, then each physics step `tau = joint_torques_nm(q, qdot)` (what the servos apply),
  `observe(t_s, q, qdot, tau)` (what the next read returns), and `poll(now_s)` (answer every
  instruction packet that arrived); `close()`. `fds()` lists the descriptors to wait on.
A servo answers in the `poll` that reads its instruction: the bus's latency is the caller's
poll period (the servos' Return Delay Time is not emulated).
"""
from __future__ import annotations

import errno
import os
import socket
import tty
from dataclasses import dataclass, field

import numpy as np

from amcore.config import JointEffortSpec
from amlink import dxl_protocol as dxl
from amlink.endpoint import TCP_IN, listen_address

from .dxl_servo import BusPort, BusStats, DxlBus, XServo, servo_rng

_RECV = 1 << 16
_OUTBOX_MAX = 1 << 16  # bytes held for a reader that does not read; beyond, dropped (a bus loses them)


def default_endpoint(index: int) -> str:
    """The servo bus endpoint of vehicle `index` (0-based [[am]] order)."""
    return f"tcpin:127.0.0.1:{dxl.servo_bus_port(index)}"


@dataclass
class _Link:
    port: BusPort
    outbox: bytearray = field(default_factory=bytearray)


@dataclass
class ServoBusStats:
    clients: int = 0  # TCP clients accepted
    refused_clients: int = 0  # connections closed because one was already connected
    bytes_rx: int = 0
    bytes_tx: int = 0
    dropped_tx: int = 0  # answers nobody read (outbox full)


class ServoBus:
    """Vehicle's servo bus (module doc).

    n_joints: servos on the bus (IDs 1..n). q0_rad: the joints at power-up (the pose
    position mode holds; default zeros). torque_max_nm: each joint's torque limit, written as
    its Current Limit(38) = round(tau_max / (K_t x 2.69 mA)) (None: the model's initial
    value). model: the servos' `amlink.dxl_protocol.ServoModel` (XM540-W270: the project's
    torque constant). effort, noise_scale: Present Current's lag and noise ([devices.effort],
    [devices].scale). seed, sysid: the servos' generators. pty_link: a path for the pty's
    symlink (None: no pty). endpoint: ``tcpin:HOST:PORT`` (port 0: a free one, see
    `address`), or None for no TCP."""

    def __init__(self, n_joints: int, *, q0_rad=None, torque_max_nm=None, model: dxl.ServoModel = dxl.XM540_W270,
                 effort: JointEffortSpec = JointEffortSpec(), noise_scale: float = 1.0, seed: int = 0,
                 sysid: int = 1, pty_link: str | None = None,
                 endpoint: str | None = "tcpin:127.0.0.1:7200") -> None:
        if not 1 <= n_joints <= dxl.MAX_ID:
            raise ValueError(f"n_joints = {n_joints}: a bus holds 1..{dxl.MAX_ID} servos")
        q0 = np.zeros(n_joints) if q0_rad is None else np.asarray(q0_rad, dtype=float)
        if q0.shape != (n_joints,):
            raise ValueError(f"q0_rad has shape {q0.shape}, expected ({n_joints},)")
        limits: list[int | None] = [None] * n_joints
        if torque_max_nm is not None:
            t = np.asarray(torque_max_nm, dtype=float)
            if t.shape != (n_joints,) or not np.all(t > 0):
                raise ValueError(f"torque_max_nm must be {n_joints} positive values, got {torque_max_nm!r}")
            limits = [min(model.current_limit_max, int(round(x / model.nm_per_current_unit))) for x in t]
        if endpoint is not None:
            self._bind = listen_address(endpoint, TCP_IN, "servo bus")
        self.endpoint, self.pty_link = endpoint, pty_link
        self.model = model
        self.servos = [XServo(dxl.joint_id(j), model, float(q0[j]), limits[j], effort, noise_scale,
                              servo_rng(seed, sysid, dxl.joint_id(j))) for j in range(n_joints)]
        self.bus = DxlBus(self.servos)
        self.stats = ServoBusStats()
        self._listener: socket.socket | None = None
        self._client: socket.socket | None = None
        self._client_link: _Link | None = None
        self._master = self._slave = -1
        self._pty_link_made = False
        self._pty_path: str | None = None
        self._pty: _Link | None = None

    # -- transports ---------------------------------------------------------------------
    def open(self) -> None:
        """Listen on the TCP endpoint and/or create the pty; OSError names what failed."""
        try:
            if self.endpoint is not None:
                s = socket.socket(socket.AF_INET6 if ":" in self._bind[0] else socket.AF_INET, socket.SOCK_STREAM)
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    s.bind(self._bind)
                except OSError as e:
                    s.close()
                    raise OSError(e.errno, f"servo bus: cannot listen on {self.endpoint}: {e.strerror}") from None
                s.listen(1)
                s.setblocking(False)
                self._listener = s
            if self.pty_link is not None:
                self._open_pty()
        except BaseException:
            self.close()
            raise

    def _open_pty(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # raw before any client opens it: no echo, no line editing
        os.set_blocking(self._master, False)
        self._pty_path = os.ttyname(self._slave)
        link = self.pty_link
        if os.path.islink(link):
            os.unlink(link)
        elif os.path.exists(link):
            raise FileExistsError(f"servo bus: {link} exists and is not a symlink; not replacing it")
        os.symlink(self._pty_path, link)
        self._pty_link_made = True
        self._pty = _Link(BusPort(self.bus))

    def close(self) -> None:
        for s in (self._client, self._listener):
            if s is not None:
                s.close()
        self._client = self._listener = None
        self._client_link = None
        if self._pty_link_made:
            try:
                os.unlink(self.pty_link)
            except FileNotFoundError:
                pass
            self._pty_link_made = False
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1
        self._pty = None

    @property
    def address(self) -> tuple[str, int] | None:
        """The TCP address listened on (the port chosen when the endpoint's was 0)."""
        return None if self._listener is None else self._listener.getsockname()[:2]

    @property
    def pty_path(self) -> str | None:
        """The pty's device (/dev/pts/N); `pty_link` points to it."""
        return self._pty_path

    def fds(self) -> list[int]:
        """Descriptors with something for `poll` when readable."""
        out = [s.fileno() for s in (self._listener, self._client) if s is not None]
        return out + ([self._master] if self._master >= 0 else [])

    def poll(self, now_s: float, readable: set[int] | frozenset[int] | None = None) -> None:
        """Accept a client, read what arrived, answer it (never blocks). now_s: the caller's
        clock [s] (unused by the servos; they answer at once). readable: the descriptors of
        `fds()` a select() just found readable, so that one with nothing to read costs no
        system call (answers still queued are sent regardless); None: try every one."""
        if readable is None or (self._listener is not None and self._listener.fileno() in readable):
            self._accept()
        if self._client is not None and (readable is None or self._client_link.outbox
                                         or self._client.fileno() in readable):
            self._serve_client()
        if self._pty is not None and (readable is None or self._pty.outbox or self._master in readable):
            self._serve_pty()

    def _accept(self) -> None:
        if self._listener is None:
            return
        while True:
            try:
                conn, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return
            if self._client is not None:
                self.stats.refused_clients += 1
                conn.close()
                continue
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._client, self._client_link = conn, _Link(BusPort(self.bus))
            self.stats.clients += 1

    def _drop_client(self) -> None:
        self._client.close()
        self._client = self._client_link = None

    def _serve_client(self) -> None:
        link = self._client_link
        while True:
            try:
                data = self._client.recv(_RECV)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._drop_client()
                return
            if not data:
                self._drop_client()
                return
            self.stats.bytes_rx += len(data)
            self._queue(link, link.port.feed(data))
        while link.outbox:
            try:
                n = self._client.send(link.outbox)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self._drop_client()
                return
            self.stats.bytes_tx += n
            del link.outbox[:n]

    def _serve_pty(self) -> None:
        link = self._pty
        while True:
            try:
                data = os.read(self._master, _RECV)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as e:  # EIO: no process holds the device open (we hold the slave: rare)
                if e.errno == errno.EIO:
                    break
                raise
            if not data:
                break
            self.stats.bytes_rx += len(data)
            self._queue(link, link.port.feed(data))
        while link.outbox:
            try:
                n = os.write(self._master, link.outbox)
            except (BlockingIOError, InterruptedError):
                return
            self.stats.bytes_tx += n
            del link.outbox[:n]

    def _queue(self, link: _Link, data: bytes) -> None:
        link.outbox += data
        if len(link.outbox) > _OUTBOX_MAX:
            extra = len(link.outbox) - _OUTBOX_MAX
            del link.outbox[:extra]
            self.stats.dropped_tx += extra

    # -- the servos ---------------------------------------------------------------------
    @property
    def bus_stats(self) -> BusStats:
        return self.bus.stats

    def joint_torques_nm(self, q, qdot) -> np.ndarray:
        """The torque each servo applies now [N m] at joint angles q [rad] and rates qdot
        [rad/s] (`simulator.dxl_servo` module doc: torque off 0; current mode the goal
        current; position mode the position PID; all within the current limit)."""
        return np.array([s.torque_nm(float(qi), float(wi)) for s, qi, wi in zip(self.servos, q, qdot)])

    def observe(self, t_s: float, q, qdot, tau_nm) -> None:
        """The joint state at time t_s [s] and the torques applied over the last step: what
        the next READ returns (Present Position, Velocity, Current, ...)."""
        for s, qi, wi, ti in zip(self.servos, q, qdot, tau_nm):
            s.observe(t_s, float(qi), float(wi), float(ti))

    @property
    def current_limits_nm(self) -> np.ndarray:
        """Each servo's Current Limit as a torque [N m]."""
        return np.array([s.get("current_limit") * self.model.nm_per_current_unit for s in self.servos])
