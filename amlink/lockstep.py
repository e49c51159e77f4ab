"""Lockstep UDP transport between the simulator and N companions (sockets only).

Protocol (MAVLink 2, amstack dialect, one UDP socket on each side):

1. Handshake.  Each companion (sysid s, compid 191 = MAV_COMP_ID_ONBOARD_COMPUTER)
   sends HEARTBEAT at 2 Hz to the simulator.  The simulator (sysid 1, compid 1 =
   MAV_COMP_ID_AUTOPILOT1: it plays every vehicle's flight controller) learns
   the companion's address from that datagram and answers with AM_SCENARIO.
2. Optional arming: COMMAND_LONG(MAV_CMD_COMPONENT_ARM_DISARM) -> COMMAND_ACK.
3. Each step the simulator sends every companion ONE datagram
   ``ODOMETRY, AM_JOINT_STATE, AM_WRENCH, AM_SIM_STEP`` (all N first), then waits
   until every companion has answered with ``[SET_ATTITUDE_TARGET,]
   AM_TORQUE_SETPOINT`` for that same step.
4. :meth:`SimServer.close` sends ``STATUSTEXT, AM_SIM_STEP(SHUTDOWN)``.

All companions share the simulator's single socket; the simulator tells them
apart by the packet's sysid and updates each one's address from its latest
packet.  Neither object is thread-safe; use one per thread.

Hooks for later (not implemented): MAVLink 2 signing goes into
``codec.Encoder.pack`` / ``codec.Decoder.feed`` (``.mavlink.signing``); link
impairment (loss, delay) goes into ``amlink.udp.Udp.send`` / ``.recv``, the one
send path and the one receive path of both sides.
"""

from __future__ import annotations

import socket
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from amlink import codec
from amlink.codec import mav
from amlink.errors import (
    CommandRejectedError,
    PeerMissingError,
    PeerProtocolError,
    PeerTimeoutError,
    SimulatorTimeoutError,
    SimulatorUnreachableError,
)
from amlink.types import AttitudeTarget, ScenarioInfo, SensorFrame, TorqueSetpoint
from amlink.udp import (
    COMMAND_RETRY_S,
    COMPANION_COMPID,
    HEARTBEAT_PERIOD_S,
    SIM_COMPID,
    SIM_SYSID,
    STATUSTEXT_MAX,
    LinkStats,
    Udp,
    parse_endpoint,
)

@dataclass
class _Peer:
    sysid: int
    encoder: codec.Encoder
    setpoints: codec.SetpointAssembler
    addr: tuple[str, int] | None = None
    armed: bool = False
    last_step: int = -1
    last_time_s: float = 0.0


class SimServer:
    """Simulator end of the lockstep link: one UDP socket shared by all companions.

    Args:
        bind: ``"udp:HOST:PORT"`` or ``"udpin:HOST:PORT"``; HOST ``0.0.0.0`` serves
            other hosts, PORT 0 picks a free port (see :attr:`address`).
        sysids: companion system ids (2..255; 1 is the simulator).
        scenario: what :meth:`wait_for_peers` announces in AM_SCENARIO.
        timeout_s: default per-step answer timeout of :meth:`exchange` [s].
    """

    def __init__(self, bind: str = "udp:127.0.0.1:14550", *, sysids: Sequence[int], scenario: ScenarioInfo,
                 timeout_s: float = 1.0) -> None:  # fmt: skip
        self.bind_host, self.bind_port = parse_endpoint(bind, ("udp", "udpin"))
        self.sysids = tuple(sysids)
        if not self.sysids or len(set(self.sysids)) != len(self.sysids) or not all(2 <= s <= 255 for s in self.sysids):
            raise ValueError(f"sysids {self.sysids} must be non-empty, distinct and in 2..255 (1 is the simulator)")
        self.scenario = scenario
        self.timeout_s = timeout_s
        self.stats = LinkStats()
        self.attitude_targets: dict[int, AttitudeTarget] = {}  # latest, informational
        self._udp: Udp | None = None
        self._peers: dict[int, _Peer] = {}
        self._decoders: dict[tuple[str, int], codec.Decoder] = {}

    # -- lifecycle -----------------------------------------------------------
    def open(self) -> tuple[str, int]:
        """Bind the socket; returns the bound ``(host, port)``."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            sock.bind((self.bind_host, self.bind_port))
        except OSError:
            sock.close()
            raise
        self._udp = Udp(sock, self.stats)
        self._peers = {
            s: _Peer(s, codec.Encoder(SIM_SYSID, SIM_COMPID), codec.SetpointAssembler()) for s in self.sysids
        }
        return self.address

    @property
    def address(self) -> tuple[str, int]:
        return self._require_open().sock.getsockname()

    def __enter__(self) -> SimServer:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close("simulator exiting on error" if exc[0] else "run complete", error=exc[0] is not None)

    def close(self, reason: str = "run complete", error: bool = False) -> None:
        """Send STATUSTEXT(reason) + AM_SIM_STEP(SHUTDOWN) to every known peer, then close."""
        if self._udp is None:
            return
        severity = mav.MAV_SEVERITY_ERROR if error else mav.MAV_SEVERITY_NOTICE
        text = reason.encode("utf-8")[:STATUSTEXT_MAX].decode("utf-8", "ignore").encode("utf-8")
        for peer in self._peers.values():
            if peer.addr is None:
                continue
            msgs = [
                mav.MAVLink_statustext_message(severity, text),
                codec.shutdown_message(peer.last_step + 1, peer.last_time_s, self.scenario.scenario_id),
            ]
            try:
                self._udp.send(peer.addr, peer.encoder.pack(msgs))
            except OSError:
                pass  # closing anyway; the peer will time out
        self._udp.close()
        self._udp = None

    # -- queries ---------------------------------------------------------------
    def armed(self, sysid: int) -> bool:
        """Armed state of companion ``sysid`` as last commanded by it."""
        return self._peers[sysid].armed

    def peer_address(self, sysid: int) -> tuple[str, int] | None:
        return self._peers[sysid].addr

    # -- handshake ---------------------------------------------------------------
    def wait_for_peers(self, timeout_s: float) -> None:
        """Wait for a HEARTBEAT from every configured sysid (each answered with AM_SCENARIO).

        Raises PeerMissingError naming the silent sysids after ``timeout_s``.
        """
        self._wait_until(lambda p: p.addr is not None, timeout_s, "HEARTBEAT")

    def wait_for_armed(self, timeout_s: float) -> None:
        """Wait until every companion has armed (COMMAND_LONG ARM); PeerMissingError if not."""
        self._wait_until(lambda p: p.armed, timeout_s, "ARM command")

    def _wait_until(self, ok, timeout_s: float, what: str) -> None:
        udp = self._require_open()
        deadline = time.monotonic() + timeout_s
        while True:
            missing = [s for s, p in self._peers.items() if not ok(p)]
            if not missing:
                return
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise PeerMissingError(missing, timeout_s, what)
            for data, addr in udp.recv(remaining):
                for _setpoint in self._handle(data, addr):
                    self.stats.stale_setpoints += 1  # nothing awaited yet

    # -- lockstep ----------------------------------------------------------------
    def exchange(self, frames: dict[int, SensorFrame], timeout_s: float | None = None) -> dict[int, TorqueSetpoint]:
        """Send each companion its frame, then wait for all setpoints of those steps.

        All batches go out before any answer is awaited, so the companions
        compute concurrently.  Stale, duplicate and wrong-step setpoints and
        packets from unknown sysids are ignored and counted in :attr:`stats`.

        Raises PeerTimeoutError(sysid, step) if a companion does not answer
        within ``timeout_s`` (default: the constructor's), PeerMissingError if a
        companion never said hello, PeerProtocolError on an invalid setpoint.
        """
        udp = self._require_open()
        timeout = self.timeout_s if timeout_s is None else timeout_s
        outgoing = []
        for sysid, frame in frames.items():
            peer = self._peers.get(sysid)
            if peer is None:
                raise ValueError(f"sysid {sysid} is not one of {self.sysids}")
            if peer.addr is None:
                raise PeerMissingError([sysid], 0.0, "HEARTBEAT (call wait_for_peers first)")
            msgs = codec.sensor_frame_messages(frame, self.scenario.scenario_id)
            outgoing.append((peer, frame, peer.encoder.pack(msgs)))
        expected = {peer.sysid: frame.step for peer, frame, _ in outgoing}
        for peer, frame, data in outgoing:
            udp.send(peer.addr, data)
            peer.last_step, peer.last_time_s = frame.step, frame.time_s
        results: dict[int, TorqueSetpoint] = {}
        deadline = time.monotonic() + timeout
        polled = False  # read the socket at least once, even with timeout 0
        while len(results) < len(expected):
            remaining = deadline - time.monotonic()
            if remaining <= 0 and polled:
                missing = sorted(set(expected) - set(results))
                raise PeerTimeoutError(missing[0], expected[missing[0]], timeout, missing)
            polled = True
            for data, addr in udp.recv(remaining):
                for sysid, sp, att in self._handle(data, addr):
                    step = expected.get(sysid)
                    if step is None or sp.step < step:
                        self.stats.stale_setpoints += 1
                    elif sp.step > step:
                        self.stats.wrong_step_setpoints += 1
                    elif sysid in results:
                        self.stats.duplicate_setpoints += 1
                    else:
                        results[sysid] = sp
                        if att is not None:
                            self.attitude_targets[sysid] = att
        return results

    # -- receive path ----------------------------------------------------------
    def _handle(self, data: bytes, addr: tuple[str, int]):
        """Decode one datagram; answer control messages; return its setpoints."""
        dec = self._decoders.get(addr)
        if dec is None:
            if len(self._decoders) > 4 * len(self._peers) + 16:  # bound junk senders
                self._decoders = {p.addr: self._decoders[p.addr] for p in self._peers.values()
                                  if p.addr in self._decoders}  # fmt: skip
            dec = self._decoders[addr] = codec.Decoder()
        bad_before = dec.bad_frames
        msgs = dec.feed(data)
        self.stats.bad_frames += dec.bad_frames - bad_before
        out = []
        for msg in msgs:
            peer = self._peers.get(msg.get_srcSystem())
            if peer is None:
                self.stats.unknown_sysid += 1
                continue
            peer.addr = addr  # learn / follow the companion's address
            mid = msg.get_msgId()  # not msg.id: STATUSTEXT has a field named "id"
            if mid == mav.MAVLINK_MSG_ID_HEARTBEAT:
                self._udp.send(addr, peer.encoder.pack([codec.scenario_message(self.scenario)]))
            elif mid == mav.MAVLINK_MSG_ID_COMMAND_LONG:
                self._on_command(peer, msg)
            elif mid in (mav.MAVLINK_MSG_ID_AM_TORQUE_SETPOINT, mav.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET):
                try:
                    got = peer.setpoints.push(msg)
                except codec.CodecError as exc:
                    raise PeerProtocolError(peer.sysid, str(exc)) from exc
                if got is not None:
                    out.append((peer.sysid, *got))
            else:
                self.stats.ignored += 1
        return out

    def _on_command(self, peer: _Peer, msg) -> None:
        if msg.target_system not in (0, SIM_SYSID):
            self.stats.ignored += 1
            return
        if msg.command == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            peer.armed = msg.param1 >= 0.5
            result = mav.MAV_RESULT_ACCEPTED
        else:
            result = mav.MAV_RESULT_UNSUPPORTED
        ack = mav.MAVLink_command_ack_message(msg.command, result, 0, 0, peer.sysid, msg.get_srcComponent())
        self._udp.send(peer.addr, peer.encoder.pack([ack]))

    def _require_open(self) -> Udp:
        if self._udp is None:
            raise RuntimeError("SimServer is not open; call open() first")
        return self._udp


class CompanionClient:
    """Companion end of the lockstep link for vehicle ``sysid``.

    Args:
        sysid: this companion's MAVLink system id (2..255).
        sim: simulator address ``"udp:HOST:PORT"`` (or ``udpout:``).
        compid: MAVLink component id, 191 = MAV_COMP_ID_ONBOARD_COMPUTER.

    Messages that arrive while waiting for something else (a sensor batch
    while :meth:`arm` waits for its ACK, say) are kept, never dropped.
    """

    def __init__(self, sysid: int, sim: str = "udp:127.0.0.1:14550", compid: int = COMPANION_COMPID) -> None:
        if not 2 <= sysid <= 255:
            raise ValueError(f"sysid {sysid} must be in 2..255 (1 is the simulator)")
        self.sysid = sysid
        self.compid = compid
        self.sim = sim
        self.sim_host, self.sim_port = parse_endpoint(sim, ("udp", "udpout"))
        self.stats = LinkStats()
        self.scenario: ScenarioInfo | None = None
        self.status_texts: list[tuple[int, str]] = []  # (MAV_SEVERITY, text) from the simulator
        self._udp: Udp | None = None
        self._sim_addr: tuple[str, int] | None = None
        self._encoder = codec.Encoder(sysid, compid)
        self._decoder = codec.Decoder()
        self._frames = codec.SensorFrameAssembler()
        self._inbox: deque[SensorFrame | codec.Shutdown] = deque()
        self._acks: deque = deque()
        self._shutdown = False
        self._last_time_s = 0.0

    def connect(self, timeout_s: float = 5.0) -> ScenarioInfo:
        """Open a socket and say HEARTBEAT at 2 Hz until the simulator answers AM_SCENARIO.

        Raises SimulatorUnreachableError naming the address after ``timeout_s``.
        """
        try:
            infos = socket.getaddrinfo(self.sim_host, self.sim_port, socket.AF_INET, socket.SOCK_DGRAM)
        except socket.gaierror as exc:
            raise SimulatorUnreachableError(self.sim, 0.0, f"cannot resolve: {exc}") from exc
        if self._udp is not None:
            raise RuntimeError("CompanionClient is already connected")
        self._sim_addr = infos[0][4]
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("0.0.0.0", 0))
        self._udp = Udp(sock, self.stats)
        heartbeat = mav.MAVLink_heartbeat_message(
            mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE, 3
        )
        deadline = time.monotonic() + timeout_s
        next_beat = 0.0
        try:
            while self.scenario is None:
                now = time.monotonic()
                if now >= deadline:
                    raise SimulatorUnreachableError(self.sim, timeout_s)
                if now >= next_beat:
                    self._send([heartbeat])
                    next_beat = now + HEARTBEAT_PERIOD_S
                self._pump(min(deadline, next_beat) - now)
        except BaseException:
            self.close()
            raise
        return self.scenario

    @property
    def local_address(self) -> tuple[str, int]:
        """The ``(host, port)`` this companion's socket is bound to (after connect)."""
        return self._require_connected().sock.getsockname()

    def arm(self, timeout_s: float = 1.0, arm: bool = True) -> None:
        """COMMAND_LONG(MAV_CMD_COMPONENT_ARM_DISARM) until COMMAND_ACK (retried every 0.25 s).

        Raises CommandRejectedError if not accepted, SimulatorTimeoutError on timeout.
        """
        self._require_connected()
        cmd = mav.MAV_CMD_COMPONENT_ARM_DISARM
        deadline = time.monotonic() + timeout_s
        next_try, confirmation = 0.0, 0
        while True:
            while self._acks:
                ack = self._acks.popleft()
                if ack.command == cmd:
                    if ack.result != mav.MAV_RESULT_ACCEPTED:
                        raise CommandRejectedError(cmd, ack.result)
                    return
            now = time.monotonic()
            if now >= deadline:
                raise SimulatorTimeoutError("COMMAND_ACK for ARM_DISARM", timeout_s)
            if now >= next_try:
                self._send([mav.MAVLink_command_long_message(
                    SIM_SYSID, SIM_COMPID, cmd, confirmation, 1.0 if arm else 0.0, 0, 0, 0, 0, 0, 0)])  # fmt: skip
                next_try, confirmation = now + COMMAND_RETRY_S, min(confirmation + 1, 255)
            self._pump(min(deadline, next_try) - now)

    def recv_frame(self, timeout_s: float = 1.0) -> SensorFrame | None:
        """Next sensor frame, or None once the simulator announced shutdown.

        Keeps reading across datagrams until a batch's AM_SIM_STEP arrives.
        Raises SimulatorTimeoutError after ``timeout_s``; codec errors propagate.
        """
        self._require_connected()
        deadline = time.monotonic() + timeout_s
        polled = False  # poll the socket at least once, even with timeout_s = 0
        while not self._shutdown:
            if self._inbox:
                item = self._inbox.popleft()
                if isinstance(item, codec.Shutdown):
                    self._shutdown = True
                    break
                self._last_time_s = item.time_s
                return item
            remaining = deadline - time.monotonic()
            if remaining <= 0 and polled:
                raise SimulatorTimeoutError("sensor frame", timeout_s)
            self._pump(remaining)
            polled = True
        return None

    def send_setpoint(self, setpoint: TorqueSetpoint, attitude: AttitudeTarget | None = None) -> None:
        """Send the answer to step ``setpoint.step`` (one datagram)."""
        time_boot_ms = round(self._last_time_s * 1e3)
        self._send(codec.setpoint_messages(setpoint, attitude, time_boot_ms, SIM_SYSID, SIM_COMPID))

    def close(self) -> None:
        if self._udp is not None:
            self._udp.close()
            self._udp = None

    def __enter__(self) -> CompanionClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- the one send path and the one receive path ------------------------------
    def _require_connected(self) -> Udp:
        if self._udp is None:
            raise RuntimeError("CompanionClient is not connected; call connect() first")
        return self._udp

    def _send(self, msgs) -> None:
        self._require_connected().send(self._sim_addr, self._encoder.pack(msgs))

    def _pump(self, timeout_s: float) -> None:
        for data, _addr in self._require_connected().recv(timeout_s):
            bad_before = self._decoder.bad_frames
            msgs = self._decoder.feed(data)
            self.stats.bad_frames += self._decoder.bad_frames - bad_before
            for msg in msgs:
                if msg.get_srcSystem() != SIM_SYSID:
                    self.stats.unknown_sysid += 1
                    continue
                mid = msg.get_msgId()  # not msg.id: STATUSTEXT has a field named "id"
                if mid == mav.MAVLINK_MSG_ID_AM_SCENARIO:
                    if self.scenario is None:
                        self.scenario = codec.scenario_from_message(msg)
                elif mid == mav.MAVLINK_MSG_ID_COMMAND_ACK:
                    self._acks.append(msg)
                elif mid == mav.MAVLINK_MSG_ID_STATUSTEXT:
                    self.status_texts.append((msg.severity, msg.text))
                else:
                    item = self._frames.push(msg)
                    if item is not None:
                        self._inbox.append(item)
                    elif mid not in _SENSOR_PART_IDS:
                        self.stats.ignored += 1


_SENSOR_PART_IDS = frozenset(
    (mav.MAVLINK_MSG_ID_ODOMETRY, mav.MAVLINK_MSG_ID_AM_JOINT_STATE, mav.MAVLINK_MSG_ID_AM_WRENCH)
)
