"""Companion end of the lockstep link (see :mod:`amlink.lockstep` for the protocol)."""

from __future__ import annotations

import re
import time
from collections import deque

from amlink import codec
from amlink.codec import mav
from amlink.endpoint import UDP_IN, UDP_OUT, Endpoint, as_destination, parse_endpoint
from amlink.errors import CommandRejectedError, LinkError, SimulatorTimeoutError, SimulatorUnreachableError
from amlink.protocol import (
    COMMAND_RETRY_S,
    COMPANION_COMPID,
    HEARTBEAT_PERIOD_S,
    RUN_HEARTBEAT_PERIOD_S,
    SIM_COMPID,
    SIM_SYSID,
    WAITING_NOTICE_PREFIX,
    LinkStats,
)
from amlink.transport import Shim, open_transport
from amlink.types import (
    DEFAULT_SENSOR_LIMITS,
    AttitudeSetpoint,
    AttitudeTarget,
    ScenarioInfo,
    SensorFrame,
    SensorLimits,
    TorqueSetpoint,
)

_HEARTBEAT = mav.MAVLINK_MSG_ID_HEARTBEAT
_SCENARIO = mav.MAVLINK_MSG_ID_AM_SCENARIO
_OBJECT_POSE = mav.MAVLINK_MSG_ID_AM_OBJECT_POSE
_ACK = mav.MAVLINK_MSG_ID_COMMAND_ACK
_STATUSTEXT = mav.MAVLINK_MSG_ID_STATUSTEXT
_SIM_STEP = mav.MAVLINK_MSG_ID_AM_SIM_STEP
_SENSOR_PART_IDS = frozenset(
    (mav.MAVLINK_MSG_ID_ODOMETRY, mav.MAVLINK_MSG_ID_AM_JOINT_STATE, mav.MAVLINK_MSG_ID_AM_WRENCH,
     mav.MAVLINK_MSG_ID_ATTITUDE_TARGET)  # ATTITUDE_TARGET: attitude mode's report of the flown target
)
_ACCEPT = (_HEARTBEAT, _SCENARIO, _OBJECT_POSE, _ACK, _STATUSTEXT, _SIM_STEP, *_SENSOR_PART_IDS)
_MAX_TEXTS = 256
_MAX_ACKS = 64


class EndpointOpenError(SimulatorUnreachableError):
    """Companion side: the simulator's endpoint could not be opened (no such serial device,
    an unknown host, an address in use) or, as a TCP client, connected to within the
    timeout. Nothing reached the simulator: it is not its answer (or a signing key) that
    is missing. ``why`` is the operating system's reason."""

    def __init__(self, address: str, why: str, timeout_s: float | None = None):
        self.address = address
        self.why = why
        self.timeout_s = timeout_s  # None: it failed at once
        self.listening = False
        LinkError.__init__(self, f"cannot open {address}: {why}" if timeout_s is None
                           else f"cannot connect to {address} within {timeout_s:.3g} s: {why}")


def _os_reason(exc: OSError | str) -> str:
    """The OS error without Python's '[Errno N]' and the repeated file name."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return re.sub(r"^\[Errno -?\d+\] ", "", str(exc))


class CompanionClient:
    """Companion end of the lockstep link for vehicle ``sysid``.

    Args:
        sysid: this companion's MAVLink system id (2..255).
        sim: the flight controller's (simulator's) endpoint, mavutil's forms
            (:mod:`amlink.endpoint`): ``"udpout:HOST:PORT"`` sends to it;
            ``"udp:HOST:PORT"`` is read the same way (this API's older form, kept);
            ``"udpin:HOST:PORT"`` listens until it speaks (``udpout:`` on its side);
            ``"tcp:HOST:PORT"``, ``"tcpin:HOST:PORT"``, or a serial device
            ``"/dev/ttyUSB0:921600"``.
        compid: MAVLink component id, 191 = MAV_COMP_ID_ONBOARD_COMPUTER.
        signing_key: ``None`` -- signing off (default at this API level).  Else this
            vehicle's 32-byte key: everything sent is signed (link id = sysid) and
            only packets signed by the simulator with this key are accepted.
        limits: plausibility bounds a sensor frame must meet to be handed on.
        shim: send-path impairment hook of :class:`amlink.transport.Udp` (tests).
        tlog: an open :class:`amlink.tlog.TlogWriter` that gets every frame sent and
            received, or None.

    The companion says HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER) every
    ``RUN_HEARTBEAT_PERIOD_S`` while connected, as a companion computer does; the
    simulator forwards it to its GCS link.

    Messages that arrive while waiting for something else (a sensor batch
    while :meth:`arm` waits for its ACK, say) are kept, never dropped.

    Each step's frame is handed out once.  A copy of a frame for a step already
    handed out (the simulator re-sends a batch whose answer it did not get) is
    not handed out again; if that step was answered, the cached answer is re-sent
    instead -- so loss changes neither what the controller sees nor what it sends.

    Signing off, once AM_SCENARIO arrived only datagrams from the address it came
    from are read (``wrong_address`` counts the rest); signing on, the signature
    decides and the source address does not matter.
    """

    def __init__(self, sysid: int, sim: str | Endpoint = "udpout:127.0.0.1:14550",
                 compid: int = COMPANION_COMPID, *, signing_key: bytes | None = None,
                 limits: SensorLimits = DEFAULT_SENSOR_LIMITS, shim: Shim | None = None,
                 tlog=None) -> None:  # fmt: skip
        if not 2 <= sysid <= 255:
            raise ValueError(f"sysid {sysid} must be in 2..255 (1 is the simulator)")
        self.sysid = sysid
        self.compid = compid
        ep = sim if isinstance(sim, Endpoint) else parse_endpoint(sim)
        if ep.alias == "udp":  # the companion's --sim udp: has always meant "send to"
            ep = as_destination(ep)
        self.endpoint = ep
        self.sim = sim.strip() if isinstance(sim, str) else str(ep)  # as written, for messages
        self._tlog = tlog
        self.limits = limits
        self.stats = LinkStats()
        self.scenario: ScenarioInfo | None = None
        self.object_pose: tuple | None = None  # ((x, y, z) [m, W], yaw [rad]) if the simulator sent AM_OBJECT_POSE
        self.status_texts: deque[tuple[int, str]] = deque(maxlen=_MAX_TEXTS)  # (MAV_SEVERITY, text), latest
        # the simulator's last "still gathering companions" notice: (time.monotonic(), text), or None
        self.waiting_notice: tuple[float, str] | None = None
        self._shim = shim
        self._link = None  # the transport (amlink.transport), once connected
        self._sim_addr = None  # where we send: the simulator's address, or its stream connection
        self._sim_rx_addr: tuple[str, int] | None = None  # signing off: the only source we read
        self._encoder = codec.Encoder(sysid, compid, signing_key=signing_key, link_id=sysid)
        keys = None if signing_key is None else {SIM_SYSID: signing_key}
        self._decoder = codec.Decoder(keys, accept=_ACCEPT, counters=self.stats, readers=codec.READERS)
        self._frames = codec.SensorFrameAssembler()
        self._inbox: deque[SensorFrame | codec.Shutdown] = deque()
        self._acks: deque = deque(maxlen=_MAX_ACKS)
        self._shutdown = False  # recv_frame has returned None
        self._shutdown_seen = False  # a SHUTDOWN arrived; the rest of the traffic is ignored
        self._newest_step = -1  # newest step queued or handed out
        self._answer: tuple[int, tuple] | None = None  # (step, (msgid, payload)s) of the last setpoint sent
        self._last_time_s = 0.0
        self._next_beat = 0.0  # time.monotonic() of the next HEARTBEAT once connected
        self._heartbeat = mav.MAVLink_heartbeat_message(
            mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE, 3)

    @property
    def signing(self) -> bool:
        return self._decoder.signing

    def connect(self, timeout_s: float = 5.0) -> ScenarioInfo:
        """Open the endpoint and say HEARTBEAT at 2 Hz until the simulator answers AM_SCENARIO.

        Listening (udpin, tcpin) it first waits for the simulator to speak (or connect);
        as a TCP client it retries connecting.  Raises SimulatorUnreachableError naming
        the endpoint after ``timeout_s``; its subclass EndpointOpenError at once if the
        endpoint cannot be opened, or after ``timeout_s`` if a TCP connection never got
        through (nothing was sent, so no HEARTBEAT went unanswered).
        """
        if self._link is not None:
            raise RuntimeError("CompanionClient is already connected")
        try:
            self._link = open_transport(self.endpoint, self.stats, shim=self._shim, client=True)
        except OSError as exc:
            raise EndpointOpenError(self.sim, _os_reason(exc)) from exc
        self._sim_addr = self._link.peer if self.endpoint.kind == UDP_OUT else None
        deadline = time.monotonic() + timeout_s
        next_beat = 0.0
        try:
            while self.scenario is None:
                now = time.monotonic()
                if now >= deadline:
                    detail = getattr(self._link, "last_error", "")
                    if detail and self._dest() is None:  # a TCP client that never connected
                        raise EndpointOpenError(self.sim, _os_reason(detail), timeout_s)
                    raise SimulatorUnreachableError(self.sim, timeout_s, detail,
                                                    listening=self.endpoint.listens and self._dest() is None)
                if now >= next_beat and self._dest() is not None:
                    self._send([self._heartbeat])
                    next_beat = now + HEARTBEAT_PERIOD_S
                self._pump(min(deadline, next_beat if self._dest() is not None else now + 0.05) - now)
        except BaseException:
            self.close()
            raise
        self._next_beat = time.monotonic() + RUN_HEARTBEAT_PERIOD_S
        return self.scenario

    @property
    def local_address(self) -> tuple[str, int]:
        """The ``(host, port)`` this companion's UDP socket is bound to (after connect)."""
        return self._require_connected().sock.getsockname()

    def arm(self, timeout_s: float = 1.0, arm: bool = True) -> None:
        """COMMAND_LONG(MAV_CMD_COMPONENT_ARM_DISARM) until COMMAND_ACK (retried every 0.25 s).

        Raises CommandRejectedError if not accepted, SimulatorTimeoutError on timeout.
        """
        self._command(mav.MAV_CMD_COMPONENT_ARM_DISARM, (1.0 if arm else 0.0,), timeout_s, "ARM_DISARM")

    def set_message_interval(self, msgid: int, interval_us: float, timeout_s: float = 1.0) -> None:
        """COMMAND_LONG(MAV_CMD_SET_MESSAGE_INTERVAL): stream message `msgid` every `interval_us`
        [us], as a companion asks PX4 for ODOMETRY or ATTITUDE_TARGET faster than its defaults.
        Raises CommandRejectedError if not accepted, SimulatorTimeoutError on timeout."""
        self._command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, (float(msgid), float(interval_us)), timeout_s,
                      "SET_MESSAGE_INTERVAL")

    def _command(self, cmd: int, params: tuple[float, ...], timeout_s: float, what: str) -> None:
        """COMMAND_LONG `cmd` with `params` (the rest 0) until its COMMAND_ACK, retried every 0.25 s."""
        self._require_connected()
        p = (*params, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)[:7]
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
                raise SimulatorTimeoutError(f"COMMAND_ACK for {what}", timeout_s)
            if now >= next_try:
                self._send([mav.MAVLink_command_long_message(SIM_SYSID, SIM_COMPID, cmd, confirmation, *p)])
                next_try, confirmation = now + COMMAND_RETRY_S, min(confirmation + 1, 255)
            self._pump(min(deadline, next_try) - now)

    def recv_frame(self, timeout_s: float = 1.0, on_waiting=None) -> SensorFrame | None:
        """Newest sensor frame not yet returned, or None once the simulator announced shutdown.

        Before the first frame, a simulator still gathering its other companions says so every
        few seconds (:data:`amlink.protocol.WAITING_NOTICE_PREFIX`); ``timeout_s`` then counts from
        its last notice, so a companion waits as long as its simulator does, and
        ``on_waiting(text)``, if given, gets each notice.

        In lockstep at most one frame is pending.  A backlog (the simulator ran on
        while this companion did not answer, e.g. before it rejoined) is passed
        over to its newest frame, counted in ``stats.skipped_frames``: answering
        stale states one by one would only keep it behind.  Invalid batches
        (non-finite, implausible, wrong scenario) are dropped and counted in
        :attr:`stats`, never returned.  Raises SimulatorTimeoutError after
        ``timeout_s``.
        """
        self._require_connected()
        start = time.monotonic()
        deadline = start + timeout_s
        polled = False  # poll the socket at least once, even with timeout_s = 0
        seen = self.waiting_notice
        while not self._shutdown:
            if self.waiting_notice is not seen and self._newest_step < 0:
                seen = self.waiting_notice
                deadline = max(deadline, seen[0] + timeout_s)
                if on_waiting is not None:
                    on_waiting(seen[1])
            if self._inbox:
                item = self._inbox.popleft()
                if isinstance(item, codec.Shutdown):
                    self._shutdown = True
                    break
                while self._inbox and not isinstance(self._inbox[0], codec.Shutdown):
                    item = self._inbox.popleft()
                    self.stats.skipped_frames += 1
                self._last_time_s = item.time_s
                return item
            remaining = deadline - time.monotonic()
            if remaining <= 0 and polled:
                if seen is not None and self._newest_step < 0:
                    raise SimulatorTimeoutError(f"sensor frame and no word (its last: '{seen[1]}')", timeout_s)
                raise SimulatorTimeoutError("sensor frame", timeout_s)
            self._pump(remaining)
            polled = True
        return None

    def send_setpoint(self, setpoint: TorqueSetpoint | AttitudeSetpoint, attitude: AttitudeTarget | None = None) -> None:
        """Send the answer to step ``setpoint.step`` (one datagram); kept for re-sending.
        An :class:`AttitudeSetpoint` carries its own target (``attitude`` is not used)."""
        time_boot_ms = round(self._last_time_s * 1e3)
        if isinstance(setpoint, AttitudeSetpoint):
            payloads = codec.attitude_setpoint_payloads(setpoint, time_boot_ms, SIM_SYSID, SIM_COMPID)
        else:
            payloads = codec.setpoint_payloads(setpoint, attitude, time_boot_ms, SIM_SYSID, SIM_COMPID)
        self._send_payloads(payloads)
        self._answer = (setpoint.step, payloads)

    def close(self) -> None:
        if self._link is not None:
            self._link.close()
            self._link = None

    def __enter__(self) -> CompanionClient:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- the one send path and the one receive path ------------------------------
    def _require_connected(self):
        if self._link is None:
            raise RuntimeError("CompanionClient is not connected; call connect() first")
        return self._link

    def _dest(self):
        """Where to send: the simulator's UDP address, or the stream's far end (None: unknown yet)."""
        return self._sim_addr if self._sim_addr is not None else self._link.peer

    def _send(self, msgs) -> None:
        """Send pymavlink messages (handshake, commands) as one datagram."""
        self._out(self._encoder.pack(msgs))

    def _send_payloads(self, payloads) -> None:
        """Send a batch of :mod:`amlink.codec` payloads as one datagram."""
        self._out(self._encoder.pack_payloads(payloads))

    def _out(self, data: bytes) -> None:
        link = self._require_connected()
        dest = self._dest()
        if dest is None:
            self.stats.send_drops += 1
            return
        link.send(dest, data)
        if self._tlog is not None:
            self._tlog.write(data)

    def _pump(self, timeout_s: float) -> None:
        link = self._require_connected()
        resend = False
        for data, addr in link.recv(timeout_s):
            if self._sim_rx_addr is not None and addr != self._sim_rx_addr and not self.signing:
                self.stats.wrong_address += 1
                continue
            if not link.stream:
                self._frames.reset()  # a sensor batch is one datagram
            if self._tlog is not None:
                self._tlog.write(data)
            records = self._decoder.feed_records(data)
            if records and self._sim_addr is None and self.endpoint.kind == UDP_IN and records[0][1] == SIM_SYSID:
                self._sim_addr = addr  # listening: the simulator spoke (authentic, signing on)
            for record in records:
                resend |= self._on_message(record, addr)
        if resend and self._answer is not None:
            self._send_payloads(self._answer[1])  # re-framed: a new sequence number and signing timestamp
            self.stats.retransmits += 1
        if self.scenario is not None and time.monotonic() >= self._next_beat:
            self._next_beat = time.monotonic() + RUN_HEARTBEAT_PERIOD_S
            self._send([self._heartbeat])

    def _on_message(self, record, addr) -> bool:
        """Handle one decoder record; True if it asks for the last answer again.

        ``body`` is a :data:`amlink.codec.READERS` tuple for the sensor batch
        ids, a pymavlink message for the rest.
        """
        mid, sysid, _compid, body = record
        if sysid != SIM_SYSID:
            self.stats.unknown_sysid += 1
            return False
        if self._shutdown_seen:
            self.stats.ignored += 1
            return False
        if mid == _HEARTBEAT:
            return False  # the simulator's hello to a listening companion; its address is learned in _pump
        if mid == _SCENARIO:
            if self.scenario is None:
                try:
                    self.scenario = codec.scenario_from_message(body)
                except ValueError as exc:  # NonFiniteValueError, bad name, rate <= 0
                    self._reject(exc)
                    return False
                self._sim_rx_addr = addr
        elif mid == _OBJECT_POSE:  # comes just before AM_SCENARIO, in the same datagram
            try:
                self.object_pose = codec.object_pose_from_message(body)
            except ValueError as exc:
                self._reject(exc)
        elif mid == _ACK:
            self._acks.append(body)
        elif mid == _STATUSTEXT:
            self.status_texts.append((body.severity, body.text))
            if body.text.startswith(WAITING_NOTICE_PREFIX):
                self.waiting_notice = (time.monotonic(), body.text)
        elif mid == _SIM_STEP and self.scenario is not None and body[2] != self.scenario.scenario_id:
            self.stats.rejected_frames += 1  # body[2]: AM_SIM_STEP.scenario_id
            self._frames.reset()
        else:
            try:
                item = self._frames.push(mid, body)
            except ValueError as exc:  # CodecError: non-finite, mismatched or incomplete batch
                self._reject(exc)
                return False
            if item is None:
                if mid not in _SENSOR_PART_IDS:
                    self.stats.ignored += 1
            elif isinstance(item, codec.Shutdown):
                self._shutdown_seen = True
                self._inbox.append(item)
            elif self.limits.violation(item) is not None:
                self.stats.rejected_frames += 1
            elif item.step <= self._newest_step:
                self.stats.duplicate_frames += 1
                return self._answer is not None and self._answer[0] == item.step
            else:
                self._newest_step = item.step
                self._inbox.append(item)
        return False

    def _reject(self, exc: Exception) -> None:
        self.stats.rejected_frames += 1
        if isinstance(exc, codec.NonFiniteValueError):
            self.stats.nonfinite_values += 1
