"""Simulator end of the lockstep link (see :mod:`amlink.lockstep` for the protocol)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from amlink import codec
from amlink.codec import mav
from amlink.endpoint import UDP_OUT, Endpoint, parse_endpoint
from amlink.errors import PeerMissingError, PeerTimeoutError
from amlink.protocol import (
    HEARTBEAT_PERIOD_S,
    REJOIN_QUIET_S,
    SENSOR_RETRY_S,
    SHUTDOWN_COPIES,
    SIM_COMPID,
    SIM_SYSID,
    STATUSTEXT_MAX,
    WAITING_NOTICE_PERIOD_S,
    WAITING_NOTICE_PREFIX,
    LinkStats,
)
from amlink.signing import check_key
from amlink.stream import StreamPeer
from amlink.transport import Mux, Shim, close_all, open_transport
from amlink.types import (
    DEFAULT_SETPOINT_LIMITS,
    AttitudeSetpoint,
    AttitudeTarget,
    ScenarioInfo,
    SensorFrame,
    SetpointLimits,
    TorqueSetpoint,
)

_HEARTBEAT = mav.MAVLINK_MSG_ID_HEARTBEAT
_COMMAND_LONG = mav.MAVLINK_MSG_ID_COMMAND_LONG
_ATTITUDE = mav.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET
_SETPOINT = mav.MAVLINK_MSG_ID_AM_TORQUE_SETPOINT
_JOINT_SETPOINT = mav.MAVLINK_MSG_ID_AM_JOINT_TORQUE_SETPOINT  # attitude mode: with SET_ATTITUDE_TARGET
STREAMED = frozenset((mav.MAVLINK_MSG_ID_ODOMETRY, mav.MAVLINK_MSG_ID_AM_JOINT_STATE, mav.MAVLINK_MSG_ID_AM_WRENCH,
                      mav.MAVLINK_MSG_ID_ATTITUDE_TARGET))  # the sensor batch's messages (SET_MESSAGE_INTERVAL)
_ACCEPT = (_HEARTBEAT, _COMMAND_LONG, _ATTITUDE, _SETPOINT, _JOINT_SETPOINT)  # all else: counted as ignored
_MAX_BACKOFF = 4  # retry interval grows 1, 2, 4, 4, ... x retry_s


@dataclass
class _Peer:
    sysid: int
    encoder: codec.Encoder
    addr: tuple[str, int] | None = None
    armed: bool = False
    lost: bool = False  # partial exchange: missed a step; not waited for until it shows life
    last_heard: float = float("-inf")  # time.monotonic() of its last admitted packet
    last_step: int = -1
    last_time_s: float = 0.0
    batch: tuple | None = None  # (msgid, payload)s of the sensor batch awaiting an answer (re-framed on re-send)
    attitude: tuple | None = None  # stream links: SET_ATTITUDE_TARGET awaiting its AM_TORQUE_SETPOINT
    intervals: dict = field(default_factory=dict)  # msgid -> interval [us] the companion asked for


class SimServer:
    """Simulator end of the lockstep link: one UDP socket shared by all companions.

    Args:
        bind: one endpoint or several (:mod:`amlink.endpoint`, mavutil's forms), all
            served at once: ``"udpin:HOST:PORT"`` (``udp:`` is the same; HOST
            ``0.0.0.0`` serves other hosts, PORT 0 picks a free port, see
            :attr:`address`), ``"tcpin:HOST:PORT"``, a serial device
            (``"/dev/ttyUSB0:921600"``), or the sending forms ``"udpout:HOST:PORT"`` and
            ``"tcp:HOST:PORT"`` for a companion that listens (the simulator says
            HEARTBEAT there until a companion answers).
        sysids: companion system ids (2..255; 1 is the simulator).
        scenario: what :meth:`wait_for_peers` announces in AM_SCENARIO.
        object_pose: ``((x, y, z), yaw)`` of the measured object [m, rad, W], sent in
            AM_OBJECT_POSE just before every AM_SCENARIO; None: not sent.
        timeout_s: default per-step answer timeout of :meth:`exchange` [s].
        signing_keys: ``None`` -- signing off (the default at this API level; the
            process mains turn it on from the scenario).  Else ``{sysid: 32-byte
            key}`` for every sysid: all traffic with companion ``s`` is signed with
            its key on link id ``s``; unsigned, wrongly signed and replayed packets
            are dropped and counted (:class:`amlink.protocol.LinkStats`).
        limits: plausibility bounds a setpoint must meet to be returned.
        retry_s: wall time after which an unanswered sensor batch is re-sent
            (then 2x, 4x, 4x ... that) [s].
        shim: send-path impairment hook of :class:`amlink.transport.Udp` (tests).
        on_heartbeat: called with ``(sysid, compid, message)`` for every admitted
            companion HEARTBEAT (the simulator forwards them to its GCS link).

    Addresses.  A peer's address is learned from its packets.  Signing on: an
    authentic HEARTBEAT or COMMAND_LONG of sysid ``s``, or an authentic setpoint that
    passes the plausibility check, moves ``s`` to the packet's source address
    (rejoin, NAT rebinding); nothing else can: a rejected setpoint from another
    address is dropped and counted (``rejected_setpoints``, ``wrong_address``) and
    answers no step, so it neither diverts the peer's frames nor stands in for its answer.  Signing off: only a HEARTBEAT
    moves it (a companion says HEARTBEAT when it (re)connects), and only once
    ``s`` has been silent for ``REJOIN_QUIET_S`` (1 s) or is lost; any other
    packet claiming ``s`` from another address is dropped (``wrong_address``).
    Without signing nothing is authenticated, so whoever says HEARTBEAT as ``s``
    first -- or while ``s`` is silent -- takes ``s`` over: a documented
    weakness; run signed where that matters.  A HEARTBEAT from a known peer at a
    new address is a *rejoin*: the peer is disarmed until it arms again.
    """

    def __init__(self, bind: str | Endpoint | Sequence[str | Endpoint] = "udpin:127.0.0.1:14550", *,
                 sysids: Sequence[int], scenario: ScenarioInfo,
                 timeout_s: float = 1.0, signing_keys: Mapping[int, bytes] | None = None,
                 limits: SetpointLimits = DEFAULT_SETPOINT_LIMITS, retry_s: float = SENSOR_RETRY_S,
                 shim: Shim | None = None,
                 on_heartbeat: Callable[[int, int, object], None] | None = None,
                 object_pose: tuple | None = None) -> None:  # fmt: skip
        binds = [bind] if isinstance(bind, (str, Endpoint)) else list(bind)
        if not binds:
            raise ValueError("bind: at least one endpoint")
        self.endpoints = tuple(b if isinstance(b, Endpoint) else parse_endpoint(b) for b in binds)
        self.sysids = tuple(sysids)
        if not self.sysids or len(set(self.sysids)) != len(self.sysids) or not all(2 <= s <= 255 for s in self.sysids):
            raise ValueError(f"sysids {self.sysids} must be non-empty, distinct and in 2..255 (1 is the simulator)")
        if signing_keys is not None:
            if set(signing_keys) != set(self.sysids):
                raise ValueError(f"signing_keys must have exactly one key per sysid {self.sysids}")
            signing_keys = {s: check_key(k) for s, k in signing_keys.items()}
        if not retry_s > 0.0:
            raise ValueError(f"retry_s must be > 0, got {retry_s}")
        self.scenario = scenario
        # ((x, y, z) [m, W], yaw [rad]) of the measured object, sent before AM_SCENARIO; None: not sent
        self._hello_msgs = ([] if object_pose is None else [codec.object_pose_message(*object_pose)])
        self.timeout_s = timeout_s
        self.limits = limits
        self.retry_s = retry_s
        self.stats = LinkStats()
        self.attitude_targets: dict[int, AttitudeTarget] = {}  # latest, informational
        self.last_missing: tuple[int, ...] = ()  # sysids without a setpoint in the last exchange
        self.last_rejection: tuple[int, str] | None = None  # (sysid, reason) of the last rejected setpoint
        self.last_rejected: tuple[tuple[int, str], ...] = ()  # rejected answers of the last exchange (see there)
        self.on_heartbeat = on_heartbeat
        self._keys = signing_keys
        self._shim = shim
        self._link: Mux | None = None
        self._hello: list[tuple] = []  # udpout destinations: (address, transport)
        self._next_hello = 0.0
        self._peers: dict[int, _Peer] = {}
        self._decoder: codec.Decoder | None = None
        self._expected: dict[int, int] = {}  # sysid -> step of the frames sent and not yet collected

    # -- lifecycle -----------------------------------------------------------
    def open(self) -> tuple[str, int] | None:
        """Open every endpoint; returns the first one's local ``(host, port)`` (None for a serial port).

        OSError (closing what was opened) if one cannot be opened."""
        transports = []
        try:
            for ep in self.endpoints:
                transports.append(open_transport(ep, self.stats, shim=self._shim))
        except OSError:
            close_all(transports)
            raise
        self._link = Mux(transports)
        self._hello = [(t.peer, t) for ep, t in zip(self.endpoints, transports) if ep.kind == UDP_OUT]
        for addr, t in self._hello:
            self._link.route(addr, t)
        keys = self._keys or {}
        self._peers = {
            s: _Peer(s, codec.Encoder(SIM_SYSID, SIM_COMPID, signing_key=keys.get(s), link_id=s)) for s in self.sysids
        }
        self._decoder = codec.Decoder(self._keys, accept=_ACCEPT, counters=self.stats, readers=codec.READERS)
        return self.address

    @property
    def address(self) -> tuple[str, int] | None:
        """The first endpoint's local ``(host, port)`` (None for a serial port or a TCP client)."""
        return self._local(self._require_open().transports[0])

    @property
    def bound_endpoints(self) -> tuple[Endpoint, ...]:
        """The endpoints as opened: a listening one's port 0 replaced by the port it got."""
        link = self._require_open()
        out = []
        for ep, t in zip(self.endpoints, link.transports):
            local = self._local(t)
            out.append(ep.with_port(local[1]) if ep.listens and local is not None else ep)
        return tuple(out)

    @staticmethod
    def _local(transport) -> tuple | None:
        local = getattr(transport, "local_address", None)
        return None if local is None else tuple(local[:2])

    @property
    def signing(self) -> bool:
        return self._keys is not None

    def __enter__(self) -> SimServer:
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close("simulator exiting on error" if exc[0] else "run complete", error=exc[0] is not None)

    def close(self, reason: str = "run complete", error: bool = False) -> None:
        """Send STATUSTEXT(reason) + AM_SIM_STEP(SHUTDOWN) (3 copies) to every known peer, then close."""
        if self._link is None:
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
            for _ in range(SHUTDOWN_COPIES):
                try:
                    self._link.send(peer.addr, peer.encoder.pack(msgs))
                except OSError:
                    pass  # closing anyway; the peer will time out
        self._flush_streams()
        self._link.close()
        self._link = None

    def _flush_streams(self, within_s: float = 0.5) -> None:
        """Give stream transports a moment to write what they still hold (the SHUTDOWN)."""
        deadline = time.monotonic() + within_s
        while any(t.wfds() for t in self._link.transports) and time.monotonic() < deadline:
            self._link.recv(0.01)

    # -- queries ---------------------------------------------------------------
    def armed(self, sysid: int) -> bool:
        """Armed state of companion ``sysid`` as last commanded by it (a rejoin disarms)."""
        return self._peers[sysid].armed

    def peer_address(self, sysid: int) -> tuple[str, int] | None:
        return self._peers[sysid].addr

    @property
    def lost_peers(self) -> frozenset[int]:
        """Sysids that missed a step of :meth:`exchange` (partial) and have not shown life since."""
        return frozenset(s for s, p in self._peers.items() if p.lost)

    # -- handshake ---------------------------------------------------------------
    def wait_for_peers(self, timeout_s: float, on_waiting: Callable[[str], None] | None = None) -> None:
        """Wait for a HEARTBEAT from every configured sysid (each answered with AM_SCENARIO).

        Raises PeerMissingError naming the silent sysids after ``timeout_s``. Meanwhile, every
        WAITING_NOTICE_PERIOD_S, the companions already there hear whom it waits for (a
        STATUSTEXT, :func:`waiting_notice`) and ``on_waiting`` gets the same text.
        """
        self._wait_until(lambda p: p.addr is not None, timeout_s, "HEARTBEAT", on_waiting)

    def wait_for_armed(self, timeout_s: float, on_waiting: Callable[[str], None] | None = None) -> None:
        """Wait until every companion has armed (COMMAND_LONG ARM); PeerMissingError if not.
        Notices as :meth:`wait_for_peers`."""
        self._wait_until(lambda p: p.armed, timeout_s, "ARM", on_waiting)

    def _wait_until(self, ok, timeout_s: float, what: str, on_waiting=None) -> None:
        link = self._require_open()
        deadline = time.monotonic() + timeout_s
        next_notice = time.monotonic() + WAITING_NOTICE_PERIOD_S
        while True:
            missing = [s for s, p in self._peers.items() if not ok(p)]
            if not missing:
                return
            now = time.monotonic()
            remaining = deadline - now
            if remaining <= 0:
                raise PeerMissingError(missing, timeout_s, what)
            if now >= next_notice:
                text = waiting_notice(what, missing, remaining)
                self._notify(text)
                if on_waiting is not None:
                    on_waiting(text)
                next_notice = now + WAITING_NOTICE_PERIOD_S
            remaining = min(remaining, next_notice - now)
            if self._hello:
                if now >= self._next_hello:
                    self._say_hello()
                    self._next_hello = now + HEARTBEAT_PERIOD_S
                remaining = min(remaining, self._next_hello - now)
            for data, addr in link.recv(remaining):
                for _setpoint in self._handle(data, addr):
                    self.stats.stale_setpoints += 1  # nothing awaited yet

    def _notify(self, text: str) -> None:
        """STATUSTEXT (INFO) to every companion heard so far."""
        msg = mav.MAVLink_statustext_message(mav.MAV_SEVERITY_INFO,
                                             text.encode("utf-8")[:STATUSTEXT_MAX].decode("utf-8", "ignore").encode())
        for peer in self._peers.values():
            if peer.addr is not None:
                self._link.send(peer.addr, peer.encoder.pack([msg]))

    def _say_hello(self) -> None:
        """HEARTBEAT to every udpout destination no companion answers from yet, once per
        companion not yet heard (each signed with that companion's key): a companion that
        listens (udpin) learns the simulator's address from it."""
        taken = {p.addr for p in self._peers.values()}
        silent = [p for p in self._peers.values() if p.addr is None]
        beat = mav.MAVLink_heartbeat_message(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_GENERIC, 0, 0,
                                             mav.MAV_STATE_STANDBY, 3)
        for addr, transport in self._hello:
            if addr in taken:
                continue
            self._link.route(addr, transport)
            for peer in silent:
                self._link.send(addr, peer.encoder.pack([beat]))

    # -- lockstep ----------------------------------------------------------------
    def exchange(self, frames: Mapping[int, SensorFrame] | Iterable[tuple[int, SensorFrame]],
                 timeout_s: float | None = None, *, partial: bool = False,
                 while_waiting: Callable[[], None] | None = None,
                 on_setpoint: Callable[[int, TorqueSetpoint | AttitudeSetpoint], None] | None = None,
                 ) -> dict[int, TorqueSetpoint | AttitudeSetpoint]:  # fmt: skip
        """Send each companion its frame, then wait for the setpoints of those steps.

        ``frames``: sysid -> frame, or (sysid, frame) pairs produced lazily: with
        ``partial=True`` each frame is sent as soon as it is produced, so that
        companion computes while the next one is read (``partial=False`` checks
        every peer first, so it takes them all before sending).  ``while_waiting``,
        if given, is called once after the frames are out and before the first
        answer is read: work that need not delay the companions (the simulator's
        bookkeeping) runs while they compute.
        ``on_setpoint(sysid, setpoint)``, if given, is called for each accepted
        setpoint as it arrives (the flight controller applies it while the others
        are awaited); the returned dict holds them all the same.

        All batches go out before any answer is awaited, so the companions
        compute concurrently.  A batch still unanswered after ``retry_s`` is
        re-sent (backing off), so a lost datagram in either direction costs a
        retry interval, not the run.  Stale, duplicate, wrong-step and
        unauthenticated setpoints are dropped and counted in :attr:`stats`; the
        step keeps waiting for a valid one.

        Rejected answers.  A setpoint for the awaited step, from the peer's own
        address, that is non-finite, malformed or outside :attr:`limits` answers
        that step at once: it is not returned, and :attr:`last_rejected` lists
        ``(sysid, reason)`` of every such answer of this exchange in the order of
        ``frames`` (so the caller's bookkeeping does not depend on arrival order).
        The caller applies its policy (``simulator.core``: hold the last valid
        command, failsafe after K in a row); the step never waits for a timeout
        because an answer was refused.

        ``partial=False``: raises PeerTimeoutError(sysid, step) if a companion does
        not answer within ``timeout_s`` (default: the constructor's), and
        PeerMissingError if one never said hello.

        ``partial=True``: never raises for a companion.  Returns the setpoints
        that arrived; :attr:`last_missing` lists the sysids of ``frames`` without
        one.  A companion that misses a step is marked *lost*
        (:attr:`lost_peers`): later exchanges still send it its frame and take
        its answer if it comes while the others are awaited, but do not wait for
        it, so one dead companion does not slow the rest.  It is waited for again
        once it shows life: any valid setpoint (even a late one), or an ARM
        command (a restarted companion: HEARTBEAT from a new address, then ARM).
        """
        self.send_frames(frames, partial=partial)
        if while_waiting is not None:
            while_waiting()
        return self.collect(timeout_s, partial=partial, on_setpoint=on_setpoint)

    def send_frames(self, frames: Mapping[int, SensorFrame] | Iterable[tuple[int, SensorFrame]], *,
                    partial: bool = False) -> None:
        """The first half of :meth:`exchange`: send each companion its frame (``partial`` as
        there) and return at once. :meth:`collect` later waits for the answers; in between the
        caller may step physics while the companions compute
        (``[flight_controller].actuation_delay_steps``, docs/flight_controller.md)."""
        link = self._require_open()
        expected: dict[int, int] = {}
        pairs = frames.items() if isinstance(frames, Mapping) else frames
        if not partial:  # every peer must be known and have said hello before anything is sent
            pairs = list(pairs)
            for sysid, _ in pairs:
                if self._peer(sysid).addr is None:
                    raise PeerMissingError([sysid], 0.0, "HEARTBEAT (call wait_for_peers first)")
        for sysid, frame in pairs:
            peer = self._peer(sysid)
            peer.batch = codec.sensor_frame_payloads(frame, self.scenario.scenario_id)
            expected[sysid] = frame.step
            if peer.addr is not None:
                link.send(peer.addr, peer.encoder.pack_payloads(peer.batch))
            peer.last_step, peer.last_time_s = frame.step, frame.time_s
        self._expected = expected

    def collect(self, timeout_s: float | None = None, *, partial: bool = False,
                on_setpoint: Callable[[int, TorqueSetpoint | AttitudeSetpoint], None] | None = None,
                ) -> dict[int, TorqueSetpoint | AttitudeSetpoint]:  # fmt: skip
        """The second half of :meth:`exchange`: wait for the setpoints answering the frames
        of the last :meth:`send_frames` (re-sending, timing out and refusing as described
        there) and return them."""
        link = self._require_open()
        timeout = self.timeout_s if timeout_s is None else timeout_s
        expected, self._expected = self._expected, {}
        results: dict[int, TorqueSetpoint | AttitudeSetpoint] = {}
        refused: dict[int, str] = {}  # sysid -> why its answer to this step was rejected
        start = time.monotonic()
        deadline, interval = start + timeout, self.retry_s
        next_retry = start + interval
        polled = False  # read the socket at least once, even with timeout 0
        while True:
            awaited = self._awaited(expected, partial).difference(refused)
            if awaited.issubset(results):
                break
            now = time.monotonic()
            if now >= deadline and polled:
                if not partial:
                    missing = sorted(awaited.difference(results))
                    self.last_missing = tuple(missing)
                    raise PeerTimeoutError(missing[0], expected[missing[0]], timeout, missing)
                for s in awaited.difference(results):
                    self._peers[s].lost = True
                    self.stats.peers_lost += 1
                break
            if now >= next_retry:
                for s in awaited.difference(results):
                    peer = self._peers[s]
                    if peer.addr is not None:
                        link.send(peer.addr, peer.encoder.pack_payloads(peer.batch))
                        self.stats.retransmits += 1
                interval = min(2 * interval, _MAX_BACKOFF * self.retry_s)
                next_retry = now + interval
            polled = True
            for data, addr in link.recv(min(deadline, next_retry) - now):
                for sysid, sp_step, sp, att in self._handle(data, addr):
                    step = expected.get(sysid)
                    if step is None or sp_step < step:
                        self.stats.stale_setpoints += 1
                    elif sp_step > step:
                        self.stats.wrong_step_setpoints += 1
                    elif sysid in results or sysid in refused:
                        self.stats.duplicate_setpoints += 1
                    elif sp is None:  # a rejected answer (att: the reason)
                        refused[sysid] = att
                    else:
                        results[sysid] = sp
                        if att is not None:
                            self.attitude_targets[sysid] = att
                        if on_setpoint is not None:
                            on_setpoint(sysid, sp)
        for peer in self._peers.values():
            peer.batch = None
        self.last_rejected = tuple((s, refused[s]) for s in expected if s in refused)
        self.last_missing = tuple(sorted(set(expected).difference(results)))
        return results

    def _peer(self, sysid: int) -> _Peer:
        peer = self._peers.get(sysid)
        if peer is None:
            raise ValueError(f"sysid {sysid} is not one of {self.sysids}")
        return peer

    def _awaited(self, expected: dict[int, int], partial: bool) -> set[int]:
        if not partial:
            return set(expected)
        return {s for s in expected if not self._peers[s].lost and self._peers[s].addr is not None}

    # -- receive path ----------------------------------------------------------
    def _handle(self, data: bytes, addr: tuple[str, int]) -> list[tuple]:
        """Decode one datagram; answer control messages; return its setpoints as
        ``(sysid, step, setpoint, attitude target or None)``, and its rejected setpoints
        from the peer's own address as ``(sysid, step, None, reason)``."""
        out = []
        # SET_ATTITUDE_TARGET pairs with the setpoint of its datagram; on a stream, with the next setpoint
        stream = type(addr) is StreamPeer
        attitude: dict[int, tuple] = {}
        # bodies: codec.READERS tuples for the lockstep ids, pymavlink messages for the rest
        for mid, sysid, compid, body in self._decoder.feed_records(data):
            peer = self._peers.get(sysid)
            if peer is None:
                self.stats.unknown_sysid += 1
                continue
            if mid in (_SETPOINT, _JOINT_SETPOINT):  # the address may move only for a valid setpoint
                if stream:
                    att, peer.attitude = peer.attitude, None
                else:
                    att = attitude.pop(peer.sysid, None)
                if not self._admit(peer, addr, mid, move=False):
                    continue
                got, reason = self._setpoint(mid, body, att)
                if got is None:
                    self.stats.rejected_setpoints += 1
                    self.last_rejection = (peer.sysid, reason)
                    if peer.addr != addr:  # a refused packet never moves a peer nor answers for it
                        self.stats.wrong_address += 1
                        continue
                    peer.lost = False  # it answered: alive, if not well
                    out.append((peer.sysid, body[0], None, reason))
                    continue
                if peer.addr != addr:
                    self._move(peer, addr, mid)
                peer.lost = False  # it is alive
                out.append((peer.sysid, body[0], *got))
                continue
            if not self._admit(peer, addr, mid, move=mid != _ATTITUDE):
                continue
            if mid == _HEARTBEAT:
                self._link.send(addr, peer.encoder.pack([*self._hello_msgs, codec.scenario_message(self.scenario)]))
                if self.on_heartbeat is not None:
                    self.on_heartbeat(sysid, compid, body)
            elif mid == _COMMAND_LONG:
                self._on_command(peer, body)
            elif mid == _ATTITUDE:  # paired with the setpoint, which decides on the address
                if stream:
                    peer.attitude = body
                else:
                    attitude[peer.sysid] = body
            else:  # pragma: no cover - the decoder only lets _ACCEPT through
                self.stats.ignored += 1
        return out

    def _admit(self, peer: _Peer, addr: tuple[str, int], mid: int, move: bool = True) -> bool:
        """Address policy (see the class docstring); True if the packet may be used.
        ``move=False``: a packet from another address that may move the peer only once it
        proves valid (a setpoint, a SET_ATTITUDE_TARGET) is admitted without moving it."""
        now = time.monotonic()
        if peer.addr == addr:
            peer.last_heard = now
            return True
        if not self.signing and (
            mid != _HEARTBEAT or (peer.addr is not None and not peer.lost and now - peer.last_heard < REJOIN_QUIET_S)
        ):
            self.stats.wrong_address += 1
            return False
        if move:
            self._move(peer, addr, mid)
        return True

    def _move(self, peer: _Peer, addr: tuple[str, int], mid: int) -> None:
        peer.last_heard = time.monotonic()
        if peer.addr is not None:
            self.stats.address_changes += 1
            if mid == _HEARTBEAT:
                self.stats.rejoins += 1
                peer.armed = False
        peer.addr = addr

    def _setpoint(self, mid: int, fields: tuple, att_fields: tuple | None) -> tuple[tuple | None, str | None]:
        """((setpoint, attitude target or None), None) for a valid setpoint, else (None, why)."""
        try:
            if mid == _JOINT_SETPOINT:  # attitude mode: the target is part of the setpoint
                if att_fields is None:
                    raise codec.BatchMismatchError(f"step {fields[0]}: AM_JOINT_TORQUE_SETPOINT without "
                                                   f"SET_ATTITUDE_TARGET")  # fmt: skip
                sp = codec.attitude_setpoint_from_fields(att_fields, fields)
                att = sp.attitude
            else:
                sp = codec.setpoint_from_fields(fields)
                att = codec.attitude_from_fields(att_fields, sp.step) if att_fields is not None else None
            reason = self.limits.violation(sp)
        except codec.NonFiniteValueError as exc:
            self.stats.nonfinite_values += 1
            reason = str(exc)
        except ValueError as exc:  # CodecError is one
            reason = str(exc)
        if reason is None:
            return (sp, att), None
        return None, reason

    def _on_command(self, peer: _Peer, msg) -> None:
        if msg.target_system not in (0, SIM_SYSID):
            self.stats.ignored += 1
            return
        if msg.command == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            peer.armed = msg.param1 >= 0.5
            peer.lost = peer.lost and not peer.armed  # a (re)armed companion is alive
            result = mav.MAV_RESULT_ACCEPTED
        elif msg.command == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            # a message of the sensor batch: recorded and accepted; the lockstep sends the batch
            # every control step whatever the interval (docs/flight_controller.md, "Rates")
            msgid = int(msg.param1)
            if msgid in STREAMED and msg.param2 > 0:
                peer.intervals[msgid] = float(msg.param2)
                result = mav.MAV_RESULT_ACCEPTED
            else:
                result = mav.MAV_RESULT_DENIED
        else:
            result = mav.MAV_RESULT_UNSUPPORTED
        ack = mav.MAVLink_command_ack_message(msg.command, result, 0, 0, peer.sysid, msg.get_srcComponent())
        self._link.send(peer.addr, peer.encoder.pack([ack]))

    def _require_open(self) -> Mux:
        if self._link is None:
            raise RuntimeError("SimServer is not open; call open() first")
        return self._link


def waiting_notice(what: str, sysids: Sequence[int], remaining_s: float) -> str:
    """What the simulator says while it gathers its companions: ``waiting 58 s more for ARM
    from sysid 5`` (it fits a STATUSTEXT for up to about six sysids; the rest is cut)."""
    who = "sysid" + ("s " if len(sysids) > 1 else " ") + ", ".join(map(str, sysids))
    return f"{WAITING_NOTICE_PREFIX}{remaining_s:.0f} s more for {what} from {who}"
