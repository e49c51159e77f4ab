"""The wall-clock loop's view of its autopilot: the PX4 link (`amlink.px4link`) with the offboard
handshake (`amlink.offboard_handshake`) attached, under the few names the loop uses
(`companion.wallclock`). A thin adapter: no policy of its own beyond the type_mask it sends.

type_mask. PX4's MavlinkReceiver::handle_message_set_attitude_target (v1.14) takes the
quaternion and the collective thrust of an attitude setpoint; of its body rates only the
yaw rate can reach the attitude controller (as yaw_sp_move_rate, a feed-forward), and roll
and pitch rates are read only when the attitude is ignored. The controller's attitude target
comes with its body rates (R_b,d and w_b,d of eq. Rd), so the companion sends them with
`TYPE_MASK` = 0 (nothing ignored): PX4 uses what it uses, and an autopilot that feeds the
rates forward gets them all. `--type-mask 7` sends what MAVSDK's set_attitude sends.
"""
from __future__ import annotations

import time

from amlink.offboard_handshake import (MSG_ATTITUDE, MSG_ATTITUDE_QUATERNION, MSG_ATTITUDE_TARGET, MSG_HIGHRES_IMU,
                                       MSG_LOCAL_POSITION_NED, MSG_ODOMETRY, STOP, OffboardHandshake,
                                       control_streams)
from amlink.px4link import Px4Link

TYPE_MASK = 0
ENGAGE_TIMEOUT_S = 6.0
ANCHOR_MAX_NS = 50_000_000  # fc_time_us anchors on a sample at most this old [ns]


UNREAD_STREAMS = (MSG_ATTITUDE, MSG_HIGHRES_IMU, MSG_LOCAL_POSITION_NED)  # stopped by the handshake


class Autopilot:
    def __init__(self, link: Px4Link, handshake: OffboardHandshake, type_mask: int = TYPE_MASK) -> None:
        self.link, self.hs, self.type_mask = link, handshake, type_mask
        link.attach(handshake)
        self._opened_ns: int | None = None

    @classmethod
    def for_rate(cls, link: Px4Link, control_rate_hz: float, type_mask: int = TYPE_MASK) -> "Autopilot":
        """The handshake asking for the control streams at the loop's rate (the autopilot caps them)."""
        # what the loop reads: not HIGHRES_IMU (the law takes the autopilot's estimate, not its raw IMU).
        # The onboard defaults it does not read are stopped: ATTITUDE (100 Hz), HIGHRES_IMU (50 Hz) and
        # LOCAL_POSITION_NED (30 Hz) would cost every step their wake-ups and decoding, and on a serial
        # link their bandwidth (ODOMETRY at 250 Hz alone is ~61 kB/s of a 921600-baud UART's ~92 kB/s)
        streams = control_streams(control_rate_hz, (MSG_ODOMETRY, MSG_ATTITUDE_QUATERNION, MSG_ATTITUDE_TARGET))
        streams += [(m, STOP) for m in UNREAD_STREAMS]
        # the engage shows in a HEARTBEAT, 1 Hz of the autopilot's clock: 6 s leaves room for a SITL at 0.5x
        return cls(link, OffboardHandshake(streams, engage_timeout_s=ENGAGE_TIMEOUT_S), type_mask)

    def open(self) -> None:
        self.link.open()
        self._opened_ns = self.link.clock()

    def close(self) -> None:
        self.link.close()

    # -- time and liveness ---------------------------------------------------------
    def wait(self, timeout_s: float) -> None:
        """Serve the link until a frame arrives or `timeout_s` passes."""
        self.link.poll(timeout_s=max(0.0, timeout_s))

    def poll(self, _now_ns: int | None = None) -> None:
        self.link.poll()

    def clock_rate(self) -> float | None:
        tb = self.link.timebase
        return tb.rate if tb.converged else None

    def fc_time_us(self, now_ns: int) -> float | None:
        """The autopilot's time now [us]: the newest sample's timestamp carried forward over the time
        since it arrived (at the TIMESYNC rate) plus the link's one-way delay (half its round trip).
        Anchoring on the newest sample, not on the TIMESYNC line alone, keeps a SITL whose clock
        stalls and catches up (a loaded machine) from making every sample look stale: the line's
        rate is a 3 s average, the anchor is at most a few milliseconds old. Before any sample,
        or once the newest is older than the line's own word (a silent autopilot), the line."""
        tb = self.link.timebase
        if not tb.ready:
            return None
        line = self.link.fc_time_us(now_ns)
        newest = None
        for source in ("attitude", "odometry"):
            s = self.link.store.latest(source)
            if s is not None and s.fc_us is not None and (newest is None or s.rx_ns > newest.rx_ns):
                newest = s
        if newest is None or now_ns - newest.rx_ns > ANCHOR_MAX_NS:
            return line
        rate = tb.rate or 1.0
        half_rtt_us = 0.5e-3 * (tb.rtt_ns or 0)
        return newest.fc_us + (now_ns - newest.rx_ns) * 1e-3 * rate + half_rtt_us * rate

    def silent_for_s(self, now_ns: int) -> float:
        last = self.link.last_rx_ns if self.link.last_rx_ns is not None else self._opened_ns
        return 0.0 if last is None else (now_ns - last) * 1e-9

    # -- the handshake -------------------------------------------------------------
    @property
    def state(self) -> str:
        return str(self.hs.state.value if hasattr(self.hs.state, "value") else self.hs.state)

    @property
    def error(self) -> str | None:
        e = self.hs.error
        return str(e) if e is not None else self.hs.yield_reason

    @property
    def armed(self) -> bool | None:
        """Whether the autopilot's last HEARTBEAT showed it armed (None before any)."""
        return self.hs.last_armed

    @property
    def engaged_fc_us(self) -> float | None:
        return self.hs.engaged_fc_us

    def hand_back(self, reason: str) -> None:
        """Ask for HOLD and yield; the link is served a little so that the command leaves."""
        self.hs.hand_back(self.link.clock(), reason)
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline and str(self.state) != "yielded":
            self.link.poll(timeout_s=0.05)

    # -- samples ---------------------------------------------------------------------
    def _value(self, source: str):
        s = self.link.store.latest(source)
        return None if s is None else s.value

    def _rx(self, source: str) -> int | None:
        s = self.link.store.latest(source)
        return None if s is None else s.rx_ns

    @property
    def odometry(self):
        """The autopilot's estimate (amlink.px4samples.Odometry: t_us, p_WB, q_WB_wxyz, v_B, w_B; ENU/FLU)."""
        return self._value("odometry")

    @property
    def odometry_rx_ns(self) -> int | None:
        return self._rx("odometry")

    @property
    def attitude(self):
        """ATTITUDE_QUATERNION (t_us, q_WB_wxyz, w_B), ENU/FLU."""
        return self._value("attitude")

    @property
    def attitude_target(self):
        """The target the autopilot reports flying (ATTITUDE_TARGET, amlink.types.AttitudeTarget)."""
        return self._value("attitude_target")

    # -- setpoints -------------------------------------------------------------------
    def send_setpoint(self, att) -> None:
        self.link.send_attitude_target(att.quat_wxyz, att.rates_rad_s, min(1.0, max(0.0, att.thrust_normalized)),
                                       self.type_mask)

    def stream_idle(self, att) -> None:
        """The priming stream's target (None: nothing to send yet)."""
        if att is not None:
            self.send_setpoint(att)
