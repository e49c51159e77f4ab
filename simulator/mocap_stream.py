"""The motion capture's pose stream as the simulator sends it (`amlink.mocap_protocol`: the
layout, subscriptions, the default port 7400).

`publish(t_s, p_W, q_W_wxyz)` sends one frame, now, to every live subscriber and every
configured destination: the caller decides when a frame exists (e.g. every 1 / rate_hz of
[devices.mocap], after its latency, with `simulator.devices.Mocap`'s noise and losses, or
the exact pose). t_s is the capture time [s] on the simulator's clock; it travels as
time_us. `poll(now_s)` takes subscriptions and forgets those not renewed within
SUBSCRIPTION_TIMEOUT_S. All non-blocking.
"""
from __future__ import annotations

from dataclasses import dataclass

from amlink import mocap_protocol as mp
from amlink.endpoint import UDP_OUT, EndpointError, parse_endpoint
from amlink.transport import UdpListener

DEFAULT_ENDPOINT = f"udpin:127.0.0.1:{mp.MOCAP_PORT}"
MAX_SUBSCRIBERS = 32


@dataclass
class MocapStats:
    frames: int = 0
    datagrams_tx: int = 0
    subscriptions: int = 0
    bad_datagrams: int = 0
    expired: int = 0
    send_errors: int = 0
    refused: int = 0  # subscriptions beyond MAX_SUBSCRIBERS


class MocapStream(UdpListener):
    """Sender of one pose stream. endpoint: ``udpin:HOST:PORT`` it binds (port 0: a free
    one, see `address`); destinations: ``udpout:HOST:PORT`` strings it always sends to."""

    def __init__(self, *, endpoint: str = DEFAULT_ENDPOINT, destinations=(), body_id: int = mp.OBJECT_BODY_ID) -> None:
        super().__init__(endpoint, "mocap stream")
        try:
            dests = [parse_endpoint(d) for d in destinations]
        except EndpointError as e:
            raise ValueError(f"mocap stream: {e}") from None
        for d, text in zip(dests, destinations):
            if d.kind != UDP_OUT:
                raise ValueError(f"mocap destination {text!r}: must be udpout:HOST:PORT")
        self._dests = [d.address for d in dests]
        self.body_id = body_id
        self.stats = MocapStats()
        self._subs: dict[tuple, float] = {}  # address -> last subscription [s]
        self._frame = 0

    def _forget(self) -> None:
        self._subs.clear()

    @property
    def subscribers(self) -> list[tuple]:
        return list(self._subs)

    def poll(self, now_s: float) -> None:
        if self._sock is None:
            return
        while True:
            try:
                data, addr = self._sock.recvfrom(64)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self.stats.send_errors += 1
                continue
            if not mp.is_subscribe(data):
                self.stats.bad_datagrams += 1
                continue
            if addr not in self._subs and len(self._subs) >= MAX_SUBSCRIBERS:
                self.stats.refused += 1
                continue
            self.stats.subscriptions += addr not in self._subs
            self._subs[addr] = now_s
        for addr, t in list(self._subs.items()):
            if now_s - t > mp.SUBSCRIPTION_TIMEOUT_S:
                del self._subs[addr]
                self.stats.expired += 1

    def publish(self, t_s: float, p_W, q_W_wxyz, tracked: bool = True) -> None:
        """One frame of the body at capture time t_s [s]: p_W [m] (ENU), q_W (w, x, y, z)."""
        if self._sock is None:
            return
        f = mp.PoseFrame(self._frame, max(0, int(round(t_s * 1e6))), self.body_id, tracked,
                         tuple(float(x) for x in p_W), tuple(float(x) for x in q_W_wxyz))
        data = mp.pack_frame(f)
        self._frame = (self._frame + 1) & 0xFFFFFFFF
        self.stats.frames += 1
        for addr in [*self._subs, *self._dests]:
            try:
                self._sock.sendto(data, addr)
                self.stats.datagrams_tx += 1
            except OSError:
                self.stats.send_errors += 1
