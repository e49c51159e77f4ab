"""The motion capture's pose stream (`amlink.mocap_protocol`: layout, subscriptions), as the
companion reads the object's pose from it (and could read any tracked body).

Endpoint: ``udp:HOST:PORT`` (or ``udpout:``) subscribes to the stream the sender serves at
HOST:PORT (default ``udp:127.0.0.1:7400``): a subscribe datagram at `open()`, again every
SUBSCRIBE_PERIOD_S from `poll()`. ``udpin:HOST:PORT`` listens there instead, for a sender
configured to send to it.

`poll()` reads what arrived (non-blocking) and keeps the latest frame of `body_id`; `read()`
returns it as a `MocapSample` (p_W [m] ENU, q_W (w, x, y, z), capture time_us on the
sender's clock, t_ns on this client's clock at receipt) or None (none, or older than
max_age_s); `object_pose()` gives it as the `amcore.mission.ObjectPose` the mission plans
from (centre and yaw). Frames lost are counted from the frame counter's gaps.
"""
from __future__ import annotations

import socket
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from amcore.mission import ObjectPose
from amcore.so3 import yaw_of_quat_wxyz
from amlink import mocap_protocol as mp
from amlink.endpoint import UDP_IN, UDP_OUT, EndpointError, as_destination, parse_endpoint

from . import DeviceError, wait_for_sample

DEFAULT_ENDPOINT = f"udp:127.0.0.1:{mp.MOCAP_PORT}"


class MocapError(DeviceError):
    pass


@dataclass(frozen=True)
class MocapSample:
    frame: int
    time_us: int
    body_id: int
    tracked: bool
    p_W: np.ndarray  # (3,) [m], ENU
    q_W_wxyz: np.ndarray  # (4,)
    t_ns: int


@dataclass
class MocapStats:
    frames: int = 0
    dropped: int = 0  # gaps in the frame counter
    other_bodies: int = 0
    untracked: int = 0
    malformed: int = 0
    refused: int = 0
    subscriptions: int = 0


class MocapClient:
    """Pose-stream client (module doc)."""

    def __init__(self, endpoint: str = DEFAULT_ENDPOINT, *, body_id: int = mp.OBJECT_BODY_ID,
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        try:
            ep = parse_endpoint(endpoint)
            if ep.kind not in (UDP_IN, UDP_OUT):
                raise EndpointError(endpoint, "the pose stream is UDP: udp:HOST:PORT or udpin:HOST:PORT")
            self.subscribe = ep.kind == UDP_OUT or ep.alias == "udp"
            if self.subscribe:
                ep = as_destination(ep, endpoint)
        except EndpointError as e:
            raise ValueError(f"--mocap {endpoint!r}: {e.why}") from None
        self.endpoint, self.address = endpoint, ep.address
        self.body_id, self.clock = body_id, clock
        self.stats = MocapStats()
        self._sock: socket.socket | None = None
        self._latest: MocapSample | None = None
        self._last_frame: int | None = None
        self._next_subscribe_ns = 0

    def open(self) -> None:
        host, port = self.address
        try:
            family, _, _, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        except socket.gaierror as e:
            raise MocapError(f"mocap {self.endpoint}: cannot resolve {host!r}: {e}") from None
        s = socket.socket(family, socket.SOCK_DGRAM)
        try:
            if self.subscribe:
                s.connect(addr)
            else:
                s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                s.bind(addr)
        except OSError as e:
            s.close()
            raise MocapError(f"mocap {self.endpoint}: {e}") from None
        s.setblocking(False)
        self._sock = s
        if self.subscribe:
            self._subscribe()

    def _subscribe(self) -> None:
        try:
            self._sock.send(mp.pack_subscribe())
            self.stats.subscriptions += 1
        except ConnectionRefusedError:
            self.stats.refused += 1
        except OSError as e:
            raise MocapError(f"mocap {self.endpoint}: cannot send: {e}") from None
        self._next_subscribe_ns = self.clock() + int(mp.SUBSCRIBE_PERIOD_S * 1e9)

    def poll(self) -> int:
        """Read what arrived (never blocks), renew the subscription when due; new frames kept."""
        if self._sock is None:
            return 0
        if self.subscribe and self.clock() >= self._next_subscribe_ns:
            self._subscribe()
        new = 0
        while True:
            try:
                data = self._sock.recv(256)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionRefusedError:
                self.stats.refused += 1
                continue
            t_ns = self.clock()
            try:
                f = mp.unpack_frame(data)
            except ValueError:
                self.stats.malformed += 1
                continue
            if f.body_id != self.body_id:
                self.stats.other_bodies += 1
                continue
            self.stats.frames += 1
            if self._last_frame is not None:
                gap = (f.frame - self._last_frame) & 0xFFFFFFFF
                if gap == 0 or gap >= 0x80000000:
                    continue  # not newer
                self.stats.dropped += gap - 1
            self._last_frame = f.frame
            if not f.tracked:
                self.stats.untracked += 1
                continue
            self._latest = MocapSample(f.frame, f.time_us, f.body_id, f.tracked, np.array(f.p_W),
                                       np.array(f.q_W_wxyz), t_ns)
            new += 1
        return new

    def read(self, max_age_s: float | None = None) -> MocapSample | None:
        s = self._latest
        if s is None or (max_age_s is not None and self.clock() - s.t_ns > max_age_s * 1e9):
            return None
        return s

    def object_pose(self, max_age_s: float | None = None) -> ObjectPose | None:
        """The latest frame as the mission's ObjectPose (centre p_W, yaw about z_W)."""
        s = self.read(max_age_s)
        if s is None:
            return None
        return ObjectPose(tuple(float(x) for x in s.p_W), yaw_of_quat_wxyz(s.q_W_wxyz))

    def wait(self, timeout_s: float) -> MocapSample:
        """Poll until a frame of the body arrives; MocapError after timeout_s [s]."""
        why = lambda: "refused (nothing serves the stream there)" if self.stats.refused else "no frame arrived"  # noqa: E731
        return wait_for_sample(self, timeout_s, lambda t: MocapError(f"mocap {self.endpoint}: {why()} within {t:g} s"))

    def fileno(self) -> int:
        return -1 if self._sock is None else self._sock.fileno()

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
        self._sock = None
