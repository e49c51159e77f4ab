"""One vehicle's PX4 onboard MAVLink port, as PX4 SITL runs it (a thin adapter: a UDP socket,
standard MAVLink from pymavlink's common messages through `amlink.wire`, nothing opened before
`open()`).

PX4 v1.14.3 starts it as ``mavlink start -x -u 14580+i -r 4000000 -f -m onboard -o 14540+i``
(ROMFS/px4fmu_common/init.d-posix/px4-rc.mavlink:25): bound to 14580+i, sending to
127.0.0.1:14540+i from the start, as (MAV_SYS_ID, MAV_COMP_ID_AUTOPILOT1), MAVLink 2.

Partner. PX4's receiver takes the address of the FIRST datagram it receives as its partner
(the preset remote is localhost) and sends everything there from then on; it never changes it
again (mavlink_receiver.cpp:3139-3160, set_client_source_initialized). Datagrams from other
addresses are still read and executed, but their answers go to the first partner. So with two
clients on one port the first one wins; a client must send from the port it listens on (MAVSDK
does). This port does the same. (With a remote that is not localhost PX4 latches only after 3 s;
so does this.)

Roles. ``role="onboard"``: the instance above. ``role="gcs"``: PX4 SITL's GCS instance,
``mavlink start -x -u 18570+i -r 4000000 -f`` (px4-rc.mavlink:14), MAVLINK_MODE_NORMAL: bound to
18570+i, sending to 127.0.0.1:14550 (mavlink_main.cpp:1002-1007), with that mode's streams and
px4-rc.mavlink's 50 Hz ones (`GCS_RATES_HZ`). Both take the same commands and setpoints for the
same commander: a GCS arms, switches modes and lands on either.

Signing. PX4 v1.14.3's MAVLink has no signing; later PX4 (MAV_SIGN_CFG) and this stack set it
per link. `require_signed` with `signing_key` (32 bytes, MAVProxy's SHA-256 of a passphrase):
every frame sent is signed with it and only frames signed with it are read; unsigned, wrongly
signed and replayed ones are dropped and counted (`PortStats.unsigned`, `bad_signature`,
`replayed`, `unknown_sysid`; MAVLink 1 is junk here). `require_signed` without a key: the port
sends its streams (unsigned) and reads nothing, a telemetry-only link. Not `require_signed`:
signing off, as PX4's ports by default (frames read signed or not, signatures unchecked,
nothing signed on the way out).

Forwarding. Both of PX4 SITL's instances run with -f: a message one receives that is not for
the autopilot alone goes to the other instances (Mavlink::forward_message, mavlink_main.cpp:448-487;
HEARTBEATs too, MAV_HB_FORW_EN = 1, mavlink_params.c:143), which is how a GCS sees the onboard
computer. Of that, this port forwards HEARTBEATs (`forward`, set by the owner, to another port's
`forwarded`): the companion's reaches the GCS, re-framed as from its source.

Input. Datagrams are read up to 8000 bytes (PX4's POSIX buffer, mavlink_receiver.cpp:3077; a
longer one is cut there, counted as oversized) and parsed as a byte stream, as
mavlink_parse_char does (`amlink.wire.StreamFramer`: junk skipped and counted, a frame may
span datagrams), then checked and decoded (`amlink.wire.Decoder`: CRC, known id). Handled:
HEARTBEAT (counted), SET_ATTITUDE_TARGET (`simulator.px4.setpoint`, for (sysid or 0, 1 or 0)),
COMMAND_LONG and COMMAND_INT, TIMESYNC; other valid messages are counted as ignored.
At most `max_datagrams` are read per `poll`, so a flood costs the physics loop a bounded time per
call; the rest waits in the socket buffer (1 MiB; the kernel drops beyond that, uncounted). Of
a flood of setpoints the newest one per physics step is flown; the others are counted as
superseded.

Impairment. `impairment` (the scenario's [link] table, `amlink.impair.LinkImpairment`: loss,
delay_s, jitter_s, reorder, duplicate) impairs what reaches the autopilot, as a lossy or slow
network between the companion and PX4 would: every datagram read is lost, delayed, held back or
doubled by `amlink.impair.ImpairedChannel`'s model and draws (the stream of this vehicle's
sysid), in whole physics steps of the autopilot's clock, and handled when it arrives. So the
delay is in simulated time (at --speed 0.5, 10 ms is 20 ms of wall time), and a datagram that
arrives after its step's first poll is handled one step later than the model says (at most
1 ms at 1 kHz). Commands and TIMESYNC are impaired with the setpoints: a handshake retries.

Commands (mavlink_receiver.cpp:478-679). A command not addressed to (sysid, 1 or 0) gets
COMMAND_ACK FAILED (:484-495; REQUEST_AUTOPILOT_CAPABILITIES and REQUEST_PROTOCOL_VERSION may be
broadcast, :368-388). The receiver answers itself: REQUEST_AUTOPILOT_CAPABILITIES,
GET_HOME_POSITION and MAV_CMD_REQUEST_MESSAGE(id) send the message once and ACCEPTED, DENIED for
an id this port does not produce (handle_request_message_command, :681-713);
SET_MESSAGE_INTERVAL(id, interval_us): FAILED for HEARTBEAT or an id without a stream, else
ACCEPTED, -1 stopping the stream, 0 its default rate, > 0 that interval, at most one message
per physics step, the source's rate (set_message_interval, :2170-2206); GET_MESSAGE_INTERVAL:
MESSAGE_INTERVAL and ACCEPTED. Everything else goes to the commander
(`simulator.px4.commander`), whose result is the COMMAND_ACK, to (source sysid, compid).

Streams (MAVLINK_MODE_ONBOARD defaults, mavlink_main.cpp; `ONBOARD_RATES_HZ`), each on the
autopilot's clock (as PX4's hrt, so at --speed 0.5 they run at half the wall rate), with PX4's
scheduling (mavlink_stream.cpp:108-116: next = last + interval unless more than 1.5
intervals late). What each carries, in NED/FRD (amlink.px4's maps):
HEARTBEAT (HEARTBEAT.hpp:80-130: MAV_AUTOPILOT_PX4, base_mode from the control mode, PX4
custom mode, MAV_STATE_STANDBY/ACTIVE/CRITICAL(failsafe)/FLIGHT_TERMINATION); SYS_STATUS
(SYS_STATUS.hpp:139-171: gyro, accelerometer, AHRS and motor outputs present, enabled and
healthy, MAV_SYS_STATUS_PREARM_CHECK in health when the current mode's pre-arm checks pass; no
battery: -1s); EXTENDED_SYS_STATE (landed state ON_GROUND / IN_AIR / LANDING in LAND);
HOME_POSITION (set where the vehicle stood when armed, and while disarmed on the ground; lat/lon
from PX4 SITL's default home, SIM_GZ_HOME_LAT/LON/ALT, gz_bridge/parameters.c:49-65);
ATTITUDE, ATTITUDE_QUATERNION, LOCAL_POSITION_NED; ODOMETRY as PX4 streams EKF2's
vehicle_odometry (ODOMETRY.hpp:64-145, EKF2.cpp:1511-1550): frame_id LOCAL_NED and
child_frame_id LOCAL_NED (EKF2 publishes its velocity in NED, VELOCITY_FRAME_NED), body rates
less the gyro bias (FRD), time_usec the sample's boot time, covariances unknown (NaN),
estimator_type AUTOPILOT; HIGHRES_IMU (accelerometer and gyroscope, fields_updated 0x3F);
ATTITUDE_TARGET (ATTITUDE_TARGET.hpp:72-98: q_d, the attitude loop's rate setpoint, thrust,
only while a target is flown); TIMESYNC (TIMESYNC.hpp:61-64: tc1 = 0, ts1 = boot time [ns]);
SYSTEM_TIME; STATUSTEXT (the commander's texts, split into 50-byte chunks as
STATUSTEXT.hpp:96-120); COMMAND_ACK at once. A client's TIMESYNC request (tc1 = 0) is answered
with tc1 = the autopilot's time [ns] and its ts1 (mavlink_timesync.cpp:62-72).
"""
from __future__ import annotations

import ipaddress
import math
import socket
import struct
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from amcore.so3 import euler_zyx_of_quat_wxyz, yaw_of_quat_wxyz
from amlink import px4
from amlink.endpoint import UDP_IN, UDP_OUT, Endpoint, EndpointError, parse_endpoint
from amlink.impair import ImpairedChannel, LinkImpairment
from amlink.wire import Decoder, Encoder, StreamFramer, mav

from . import commander as cm
from .setpoint import SetpointError, VehicleReport, from_set_attitude_target

# PX4 v1.14.3 src/modules/mavlink/mavlink_main.cpp, MAVLINK_MODE_ONBOARD (:1445-1508) and the
# constant-rate streams every instance starts with (:2143-2147) [Hz]
ONBOARD_RATES_HZ = {
    "HEARTBEAT": 1.0,  # :2144, "constant rate stream, rate never adjusted"
    "STATUSTEXT": 20.0,  # :2147
    "TIMESYNC": 10.0,  # :1447
    "HIGHRES_IMU": 50.0,  # :1449
    "LOCAL_POSITION_NED": 30.0,  # :1450
    "ATTITUDE": 100.0,  # :1451
    "ODOMETRY": 30.0,  # :1458
    "ATTITUDE_QUATERNION": 50.0,  # :1461
    "ATTITUDE_TARGET": 10.0,  # :1462
    "EXTENDED_SYS_STATE": 5.0,  # :1468
    "HOME_POSITION": 0.5,  # :1477
    "SYS_STATUS": 5.0,  # :1491
    "SYSTEM_TIME": 1.0,  # :1492
}
# PX4 SITL's GCS instance, ``mavlink start -x -u 18570+i -r 4000000 -f`` (px4-rc.mavlink:14, MAVLINK_MODE_NORMAL),
# with the streams px4-rc.mavlink:15-20 raises to 50 Hz; the rest mavlink_main.cpp:1390-1444 and :2143-2147 [Hz]
GCS_RATES_HZ = {
    "HEARTBEAT": 1.0,  # :2144
    "STATUSTEXT": 20.0,  # :2147
    "ATTITUDE": 50.0,  # px4-rc.mavlink:18 (mavlink_main.cpp:1393: 15)
    "ATTITUDE_QUATERNION": 50.0,  # px4-rc.mavlink:19 (:1394: 10)
    "ATTITUDE_TARGET": 50.0,  # px4-rc.mavlink:20 (:1395: 2)
    "EXTENDED_SYS_STATE": 1.0,  # :1404
    "GLOBAL_POSITION_INT": 50.0,  # px4-rc.mavlink:17 (:1408: 5)
    "HOME_POSITION": 0.5,  # :1413
    "LOCAL_POSITION_NED": 50.0,  # px4-rc.mavlink:16 (:1415: 1)
    "SYS_STATUS": 1.0,  # :1428
}
ROLE_RATES_HZ = {"onboard": ONBOARD_RATES_HZ, "gcs": GCS_RATES_HZ}
_IDS = {name: getattr(mav, f"MAVLINK_MSG_ID_{name}") for name in {**ONBOARD_RATES_HZ, **GCS_RATES_HZ}}
_NAMES = {i: n for n, i in _IDS.items()}
_REQUESTABLE = {**_IDS, "AUTOPILOT_VERSION": mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION}
MAX_DATAGRAM = 1600 * 5  # PX4's POSIX receive buffer (mavlink_receiver.cpp:3077)
HOME_LAT_DEG, HOME_LON_DEG, HOME_ALT_M = 47.397742, 8.545594, 488.0  # SIM_GZ_HOME_LAT/LON/ALT
PARTNER_WAIT_S = 3.0  # mavlink_receiver.cpp:3150
_EARTH_R_M = 6371000.0
_ACCEPT = (mav.MAVLINK_MSG_ID_HEARTBEAT, mav.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET, mav.MAVLINK_MSG_ID_COMMAND_LONG,
           mav.MAVLINK_MSG_ID_COMMAND_INT, mav.MAVLINK_MSG_ID_TIMESYNC)
# SET_ATTITUDE_TARGET's payload with its MAVLink 2 extension thrust_body (common.xml), which
# pymavlink 2.4's common lacks: time_boot_ms, q[4], roll/pitch/yaw rate, thrust, target
# system, target component, type_mask, thrust_body[3]
_SAT = struct.Struct("<I4f4f3B3f")
_NAN21 = [math.nan] * 21
_FLIGHT_SW_VERSION = (1 << 24) | (14 << 16) | (3 << 8) | 255  # v1.14.3, FIRMWARE_VERSION_TYPE_OFFICIAL
_CAPABILITIES = (mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                 | mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET)
_SENSORS = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL | mav.MAV_SYS_STATUS_AHRS
            | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
_MAV_TYPES = {4: mav.MAV_TYPE_QUADROTOR, 6: mav.MAV_TYPE_HEXAROTOR, 8: mav.MAV_TYPE_OCTOROTOR}


def _read_set_attitude_target(buf: bytes, start: int, plen: int) -> tuple:
    return _SAT.unpack(bytes(buf[start:start + min(plen, _SAT.size)]).ljust(_SAT.size, b"\0"))


class PortError(ValueError):
    """An onboard endpoint this port cannot serve (the message names it)."""


def onboard_endpoint(index: int, text: str | None = None) -> Endpoint:
    """The onboard endpoint of vehicle `index`: PX4 SITL's (send to 127.0.0.1:14540+i) unless
    `text` names another (mavlink's forms, UDP only: ``udpout:HOST:PORT`` sends there from the
    start, ``udpin:HOST:PORT`` binds there and waits for a client). PortError if unusable."""
    if text is None:
        return Endpoint(UDP_OUT, "127.0.0.1", px4.onboard_port(index))
    try:
        ep = parse_endpoint(text)
    except EndpointError as exc:
        raise PortError(str(exc)) from None
    if ep.kind not in (UDP_IN, UDP_OUT):
        raise PortError(f"--onboard {text!r}: PX4's onboard link is UDP (mavlink start -u ... -o ...); "
                        f"give udpout:HOST:PORT (send there) or udpin:HOST:PORT (listen there)")
    return ep


def gcs_endpoint(index: int, text: str | None = None) -> Endpoint:
    """The GCS endpoint of vehicle `index`: PX4 SITL's (send to 127.0.0.1:14550 from 18570+i)
    unless `text` names another ``udpout:HOST:PORT`` (every vehicle sends there, each from its
    own 18570+i, as PX4 SITL instances do). PortError if unusable."""
    if text is None:
        return Endpoint(UDP_OUT, "127.0.0.1", px4.GCS_PORT)
    try:
        ep = parse_endpoint(text)
    except EndpointError as exc:
        raise PortError(f"--gcs {text!r}: {exc}") from None
    if ep.kind != UDP_OUT:
        raise PortError(f"--gcs {text!r}: free-running, each vehicle's GCS instance sends from its own port "
                        f"18570+i to one GCS (PX4 SITL's -u 18570+i): give udpout:HOST:PORT, or none")
    return ep


@dataclass
class PortStats:
    """Counters of one port. The first six are `amlink.wire.Decoder`'s."""

    bad_frames: int = 0  # CRC errors, unknown ids, cut frames
    unknown_sysid: int = 0
    unsigned: int = 0
    bad_signature: int = 0
    replayed: int = 0
    ignored: int = 0  # valid messages this port does not handle
    datagrams_rx: int = 0
    datagrams_tx: int = 0
    junk_bytes: int = 0  # bytes skipped while finding frames (StreamFramer)
    oversized: int = 0  # datagrams longer than MAX_DATAGRAM, cut there
    before_partner: int = 0  # datagrams dropped before a partner was known (non-local remote, first 3 s)
    not_for_us: int = 0  # setpoints for another system or component
    setpoints: int = 0  # SET_ATTITUDE_TARGETs accepted
    rejected_setpoints: int = 0  # refused (non-finite, zero quaternion)
    superseded_setpoints: int = 0  # accepted, replaced by a newer one before a physics step used them
    commands: int = 0
    handler_errors: int = 0  # messages whose handling raised (a bug; logged once per message id)
    send_drops: int = 0  # sends that failed (no listener: ICMP port unreachable; full buffer)
    rx: dict = field(default_factory=dict)  # message name -> count
    tx: dict = field(default_factory=dict)
    acks: dict = field(default_factory=dict)  # "command:RESULT" -> count of COMMAND_ACKs sent


class Px4Port:
    """The onboard MAVLink port of one vehicle (module doc). `open()`; then `poll(now_s)`
    (non-blocking) whenever its socket is readable and once per physics step, and
    `publish(now_s, report)` once per physics step; `close()`. now_s: the autopilot's time
    (boot time) [s]; `unix_time_us`: the wall clock for SYSTEM_TIME."""

    def __init__(self, index: int, sysid: int, commander: cm.Commander, endpoint: Endpoint | None = None, *,
                 role: str = "onboard", signing_key: bytes | None = None, require_signed: bool = False,
                 local_port: int | None = None,
                 rotor_count: int = 4, max_datagrams: int = 64, impairment: LinkImpairment | None = None,
                 unix_time_us: Callable[[], int] | None = None, log: Callable[[str], None] = lambda _m: None) -> None:
        if role not in ROLE_RATES_HZ:
            raise ValueError(f"role {role!r}: one of {', '.join(ROLE_RATES_HZ)}")
        self.index, self.sysid, self.commander, self.role = index, sysid, commander, role
        self.endpoint = endpoint or (onboard_endpoint(index) if role == "onboard" else gcs_endpoint(index))
        self._rates = ROLE_RATES_HZ[role]
        self._local_port = local_port  # a udpout endpoint's own port (None: open's rule)
        self.signing = bool(require_signed)  # (module doc, Signing)
        self.forward: Callable[[int, int, object], None] | None = None  # another port's `forwarded` (Forwarding)
        self.stats = PortStats()
        self.max_datagrams = max_datagrams
        self.log = log
        self._unix_us = unix_time_us or (lambda: time.time_ns() // 1000)
        self._mav_type = _MAV_TYPES.get(rotor_count, mav.MAV_TYPE_GENERIC)
        self.sock: socket.socket | None = None
        self.partner: tuple | None = None  # where everything goes once latched
        self._remote: tuple | None = None  # the preset remote (-o), until then
        self._opened_s: float | None = None
        self._framer = StreamFramer()
        keys = ({s: signing_key for s in range(256)} if signing_key is not None else {}) if self.signing else None
        self._decoder = Decoder(keys, accept=_ACCEPT, counters=self.stats,
                                readers={mav.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET: _read_set_attitude_target})
        self._signing_key = signing_key if self.signing else None
        self._encoder = Encoder(sysid, px4.PX4_COMPID, signing_key=self._signing_key)
        self._forward_encoders: dict[tuple[int, int], Encoder] = {}
        self._interval_s = {n: 1.0 / r for n, r in self._rates.items()}
        self._last_sent: dict[str, float] = {}
        self._texts: deque[tuple[int, str]] = deque(maxlen=256)
        self._text_id = 0
        self._report: VehicleReport | None = None
        self._home: tuple[tuple[float, float, float], float] | None = None
        self._setpoints_since_step = 0
        self._next_due = -math.inf  # the earliest time a stream is due (publish's fast path)
        self._warned: set[str] = set()
        # the scenario's [link] impairment of what reaches the autopilot (Impairment): None, or ideal, for none
        self.impaired: ImpairedChannel | None = None
        if impairment is not None and not impairment.is_ideal:
            self.impaired = ImpairedChannel(impairment, impairment.rng(sysid))
        self._rate_hz = impairment.rate_hz if impairment is not None else 1000.0
        self._delivered_step = -1  # the last physics step whose impaired arrivals were handled

    # -- life cycle ---------------------------------------------------------------------
    def open(self) -> None:
        """Bind the socket (OSError if the port is taken)."""
        ep = self.endpoint
        family = socket.AF_INET6 if ":" in ep.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            if ep.kind == UDP_OUT:
                self._remote = socket.getaddrinfo(ep.host, ep.port, family, socket.SOCK_DGRAM)[0][4][:2]
                local = "127.0.0.1" if family == socket.AF_INET else "::1"
                if not _is_loopback(self._remote[0]):
                    local = "0.0.0.0" if family == socket.AF_INET else "::"
                # PX4's -u port when the remote is PX4's -o port for this instance (the GCS instance's:
                # 18570+i whatever the remote), else any free port
                if self._local_port is not None:
                    port = self._local_port
                elif self.role == "gcs":
                    port = px4.gcs_local_port(self.index)
                else:
                    port = px4.px4_local_port(self.index) if ep.port == px4.onboard_port(self.index) else 0
                sock.bind((local, port))
            else:
                sock.bind((ep.host, ep.port))
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        self.sock = sock

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    @property
    def local_address(self) -> tuple:
        return self.sock.getsockname()[:2]

    def fileno(self) -> int:
        return self.sock.fileno()

    def describe(self) -> str:
        """"udp 127.0.0.1:14580 -> 127.0.0.1:14540" (bound -> where it sends)."""
        host, port = self.local_address
        dest = self.partner or self._remote
        return f"udp {host}:{port} -> " + (f"{dest[0]}:{dest[1]}" if dest else "the first client")

    # -- input ----------------------------------------------------------------------------
    def poll(self, now_s: float) -> int:
        """Read and handle what has arrived (at most max_datagrams), without waiting; the
        number of datagrams read."""
        if self._opened_s is None:
            self._opened_s = now_s
        n = 0
        while n < self.max_datagrams:
            try:
                data, addr = self.sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                break
            except (ConnectionRefusedError, ConnectionResetError):  # ICMP of an earlier send
                continue
            n += 1
            self.stats.datagrams_rx += 1
            if self.impaired is not None:
                self.impaired.send(self._step(now_s), (data, addr))
                continue
            self._datagram(now_s, data, addr)
        if self.impaired is not None:
            k = self._step(now_s)
            if k > self._delivered_step:
                self._delivered_step = k
                for _sent, (data, addr) in self.impaired.deliver(k):
                    self._datagram(now_s, data, addr)
        return n

    def _step(self, now_s: float) -> int:
        """The physics step of autopilot time `now_s` (the impairment's time base)."""
        return max(round(now_s * self._rate_hz), self._delivered_step)

    def _datagram(self, now_s: float, data: bytes, addr: tuple) -> None:
        """One datagram as PX4's receiver takes it: its sender latched as the partner (the first
        one), cut to MAX_DATAGRAM, its frames parsed and handled."""
        if self.partner is None:
            if self._remote is None or _is_loopback(self._remote[0]) or now_s - self._opened_s > PARTNER_WAIT_S:
                self.partner = addr[:2]
                self.log(f"vehicle {self.index} (sysid {self.sysid}): partner {addr[0]}:{addr[1]}")
            else:
                self.stats.before_partner += 1
                return
        if len(data) > MAX_DATAGRAM:
            self.stats.oversized += 1
            data = data[:MAX_DATAGRAM]
        before = self._framer.junk_bytes
        frames = self._framer.feed(data)
        self.stats.junk_bytes += self._framer.junk_bytes - before
        if frames:
            for msgid, sysid, compid, body in self._decoder.feed_records(frames):
                try:
                    self._handle(now_s, msgid, sysid, compid, body)
                except Exception as exc:  # a message that trips a bug must not end the run: say it once
                    self.stats.handler_errors += 1
                    self._warn_once(f"handler {msgid}",
                                    f"message id {msgid} from ({sysid}, {compid}) not handled: "
                                    f"{type(exc).__name__}: {exc}; counted, further not printed")

    def _handle(self, now: float, msgid: int, sysid: int, compid: int, body) -> None:
        rx = self.stats.rx
        if msgid == mav.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET:
            rx["SET_ATTITUDE_TARGET"] = rx.get("SET_ATTITUDE_TARGET", 0) + 1
            self._setpoint(now, body)
            return
        name = body.get_type()
        rx[name] = rx.get(name, 0) + 1
        if msgid == mav.MAVLINK_MSG_ID_HEARTBEAT:
            if self.forward is not None and (sysid, compid) != (self.sysid, px4.PX4_COMPID):
                self.forward(sysid, compid, body)
        elif msgid in (mav.MAVLINK_MSG_ID_COMMAND_LONG, mav.MAVLINK_MSG_ID_COMMAND_INT):
            self._command(now, sysid, compid, body)
        elif msgid == mav.MAVLINK_MSG_ID_TIMESYNC and body.tc1 == 0:
            self._send(mav.MAVLink_timesync_message(tc1=_ns(now), ts1=body.ts1), "TIMESYNC")

    def _setpoint(self, now: float, v: tuple) -> None:
        _, qw, qx, qy, qz, roll, pitch, yaw, thrust, target_system, target_component, mask, bx, by, bz = v
        if target_system not in (0, self.sysid) or target_component not in (0, px4.PX4_COMPID):
            self.stats.not_for_us += 1
            return
        try:
            sp = from_set_attitude_target(mask, (qw, qx, qy, qz), (roll, pitch, yaw), thrust, (bx, by, bz), now)
        except SetpointError as exc:
            self.stats.rejected_setpoints += 1
            self._warn_once("setpoint", f"refused a SET_ATTITUDE_TARGET ({exc}); counted, further ones not printed")
            return
        self.stats.setpoints += 1
        self._setpoints_since_step += 1
        self.commander.offboard_setpoint(now, sp)

    def _command(self, now: float, sysid: int, compid: int, msg) -> None:
        if sysid == self.sysid and compid == px4.PX4_COMPID:
            return  # our own (mavlink_receiver.cpp:646-649)
        self.stats.commands += 1
        cmd = msg.command
        params = (msg.param1, msg.param2, msg.param3, msg.param4,
                  *((msg.param5, msg.param6, msg.param7) if msg.get_type() == "COMMAND_LONG" else
                    (float(msg.x), float(msg.y), msg.z)))
        broadcast_ok = cmd in (mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, mav.MAV_CMD_REQUEST_PROTOCOL_VERSION)
        if broadcast_ok:
            ok = msg.target_system in (0, self.sysid)
        else:
            ok = msg.target_system == self.sysid and msg.target_component in (px4.PX4_COMPID, 0)
        if not ok:
            self._ack(cmd, cm.FAILED, sysid, compid)
            return
        if cmd == mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            result = self._request(now, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        elif cmd == mav.MAV_CMD_REQUEST_PROTOCOL_VERSION:
            result = cm.DENIED  # no PROTOCOL_VERSION in this dialect
        elif cmd == mav.MAV_CMD_GET_HOME_POSITION:
            result = self._request(now, mav.MAVLINK_MSG_ID_HOME_POSITION)
        elif cmd == mav.MAV_CMD_REQUEST_MESSAGE:
            result = self._request(now, int(round(params[0])) if math.isfinite(params[0]) else -1)
        elif cmd == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_interval(int(round(params[0])) if math.isfinite(params[0]) else -1, params[1])
        elif cmd == mav.MAV_CMD_GET_MESSAGE_INTERVAL:
            mid = int(round(params[0])) if math.isfinite(params[0]) else -1
            name = _NAMES.get(mid)
            interval = self._interval_s.get(name) if name else None
            us = 0 if interval is None else (-1 if interval < 0 else round(interval * 1e6))
            self._send(mav.MAVLink_message_interval_message(mid & 0xFFFF, us), "MESSAGE_INTERVAL")
            result = cm.ACCEPTED
        else:
            result = self.commander.handle_command(now, cmd, params)
        self._ack(cmd, result, sysid, compid)

    def _request(self, now: float, msgid: int) -> int:
        name = next((n for n, i in _REQUESTABLE.items() if i == msgid), None)
        msg = None if name is None else self._build(name, now, self._report)
        if msg is None:
            return cm.DENIED
        self._send(msg, name)
        return cm.ACCEPTED

    def _set_interval(self, msgid: int, interval_us: float) -> int:
        name = _NAMES.get(msgid)
        if name is None or name == "HEARTBEAT" or not math.isfinite(interval_us):
            return cm.FAILED
        self._next_due = -math.inf
        if interval_us < -1e-5:
            self._interval_s[name] = -1.0  # stopped
        elif interval_us > 1e-5:
            self._interval_s[name] = interval_us * 1e-6
        else:
            default = self._rates.get(name)
            self._interval_s[name] = 1.0 / default if default else -1.0
        return cm.ACCEPTED

    def forwarded(self, sysid: int, compid: int, msg) -> None:
        """Send a HEARTBEAT another port of this autopilot received from (sysid, compid) (its
        companion's, a GCS's), as PX4's forwarding does (module doc, Forwarding): re-framed as
        from its source, and signed when this link signs."""
        enc = self._forward_encoders.get((sysid, compid))
        if enc is None:
            enc = self._forward_encoders[(sysid, compid)] = Encoder(sysid, compid, signing_key=self._signing_key)
        self._send(msg, "HEARTBEAT (forwarded)", enc)

    def _ack(self, command: int, result: int, sysid: int, compid: int) -> None:
        key = f"{command}:{cm.RESULT_NAMES.get(result, result)}"
        self.stats.acks[key] = self.stats.acks.get(key, 0) + 1
        self._send(mav.MAVLink_command_ack_message(command, result, 0, 0, sysid, compid), "COMMAND_ACK")

    # -- output ---------------------------------------------------------------------------
    def publish(self, now_s: float, report: VehicleReport) -> None:
        """One physics step: the streams that are due, from `report` and the commander."""
        self._report = report
        if self._setpoints_since_step > 1:
            self.stats.superseded_setpoints += self._setpoints_since_step - 1
        self._setpoints_since_step = 0
        c = self.commander
        if not c.armed and c.landed:  # home follows the vehicle on the ground until armed (Commander.cpp)
            self._home = (report.p_W, yaw_of_quat_wxyz(report.quat_WB))
        texts = c.pop_texts()
        if texts:
            self._texts.extend(texts)
        if self._texts and self._due("STATUSTEXT", now_s):
            while self._texts:
                self._statustext(*self._texts.popleft())
        if now_s < self._next_due:
            return
        next_due = math.inf
        for name, interval in self._interval_s.items():
            if interval < 0.0 or name == "STATUSTEXT":
                continue
            if self._due(name, now_s):
                msg = self._build(name, now_s, report)  # None: nothing to say in this slot
                if msg is not None:
                    self._send(msg, name)
            last = self._last_sent.get(name)
            next_due = min(next_due, now_s if last is None else last + interval)
        self._next_due = next_due

    def _due(self, name: str, now_s: float) -> bool:
        """Whether stream `name` is due now; if so its slot is taken (mavlink_stream.cpp:108-116:
        next = last + interval, unless more than 1.5 intervals have passed)."""
        interval = self._interval_s[name]
        last = self._last_sent.get(name)
        if last is not None and now_s - last < interval:
            return False
        self._last_sent[name] = last + interval if last is not None and now_s - last < 1.5 * interval else now_s
        return True

    def _statustext(self, severity: int, text: str) -> None:
        raw = text.encode()[:200]
        chunks = [raw[i:i + 50] for i in range(0, len(raw), 50)] or [b""]
        ident = 0
        if len(chunks) > 1:
            self._text_id = self._text_id % 65535 + 1
            ident = self._text_id
        for seq, chunk in enumerate(chunks):
            self._send(mav.MAVLink_statustext_message(severity, chunk, ident, seq), "STATUSTEXT")

    def _build(self, name: str, now: float, r: VehicleReport | None):
        """The message `name` now, or None when there is nothing to say."""
        c = self.commander
        if name == "HEARTBEAT":
            if c.nav_state == cm.NavState.TERMINATION:
                state = mav.MAV_STATE_FLIGHT_TERMINATION
            elif c.armed:
                state = mav.MAV_STATE_CRITICAL if c.failsafe else mav.MAV_STATE_ACTIVE
            else:
                state = mav.MAV_STATE_STANDBY
            return mav.MAVLink_heartbeat_message(self._mav_type, mav.MAV_AUTOPILOT_PX4, c.base_mode(), c.custom_mode,
                                                 state, 3)
        if name == "TIMESYNC":
            return mav.MAVLink_timesync_message(tc1=0, ts1=_ns(now))
        if name == "SYSTEM_TIME":
            return mav.MAVLink_system_time_message(self._unix_us(), _ms(now))
        if name == "SYS_STATUS":
            health = _SENSORS | (mav.MAV_SYS_STATUS_PREARM_CHECK if c.can_arm(now) else 0)
            return mav.MAVLink_sys_status_message(_SENSORS, _SENSORS, health, 0, 65535, -1, -1, 0, 0, 0, 0, 0, 0,
                                                  0, 0, 0)
        if name == "EXTENDED_SYS_STATE":
            if c.landed:
                landed = mav.MAV_LANDED_STATE_ON_GROUND
            elif c.nav_state in cm.LANDING:
                landed = mav.MAV_LANDED_STATE_LANDING
            else:
                landed = mav.MAV_LANDED_STATE_IN_AIR
            return mav.MAVLink_extended_sys_state_message(mav.MAV_VTOL_STATE_UNDEFINED, landed)
        if name == "AUTOPILOT_VERSION":
            return mav.MAVLink_autopilot_version_message(_CAPABILITIES, _FLIGHT_SW_VERSION, 0, 0, 0, [0] * 8, [0] * 8,
                                                         [0] * 8, 0, 0, self.sysid, [0] * 18)
        if r is None:
            return None
        if name == "HOME_POSITION":
            if self._home is None:
                return None
            p, yaw = self._home
            x, y, z = px4.enu_to_ned(p)
            lat, lon = _lat_lon(x, y)
            psi = math.pi / 2.0 - yaw  # heading about NED down from the yaw about ENU up
            q = [math.cos(psi / 2.0), 0.0, 0.0, math.sin(psi / 2.0)]
            return mav.MAVLink_home_position_message(lat, lon, round((HOME_ALT_M - z) * 1e3),
                                                     x, y, z, q, 0.0, 0.0, 0.0, _us(r.time_s))
        q = px4.q_enu_flu_to_ned_frd(r.quat_WB)
        w = px4.flu_to_frd(r.w_B)
        if name == "ATTITUDE_QUATERNION":
            return mav.MAVLink_attitude_quaternion_message(_ms(r.time_s), *q, *w, [0.0, 0.0, 0.0, 0.0])
        if name == "ATTITUDE":
            return mav.MAVLink_attitude_message(_ms(r.time_s), *euler_zyx_of_quat_wxyz(q), *w)
        if name == "GLOBAL_POSITION_INT":
            x, y, z = px4.enu_to_ned(r.p_W)
            vx, vy, vz = px4.enu_to_ned(r.v_W)
            lat, lon = _lat_lon(x, y)
            hdg = round(math.degrees(math.pi / 2.0 - yaw_of_quat_wxyz(r.quat_WB)) * 100.0) % 36000
            rel = -z - (0.0 if self._home is None else -px4.enu_to_ned(self._home[0])[2])
            return mav.MAVLink_global_position_int_message(_ms(r.time_s), lat, lon, round((HOME_ALT_M - z) * 1e3),
                                                           round(rel * 1e3), _cm_s(vx), _cm_s(vy), _cm_s(vz), hdg)
        if name == "LOCAL_POSITION_NED":
            return mav.MAVLink_local_position_ned_message(_ms(r.time_s), *px4.enu_to_ned(r.p_W), *px4.enu_to_ned(r.v_W))
        if name == "ODOMETRY":
            return mav.MAVLink_odometry_message(_us(r.time_s), mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_NED,
                                                *px4.enu_to_ned(r.p_W), list(q), *px4.enu_to_ned(r.v_W), *w, _NAN21,
                                                _NAN21, 0, mav.MAV_ESTIMATOR_TYPE_AUTOPILOT, 0)
        if name == "HIGHRES_IMU":
            return mav.MAVLink_highres_imu_message(_us(r.time_s), *px4.flu_to_frd(r.accel_B), *px4.flu_to_frd(r.gyro_B),
                                                   0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0x3F, 0)
        if name == "ATTITUDE_TARGET":
            if r.target is None:
                return None
            rates = px4.flu_to_frd(r.rates_sp_B) if r.rates_sp_B is not None else (0.0, 0.0, 0.0)
            q_d = list(px4.q_enu_flu_to_ned_frd(r.target.quat_wxyz))
            return mav.MAVLink_attitude_target_message(_ms(r.time_s), 0, q_d, *rates,
                                                       min(max(r.target.thrust_normalized, 0.0), 1.0))
        return None

    def _send(self, msg, name: str, encoder: Encoder | None = None) -> None:
        dest = self.partner or self._remote
        if dest is None or self.sock is None:
            return
        try:
            data = (encoder or self._encoder).pack([msg])
        except Exception as exc:  # a value out of range for its field: a bug to hear about, never a crash
            self._warn_once(f"pack {name}", f"cannot pack {name}: {exc}")
            return
        try:
            self.sock.sendto(data, dest)
        except (BlockingIOError, ConnectionRefusedError, ConnectionResetError, OSError):
            self.stats.send_drops += 1
            return
        self.stats.datagrams_tx += 1
        self.stats.tx[name] = self.stats.tx.get(name, 0) + 1

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.log(f"vehicle {self.index} (sysid {self.sysid}): {text}")


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def _lat_lon(x_n: float, y_e: float) -> tuple[int, int]:
    """Latitude and longitude [1e-7 deg] of the point x_n north, y_e east [m] of PX4 SITL's home."""
    lat = HOME_LAT_DEG + math.degrees(x_n / _EARTH_R_M)
    lon = HOME_LON_DEG + math.degrees(y_e / (_EARTH_R_M * math.cos(math.radians(HOME_LAT_DEG))))
    return round(lat * 1e7), round(lon * 1e7)


def _cm_s(v: float) -> int:
    return max(-32768, min(32767, round(v * 100.0)))


def _ms(t: float) -> int:
    return max(0, int(t * 1e3)) & 0xFFFFFFFF


def _us(t: float) -> int:
    return max(0, int(t * 1e6))


def _ns(t: float) -> int:
    return max(0, int(t * 1e9))


