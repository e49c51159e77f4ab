"""A minimal PX4-like endpoint for the PX4 client's tests, written on pymavlink's stock common.xml
dialect (standard messages only), and a clock the tests drive.

It behaves as the parts of PX4 the companion meets (PX4-Autopilot mavlink_receiver.cpp,
mavlink_timesync.cpp, Commander.cpp): HEARTBEAT with PX4's custom modes; COMMAND_ACK for
DO_SET_MODE, ARM_DISARM and SET_MESSAGE_INTERVAL; OFFBOARD accepted only while a setpoint came
within COM_OF_LOSS_T (1 s), else TEMPORARILY_REJECTED (offboardCheck.cpp); TIMESYNC requests
answered with tc1 = its boot time [ns] and ts1 echoed; its own TIMESYNC requests; ODOMETRY.
Results can be scripted per command to play refusals.
"""
from __future__ import annotations

import select
import socket
import time
from collections import deque

from pymavlink.dialects.v20 import common as mc

from amlink import px4

OFFBOARD_LOSS_NS = 1_000_000_000  # COM_OF_LOSS_T default 1 s


class FakeClock:
    """Monotonic ns the test advances; shared by the link and the fake autopilot."""

    def __init__(self, start_ns: int = 1_000_000_000_000) -> None:
        self.now = start_ns

    def __call__(self) -> int:
        return self.now

    def advance(self, dt_ns: int) -> int:
        self.now += int(dt_ns)
        return self.now


class FakePx4:
    def __init__(self, sysid: int, clock: FakeClock, *, rate: float = 1.0, boot_us: int = 7_000_000,
                 autopilot: int = mc.MAV_AUTOPILOT_PX4, signing_key: bytes | None = None) -> None:  # fmt: skip
        self.sysid, self.clock, self.rate = sysid, clock, rate
        self._t0, self._boot_us = clock(), boot_us
        self.autopilot = autopilot
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.mav = mc.MAVLink(None, srcSystem=sysid, srcComponent=1)
        if signing_key is not None:
            self.mav.signing.secret_key = signing_key
            self.mav.signing.link_id = 0
            self.mav.signing.sign_outgoing = True
            self.mav.signing.timestamp = int((time.time() - 1420070400) * 1e5)  # 10 us since 2015 (signing spec)
        self.rx = mc.MAVLink(None)
        self.rx.robust_parsing = True
        self.dest = None
        self.main_mode, self.sub_mode, self.armed = px4.MAIN_POSCTL, 0, False
        self.results: dict[int, deque] = {}  # command -> scripted MAV_RESULTs, used first
        self.interval_results: dict[int, int] = {}  # msgid -> result of SET_MESSAGE_INTERVAL
        self.ignore: dict[int, int] = {}  # command -> how many of its transmissions to drop unanswered
        self.commands: list[tuple[int, object]] = []  # (clock ns, COMMAND_LONG)
        self.setpoints: list[tuple[int, object]] = []
        self.heartbeats: list[tuple[int, object]] = []
        self.timesync_answers: list[object] = []  # our requests, answered by the companion
        self.requests_sent: list[int] = []  # ts1 of our requests
        self.other: list[object] = []

    # -- time --------------------------------------------------------------------------
    def fc_us(self, mono_ns: int | None = None) -> float:
        t = self.clock() if mono_ns is None else mono_ns
        return self._boot_us + self.rate * (t - self._t0) / 1000.0

    # -- sending ---------------------------------------------------------------------------
    def send(self, msg) -> None:
        self.send_raw(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.dest)

    def base_mode(self) -> int:
        return mc.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mc.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)

    def heartbeat(self) -> None:
        self.send(mc.MAVLink_heartbeat_message(mc.MAV_TYPE_QUADROTOR, self.autopilot, self.base_mode(),
                                               px4.custom_mode(self.main_mode, self.sub_mode),
                                               mc.MAV_STATE_ACTIVE, 3))

    def odometry(self, p_ned, q_ned_frd, v, w_frd, *, frame_id=mc.MAV_FRAME_LOCAL_NED,
                 child_frame_id=mc.MAV_FRAME_BODY_FRD, t_us=None) -> int:  # fmt: skip
        t = int(self.fc_us()) if t_us is None else int(t_us)
        nan21 = [float("nan")] * 21
        self.send(mc.MAVLink_odometry_message(t, frame_id, child_frame_id, *p_ned, list(q_ned_frd), *v, *w_frd,
                                              nan21, nan21, 0, mc.MAV_ESTIMATOR_TYPE_AUTOPILOT, 100))
        return t

    def timesync_request(self) -> int:
        ts1 = int(self.fc_us()) * 1000
        self.requests_sent.append(ts1)
        self.send(mc.MAVLink_timesync_message(0, ts1))
        return ts1

    def set_mode(self, main: int, sub: int = 0) -> None:
        self.main_mode, self.sub_mode = main, sub

    # -- receiving ---------------------------------------------------------------------------
    def serve(self, wait_s: float = 0.0) -> int:
        """Handle every datagram that arrived (waiting up to wait_s for the first); how many."""
        n = 0
        timeout = wait_s
        while True:
            r, _, _ = select.select([self.sock], [], [], timeout)
            if not r:
                return n
            timeout = 0.0
            data, _ = self.sock.recvfrom(65535)
            n += 1
            for m in self.rx.parse_buffer(data) or []:
                self._handle(m)

    def _handle(self, m) -> None:
        now = self.clock()
        t = m.get_type()
        if t == "COMMAND_LONG":
            self.commands.append((now, m))
            if self.ignore.get(m.command, 0) > 0:
                self.ignore[m.command] -= 1
                return
            self._ack(m, self._result(m, now))
        elif t == "SET_ATTITUDE_TARGET":
            self.setpoints.append((now, m))
        elif t == "TIMESYNC":
            if m.tc1 == 0:
                self.send(mc.MAVLink_timesync_message(int(self.fc_us()) * 1000, m.ts1))  # as PX4: us * 1000
            else:
                self.timesync_answers.append(m)
        elif t == "HEARTBEAT":
            self.heartbeats.append((now, m))
        else:
            self.other.append(m)

    def _result(self, m, now: int) -> int:
        scripted = self.results.get(m.command)
        if scripted:
            result = scripted.popleft()
        elif m.command == mc.MAV_CMD_DO_SET_MODE and round(m.param2) == px4.MAIN_OFFBOARD:
            fresh = self.setpoints and now - self.setpoints[-1][0] < OFFBOARD_LOSS_NS
            result = mc.MAV_RESULT_ACCEPTED if fresh else mc.MAV_RESULT_TEMPORARILY_REJECTED
        elif m.command == mc.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self.interval_results.get(round(m.param1), mc.MAV_RESULT_ACCEPTED)
        else:
            result = mc.MAV_RESULT_ACCEPTED
        if result == mc.MAV_RESULT_ACCEPTED:
            if m.command == mc.MAV_CMD_DO_SET_MODE:
                self.set_mode(round(m.param2), round(m.param3))
            elif m.command == mc.MAV_CMD_COMPONENT_ARM_DISARM:
                self.armed = round(m.param1) == 1
        return result

    def _ack(self, m, result: int) -> None:
        self.send(mc.MAVLink_command_ack_message(m.command, result, 0, 0, m.get_srcSystem(), m.get_srcComponent()))

    def commands_of(self, command: int) -> list:
        return [m for _, m in self.commands if m.command == command]

    def close(self) -> None:
        self.sock.close()
