"""The companion's link to a PX4 autopilot: standard MAVLink 2 (common.xml) on the wall clock.

A thin adapter (nothing happens in the constructor; :meth:`Px4Link.open` opens the endpoint):

* receive: :meth:`poll` reads every pending frame without blocking (or waits up to
  ``timeout_s`` for the first), decodes what PX4 streams into ENU / FLU samples
  (:mod:`amlink.px4samples`) kept in a latest-sample store (:attr:`store`), answers the
  autopilot's TIMESYNC requests, resolves COMMAND_ACKs, and returns the events a handshake
  needs (:class:`HeartbeatEvent`, :class:`AckEvent`, :class:`StatusTextEvent`);
* time: its own TIMESYNC requests every ``1 / timesync_rate_hz`` (10 Hz, what PX4 streams on
  an onboard link) feed :attr:`timebase` (:class:`amlink.timebase.Timebase`);
* send: HEARTBEAT as (sysid, 191) MAV_TYPE_ONBOARD_CONTROLLER, SET_ATTITUDE_TARGET converted
  from ENU / FLU to NED / FRD (amlink.px4), COMMAND_LONG tracked to its COMMAND_ACK
  (:class:`PendingCommand`), SET_MESSAGE_INTERVAL;
* :meth:`attach` an :class:`amlink.offboard_handshake.OffboardHandshake`: every poll feeds it
  and sends what it says; every setpoint sent is reported to it.

Endpoints (amlink.endpoint): the default of vehicle ``i`` is :func:`default_endpoint`,
``udpin:0.0.0.0:14540+i``, listening as MAVSDK's ``udpin://0.0.0.0:14540`` does (PX4 SITL sends
to that port and answers whoever last sent to it, px4-rc.mavlink ``-o``); ``udpout:HOST:PORT``,
``tcp:HOST:PORT`` and serial devices work the same way.  Listening, nothing is sent before the
autopilot spoke (sends are counted in ``stats.send_drops``); its address is learned from its
first frame, and follows it if it moves.

Use (the control loop owns the timer)::

    link = Px4Link(sysid, default_endpoint(i)).open()
    hs = OffboardHandshake(control_streams(rate_hz))     # amlink.offboard_handshake
    link.attach(hs)
    while running:
        link.poll(timeout_s)                           # samples, TIMESYNC, ACKs; the handshake's sends
        odo = link.store.latest("odometry")            # Sample: .value (ENU/FLU), .fc_us, .rx_ns, ...
        link.send_attitude_target(q_WB, w_B, thrust)   # ENU/FLU in, NED/FRD on the wire
        if hs.state is State.ENGAGED: ...              # yielded / failed: stop

Only the autopilot, (sysid, MAV_COMP_ID_AUTOPILOT1), is read; frames of other systems count in
``stats.unknown_sysid``, other components' in ``stats.other_components``.  Malformed frames
(junk, bad CRC, unknown message ids, truncated) count in ``stats.bad_frames``, valid messages
this link does not use in ``stats.ignored``, non-finite samples in ``stats.nonfinite_values``,
malformed ones in ``stats.malformed``, ODOMETRY in a refused frame in ``stats.frame_refused``
(``last_refusal`` says which): none of them raises.
"""
from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from amlink import px4
from amlink import px4samples as ps
from amlink.endpoint import UDP_IN, UDP_OUT, Endpoint, parse_endpoint
from amlink.offboard_handshake import (ACCEPTED, IN_PROGRESS, MAV_CMD_SET_MESSAGE_INTERVAL, OffboardHandshake,
                                       SendCommand, SendHeartbeat, result_name)
from amlink.protocol import LinkStats
from amlink.timebase import Timebase
from amlink.transport import open_transport
from amlink.wire import Decoder, Encoder, mav

TIMESYNC_RATE_HZ = 10.0  # PX4's own TIMESYNC stream rate on an onboard link (mavlink_main.cpp)
_MAX_DRAINS = 16  # transport reads per poll (each drains up to 256 datagrams) before returning
_MAX_TEXTS = 256
_ID = {n: getattr(mav, f"MAVLINK_MSG_ID_{n}") for n in (
    "HEARTBEAT", "ODOMETRY", "ATTITUDE_QUATERNION", "ATTITUDE_TARGET", "HIGHRES_IMU", "EXTENDED_SYS_STATE",
    "SYS_STATUS", "STATUSTEXT", "COMMAND_ACK", "TIMESYNC")}


def default_endpoint(index: int) -> str:
    """The endpoint a PX4 program listens on for vehicle ``index`` (0-based [[am]] order)."""
    return f"udpin:0.0.0.0:{px4.onboard_port(index)}"


@dataclass
class Px4LinkStats(LinkStats):
    """LinkStats (transport, framing, signing) and this link's own counters."""

    other_components: int = 0  # frames of our system from components other than the autopilot
    malformed: int = 0  # samples with a non-unit quaternion or no timestamp
    frame_refused: int = 0  # ODOMETRY in frames other than PX4's
    out_of_order: int = 0  # samples not newer than the latest of their source
    acks_unmatched: int = 0  # COMMAND_ACKs for a command not pending, or addressed to someone else
    heartbeats_sent: int = 0
    setpoints_sent: int = 0
    commands_sent: int = 0
    timesync_sent: int = 0  # our requests
    timesync_answered: int = 0  # the autopilot's requests we answered


@dataclass(frozen=True)
class HeartbeatEvent:
    value: ps.AutopilotHeartbeat
    rx_ns: int
    fc_us: float | None  # rx_ns in autopilot time, None while the time base has no estimate


@dataclass(frozen=True)
class AckEvent:
    command: int
    result: int
    progress: int
    result_param2: int
    rx_ns: int


@dataclass(frozen=True)
class StatusTextEvent:
    severity: int  # MAV_SEVERITY: 0 emergency .. 7 debug
    text: str
    rx_ns: int


class PendingCommand:
    """A COMMAND_LONG until its ACK: ``result`` (MAV_RESULT, None until answered; IN_PROGRESS is not
    final), ``progress``, ``acked_ns``; ``superseded`` when a newer command of the same id was sent
    (an ACK names only the command id, so it resolves the newest)."""

    def __init__(self, command: int, params: tuple[float, ...], confirmation: int, sent_ns: int) -> None:
        self.command, self.params, self.confirmation, self.sent_ns = command, params, confirmation, sent_ns
        self.result: int | None = None
        self.progress: int | None = None
        self.acked_ns: int | None = None
        self.superseded = False

    @property
    def done(self) -> bool:
        return self.result is not None and self.result != IN_PROGRESS

    @property
    def accepted(self) -> bool:
        return self.result == ACCEPTED

    def __repr__(self) -> str:
        res = "pending" if self.result is None else result_name(self.result)
        return f"PendingCommand({self.command}, {res})"


class LinkOpenError(OSError):
    """The endpoint could not be opened; the message names it and the operating system's reason."""

    def __init__(self, endpoint: str, why: str) -> None:
        self.endpoint, self.why = endpoint, why
        super().__init__(f"cannot open {endpoint}: {why}")

    def __str__(self) -> str:
        return f"cannot open {self.endpoint}: {self.why}"


class SetpointError(ValueError):
    """A setpoint that cannot be sent; the message names the field."""


class Px4Link:
    """The link to the PX4 of vehicle ``sysid`` (module docstring).

    Args:
        sysid: the vehicle's MAVLink system id; the autopilot is (sysid, 1), this companion
            (sysid, 191).
        endpoint: where the autopilot is (an amlink.endpoint string or Endpoint);
            :func:`default_endpoint` gives PX4's.
        clock: monotonic ns (``time.monotonic_ns``), the time of every stamp.
        signing_key: 32 bytes: MAVLink 2 signing on (sent frames signed, only frames signed
            with this key read). None: off (PX4's onboard port default).
        tlog: an open :class:`amlink.tlog.TlogWriter` for every frame sent and received.
        timesync_rate_hz: TIMESYNC requests per second (0: none).
        limits: the store's staleness limits.
    """

    def __init__(self, sysid: int, endpoint: str | Endpoint, *, clock: Callable[[], int] = time.monotonic_ns,
                 signing_key: bytes | None = None, tlog=None, timesync_rate_hz: float = TIMESYNC_RATE_HZ,
                 limits: ps.StaleLimits = ps.StaleLimits(), timebase: Timebase | None = None) -> None:  # fmt: skip
        if not 1 <= int(sysid) <= 255:
            raise ValueError(f"sysid {sysid} must be in 1..255")
        if not (math.isfinite(timesync_rate_hz) and timesync_rate_hz >= 0):
            raise ValueError(f"timesync_rate_hz must be >= 0, got {timesync_rate_hz}")
        ep = endpoint if isinstance(endpoint, Endpoint) else parse_endpoint(endpoint)  # udp: listens, as mavutil
        self.sysid, self.endpoint, self.clock = int(sysid), ep, clock
        self._tlog = tlog
        self.stats = Px4LinkStats()
        self.timebase = timebase if timebase is not None else Timebase()
        self.store = ps.SampleStore(limits)
        self.status_texts: deque[StatusTextEvent] = deque(maxlen=_MAX_TEXTS)
        self.last_refusal: str | None = None
        self.last_rx_ns: int | None = None  # the autopilot's last frame
        self._ts_period_ns = round(1e9 / timesync_rate_hz) if timesync_rate_hz > 0 else None
        self._next_ts: int | None = None
        self._encoder = Encoder(self.sysid, px4.ONBOARD_COMPID, signing_key=signing_key, link_id=self.sysid)
        keys = None if signing_key is None else {self.sysid: signing_key}
        self._decoder = Decoder(keys, accept=_ID.values(), counters=self.stats)
        self._link = None
        self._dest = None
        self._opened_ns: int | None = None
        self._pending: dict[int, PendingCommand] = {}
        self._handshake: OffboardHandshake | None = None
        self._heartbeat = mav.MAVLink_heartbeat_message(
            mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID, 0, 0, mav.MAV_STATE_ACTIVE, 3)

    # -- lifetime ---------------------------------------------------------------------
    def open(self) -> Px4Link:
        """Open the endpoint; :class:`LinkOpenError` if it cannot be (a port in use, no such device)."""
        if self._link is not None:
            raise RuntimeError("Px4Link is already open")
        try:
            self._link = open_transport(self.endpoint, self.stats, client=True)
        except OSError as exc:
            raise LinkOpenError(str(self.endpoint), exc.strerror or str(exc)) from exc
        self._dest = self._link.peer if self.endpoint.kind == UDP_OUT else None
        self._opened_ns = self.clock()
        return self

    def close(self) -> None:
        if self._link is not None:
            self._link.close()
            self._link = None

    def __enter__(self) -> Px4Link:
        return self.open() if self._link is None else self

    def __exit__(self, *exc) -> None:
        self.close()

    def fileno(self) -> int:
        """The file descriptor to wait on (a UDP socket; a stream's listening or connected fd)."""
        fds = self._require_open().fds()
        if not fds:
            raise OSError("the link has no descriptor now (a serial port or TCP connection being reopened)")
        return fds[0]

    @property
    def local_address(self):
        """The (host, port) a UDP link is bound to."""
        sock = getattr(self._require_open(), "sock", None)
        if sock is None:
            raise AttributeError(f"local_address: {self.endpoint} is not a UDP endpoint")
        return sock.getsockname()

    @property
    def autopilot_heard(self) -> bool:
        return self.last_rx_ns is not None

    @property
    def peer(self):
        """Where frames go: the autopilot's address, None while unknown (listening, not yet heard)."""
        if self._link is None:
            return None
        return self._dest if self._dest is not None else self._link.peer

    def attach(self, handshake: OffboardHandshake) -> None:
        """Drive ``handshake`` from every :meth:`poll` and setpoint sent (module docstring)."""
        self._handshake = handshake

    # -- receive ------------------------------------------------------------------------
    def poll(self, timeout_s: float = 0.0) -> list:
        """Read every pending frame (waiting up to ``timeout_s`` for the first), answer TIMESYNC,
        send our own when due, drive an attached handshake; the events received, in order."""
        link = self._require_open()
        events: list = []
        wait = max(0.0, float(timeout_s))
        for _ in range(_MAX_DRAINS):
            got = link.recv(wait)
            wait = 0.0
            if not got:
                break
            rx = self.clock()
            for data, addr in got:
                self._on_datagram(data, addr, rx, events)
        now = self.clock()
        self._timesync_due(now)
        if self._handshake is not None:
            self._drive(events, now)
        return events

    def _on_datagram(self, data: bytes, addr, rx: int, events: list) -> None:
        if self._tlog is not None:
            self._tlog.write(data)
        for m in self._decoder.feed(data):
            sysid, compid = m.get_srcSystem(), m.get_srcComponent()
            if sysid != self.sysid:
                self.stats.unknown_sysid += 1
                continue
            if compid != px4.PX4_COMPID:
                self.stats.other_components += 1
                continue
            if self.endpoint.kind == UDP_IN and addr != self._dest:
                if self._dest is not None:
                    self.stats.address_changes += 1
                self._dest = addr
            self.last_rx_ns = rx
            try:
                self._on_message(m, rx, events)
            except ps.NonFiniteSample:
                self.stats.nonfinite_values += 1
            except ps.FrameRefused as exc:
                self.stats.frame_refused += 1
                self.last_refusal = str(exc)
            except ps.SampleError:
                self.stats.malformed += 1
            except (AttributeError, TypeError, ValueError):  # a message pymavlink decoded oddly
                self.stats.malformed += 1

    def _on_message(self, m, rx: int, events: list) -> None:
        mid = m.get_msgId()
        if mid == _ID["TIMESYNC"]:
            if m.tc1 == 0:  # the autopilot asks: our time now, its ts1 back (MavlinkTimesync)
                self._send([mav.MAVLink_timesync_message(self.clock(), m.ts1)])
                self.stats.timesync_answered += 1
            else:
                self.timebase.on_answer(m.tc1, m.ts1, rx)
        elif mid == _ID["ODOMETRY"]:
            v = ps.odometry_of(m)
            self._put("odometry", v, v.t_us, rx)
        elif mid == _ID["ATTITUDE_QUATERNION"]:
            v = ps.attitude_of(m)
            self._put("attitude", v, v.t_us, rx)
        elif mid == _ID["HIGHRES_IMU"]:
            v = ps.imu_of(m)
            self._put("imu", v, v.t_us, rx)
        elif mid == _ID["ATTITUDE_TARGET"]:
            t_us, v = ps.attitude_target_of(m)
            self._put("attitude_target", v, t_us, rx)
        elif mid == _ID["HEARTBEAT"]:
            v = ps.heartbeat_of(m)
            self.store.put("heartbeat", v, None, rx)
            events.append(HeartbeatEvent(v, rx, self.timebase.fc_time_us(rx)))
        elif mid == _ID["EXTENDED_SYS_STATE"]:
            self.store.put("extended_sys_state", ps.extended_sys_state_of(m), None, rx)
        elif mid == _ID["SYS_STATUS"]:
            self.store.put("sys_status", ps.sys_status_of(m), None, rx)
        elif mid == _ID["STATUSTEXT"]:
            text = m.text if isinstance(m.text, str) else bytes(m.text).split(b"\0", 1)[0].decode("utf-8", "replace")
            e = StatusTextEvent(int(m.severity), text, rx)
            self.status_texts.append(e)
            events.append(e)
        elif mid == _ID["COMMAND_ACK"]:
            if m.target_system not in (0, self.sysid) or m.target_component not in (0, px4.ONBOARD_COMPID):
                self.stats.acks_unmatched += 1
                return
            p = self._pending.get(m.command)
            if p is None or p.done:
                self.stats.acks_unmatched += 1
            else:
                p.result, p.progress, p.acked_ns = int(m.result), int(m.progress), rx
            events.append(AckEvent(int(m.command), int(m.result), int(m.progress), int(m.result_param2), rx))

    def _put(self, source: str, value, fc_us: int, rx: int) -> None:
        if self.store.put(source, value, fc_us, rx) is None:
            self.stats.out_of_order += 1

    # -- send -----------------------------------------------------------------------------
    def send_heartbeat(self) -> None:
        """HEARTBEAT as (sysid, 191): MAV_TYPE_ONBOARD_CONTROLLER, MAV_AUTOPILOT_INVALID, MAV_STATE_ACTIVE."""
        self._send([self._heartbeat])
        self.stats.heartbeats_sent += 1

    def send_attitude_target(self, q_WB_wxyz_enu_flu, rates_B_flu_rad_s, thrust_normalized: float,
                             type_mask: int = px4.IGNORE_BODY_RATES) -> None:  # fmt: skip
        """SET_ATTITUDE_TARGET to (sysid, 1): attitude q_WB (w x y z, ENU <- FLU; a unit quaternion
        unless IGNORE_ATTITUDE), body rates [rad/s, FLU], collective thrust in [0, 1] (PX4 flies
        thrust_body z = -thrust for a multicopter), ``type_mask`` amlink.px4's bits (default: the
        rates ignored, as MAVSDK's set_attitude).  Sent in NED / FRD.  SetpointError if a value
        cannot be sent (nothing is sent then)."""
        q = _floats("q_WB_wxyz_enu_flu", q_WB_wxyz_enu_flu, 4)
        w = _floats("rates_B_flu_rad_s", rates_B_flu_rad_s, 3)
        thrust = _floats("thrust_normalized", (thrust_normalized,), 1)[0]
        mask = int(type_mask)
        if mask != type_mask or not 0 <= mask <= 255:
            raise SetpointError(f"type_mask {type_mask!r} is not a uint8")
        if mask & px4.THRUST_BODY_SET:
            raise SetpointError("type_mask THRUST_BODY_SET: this dialect's SET_ATTITUDE_TARGET has no thrust_body; "
                                "send the collective thrust")
        if not mask & px4.IGNORE_ATTITUDE:
            n = math.sqrt(sum(x * x for x in q))
            if abs(n - 1.0) > 1e-6:
                raise SetpointError(f"q_WB_wxyz_enu_flu has norm {n:.9g}, not a unit quaternion")
        if not 0.0 <= thrust <= 1.0:
            raise SetpointError(f"thrust_normalized {thrust!r} is outside [0, 1]")
        q_ned = px4.q_enu_flu_to_ned_frd(q)
        w_frd = px4.flu_to_frd(w)
        now = self.clock()
        fc = self.timebase.fc_time_us(now)
        t_ms = (round(fc / 1000.0) if fc is not None else (now - (self._opened_ns or now)) // 1_000_000) & 0xFFFFFFFF
        if not self._send([mav.MAVLink_set_attitude_target_message(t_ms, self.sysid, px4.PX4_COMPID, mask, q_ned,
                                                                   *w_frd, thrust)]):
            return  # no autopilot heard yet: counted in stats.send_drops, not a setpoint of the stream
        self.stats.setpoints_sent += 1
        if self._handshake is not None:
            self._handshake.on_setpoint_sent(now)

    def command_long(self, command: int, *params: float, confirmation: int = 0,
                     target_component: int = px4.PX4_COMPID) -> PendingCommand:  # fmt: skip
        """COMMAND_LONG ``command`` with up to 7 ``params`` (the rest 0) to (sysid, target_component);
        the :class:`PendingCommand` that its COMMAND_ACK resolves.  No resend here (a handshake, or
        the caller, decides)."""
        if len(params) > 7:
            raise ValueError(f"COMMAND_LONG has 7 params, got {len(params)}")
        p = tuple(float(x) for x in (*params, 0, 0, 0, 0, 0, 0, 0)[:7])
        if not all(math.isfinite(x) for x in p):
            raise ValueError(f"COMMAND_LONG {command}: non-finite param in {p}")
        if not 0 <= int(confirmation) <= 255:
            raise ValueError(f"confirmation {confirmation} is not a uint8")
        old = self._pending.get(int(command))
        if old is not None and not old.done:
            old.superseded = True
        pc = PendingCommand(int(command), p, int(confirmation), self.clock())
        self._pending[int(command)] = pc
        self._send([mav.MAVLink_command_long_message(self.sysid, target_component, int(command), int(confirmation),
                                                     *p)])
        self.stats.commands_sent += 1
        return pc

    def set_message_interval(self, msgid: int, interval_us: int) -> PendingCommand:
        """MAV_CMD_SET_MESSAGE_INTERVAL: stream ``msgid`` every ``interval_us`` [us] (-1 stop, 0 default)."""
        if int(interval_us) < -1:
            raise ValueError(f"interval_us {interval_us}: -1 (stop), 0 (default) or a period in us")
        return self.command_long(MAV_CMD_SET_MESSAGE_INTERVAL, float(msgid), float(interval_us))

    def fc_time_us(self, mono_ns: int | None = None) -> float | None:
        """The autopilot's clock [us] at ``mono_ns`` (default now); None before the time base has a sample."""
        return self.timebase.fc_time_us(self.clock() if mono_ns is None else mono_ns)

    # -- plumbing -------------------------------------------------------------------------
    def _timesync_due(self, now: int) -> None:
        if self._ts_period_ns is None or self.peer is None:
            return
        if self._next_ts is None or now >= self._next_ts:
            t = self.clock()
            self._send([mav.MAVLink_timesync_message(0, self.timebase.request(t))])
            self.stats.timesync_sent += 1
            self._next_ts = now if self._next_ts is None else self._next_ts
            while self._next_ts <= now:  # drift-free: last deadline + period, missed ones skipped
                self._next_ts += self._ts_period_ns

    def _drive(self, events: list, now: int) -> None:
        hs = self._handshake
        for e in events:
            if isinstance(e, HeartbeatEvent):
                v = e.value
                hs.on_heartbeat(e.rx_ns, autopilot=v.autopilot, base_mode=v.base_mode, custom_mode=v.custom_mode,
                                fc_us=e.fc_us)
            elif isinstance(e, AckEvent):
                hs.on_ack(e.rx_ns, e.command, e.result)
        for action in hs.step(now, timebase_ready=self.timebase.converged):
            if isinstance(action, SendHeartbeat):
                self.send_heartbeat()
            elif isinstance(action, SendCommand):
                self.command_long(action.command, *action.params, confirmation=action.confirmation)

    def _require_open(self):
        if self._link is None:
            raise RuntimeError("Px4Link is not open; call open() first")
        return self._link

    def _send(self, msgs) -> bool:
        """Send ``msgs`` as one datagram; False (counted in send_drops) while the autopilot is unknown."""
        link = self._require_open()
        dest = self.peer
        if dest is None:
            self.stats.send_drops += 1
            return False
        data = self._encoder.pack(msgs)
        link.send(dest, data)
        if self._tlog is not None:
            self._tlog.write(data)
        return True


def _floats(name: str, values, n: int) -> tuple[float, ...]:
    try:
        out = tuple(float(x) for x in values)
    except (TypeError, ValueError):
        raise SetpointError(f"{name} must be {n} numbers, got {values!r}") from None
    if len(out) != n:
        raise SetpointError(f"{name} must have {n} values, got {len(out)}")
    if not all(math.isfinite(x) for x in out):
        raise SetpointError(f"{name} has a non-finite value: {out}")
    return out
