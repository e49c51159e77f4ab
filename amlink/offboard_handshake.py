"""The PX4 offboard handshake as a companion must do it: a pure, time-driven state machine.

It sends nothing itself.  Its inputs are the autopilot's HEARTBEATs (:meth:`on_heartbeat`), the
COMMAND_ACKs (:meth:`on_ack`) and the setpoints the companion sent (:meth:`on_setpoint_sent`);
:meth:`step` returns what to send next (:class:`SendHeartbeat`, :class:`SendCommand`) and the
adapter (``amlink.px4link.Px4Link.attach``) sends it.  Times are the companion's monotonic ns.

The sequence (states in :class:`State`):

1. ``wait_autopilot``: HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER) every ``heartbeat_period_s``
   (1 Hz) in every state; wait for the autopilot's HEARTBEAT (the adapter passes only the one
   from (sysid, 1)).  Its ``autopilot`` must be MAV_AUTOPILOT_PX4: PX4's custom modes are read.
2. ``request_streams``: MAV_CMD_SET_MESSAGE_INTERVAL for each requested stream, one at a time
   (COMMAND_ACK names the command, not the message, so two in flight could not be told
   apart).  DENIED, UNSUPPORTED, FAILED, CANCELLED, or no answer, are not fatal: the autopilot
   keeps its default rate, and :attr:`notes` says so.
3. ``priming``: PX4 accepts OFFBOARD only while ``offboard_control_mode`` is fresher than
   COM_OF_LOSS_T (1 s; src/modules/commander/HealthAndArmingChecks/checks/offboardCheck.cpp),
   which MavlinkReceiver::handle_message_set_attitude_target publishes for every setpoint that
   carries an attitude or roll and pitch rates, in any mode.  So:
   setpoints streamed for ``prime_s`` (1 s) with no gap over ``setpoint_gap_s`` (0.5 s: > 2 Hz),
   and the time base converged (the engage time is recorded in autopilot time).
4. ``request_offboard``: MAV_CMD_DO_SET_MODE(base_mode = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
   main mode 6 = OFFBOARD); 5. ``arming``: MAV_CMD_COMPONENT_ARM_DISARM(1);
6. ``wait_engaged``: engaged when a HEARTBEAT shows OFFBOARD and armed (also in 4-5, should
   that HEARTBEAT come before the ACK): ``engaged_mono_ns`` and ``engaged_fc_us`` record it.

Every ACK by its code (Commander.cpp answers a refused mode change or arming with
TEMPORARILY_REJECTED; MAVSDK's MavlinkCommandSender maps each result, and waits on IN_PROGRESS):

* ACCEPTED: next step.  IN_PROGRESS: wait, no resend, up to ``in_progress_timeout_s``.
* TEMPORARILY_REJECTED: the command again (a new command: confirmation 0) every
  ``rejected_retry_s`` (0.5 s), for up to ``rejected_give_up_s`` (10 s) after the first
  rejection; then :class:`CommandFailed`.
* DENIED, FAILED, UNSUPPORTED, CANCELLED (or any other code): :class:`CommandFailed` naming
  the command and the result; the state is ``failed``.
* No ACK within ``ack_timeout_s`` (0.5 s, MAVSDK's timeout): resent with confirmation + 1 (the
  MAVLink command protocol), up to ``max_resends`` (3, MAVSDK's retries); then
  :class:`CommandTimeout`.

Yielding.  Once engaged, a HEARTBEAT that shows another mode (a pilot's switch, the GCS, a PX4
failsafe) or disarmed makes the state ``yielded``, and from then on this machine never asks
for OFFBOARD again: whoever took the vehicle keeps it; a companion that wants it back is
started again, and its operator decides.  :meth:`hand_back` is the companion's own yield: it
asks for HOLD (MAV_CMD_DO_SET_MODE, AUTO.LOITER) with the same retry policy and yields.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

from amlink import px4

MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_AUTOPILOT_PX4 = 12
# MAV_RESULT (common.xml)
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED, IN_PROGRESS, CANCELLED = 0, 1, 2, 3, 4, 5, 6
RESULT_NAMES = {0: "ACCEPTED", 1: "TEMPORARILY_REJECTED", 2: "DENIED", 3: "UNSUPPORTED", 4: "FAILED",
                5: "IN_PROGRESS", 6: "CANCELLED", 7: "COMMAND_LONG_ONLY", 8: "COMMAND_INT_ONLY",
                9: "COMMAND_UNSUPPORTED_MAV_FRAME"}
COMMAND_NAMES = {MAV_CMD_DO_SET_MODE: "DO_SET_MODE", MAV_CMD_COMPONENT_ARM_DISARM: "COMPONENT_ARM_DISARM",
                 MAV_CMD_SET_MESSAGE_INTERVAL: "SET_MESSAGE_INTERVAL"}


# the streams a control loop reads (common.xml message ids)
MSG_ODOMETRY, MSG_ATTITUDE_QUATERNION, MSG_ATTITUDE_TARGET, MSG_HIGHRES_IMU = 331, 31, 83, 105
MSG_ATTITUDE, MSG_LOCAL_POSITION_NED = 30, 32
STOP = -1  # SET_MESSAGE_INTERVAL's interval that stops a stream
CONTROL_MSGIDS = (MSG_ODOMETRY, MSG_ATTITUDE_QUATERNION, MSG_ATTITUDE_TARGET, MSG_HIGHRES_IMU)


def control_streams(rate_hz: float, msgids=CONTROL_MSGIDS) -> list[tuple[int, int]]:
    """``(msgid, interval_us)`` pairs asking for each of ``msgids`` at ``rate_hz`` (PX4's onboard
    defaults are ODOMETRY 30 Hz, ATTITUDE_QUATERNION 50 Hz, ATTITUDE_TARGET 10 Hz, HIGHRES_IMU 50 Hz)."""
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be > 0, got {rate_hz!r}")
    return [(int(m), round(1e6 / rate_hz)) for m in msgids]


def result_name(result: int) -> str:
    return RESULT_NAMES.get(result, f"MAV_RESULT {result}")


class State(str, enum.Enum):
    WAIT_AUTOPILOT = "wait_autopilot"
    REQUEST_STREAMS = "request_streams"
    PRIMING = "priming"
    REQUEST_OFFBOARD = "request_offboard"
    ARMING = "arming"
    WAIT_ENGAGED = "wait_engaged"
    ENGAGED = "engaged"
    YIELDED = "yielded"
    FAILED = "failed"


class HandshakeError(Exception):
    """Why the handshake failed (``OffboardHandshake.error``)."""


class CommandFailed(HandshakeError):
    """A command answered with a result that ends it (or TEMPORARILY_REJECTED for too long)."""

    def __init__(self, what: str, command: int, result: int, detail: str = "") -> None:
        self.what, self.command, self.result = what, command, result
        super().__init__(f"{what} (MAV_CMD {command}) answered {result_name(result)}{detail}")


class CommandTimeout(HandshakeError):
    def __init__(self, what: str, command: int, sends: int, waited_s: float) -> None:
        self.what, self.command, self.sends = what, command, sends
        super().__init__(f"{what} (MAV_CMD {command}): no final COMMAND_ACK after {sends} sends in {waited_s:.3g} s")


class NotPx4(HandshakeError):
    def __init__(self, autopilot: int) -> None:
        self.autopilot = autopilot
        super().__init__(f"the autopilot's HEARTBEAT says MAV_AUTOPILOT {autopilot}, not PX4 (12): its modes "
                         f"are not PX4's custom modes")


class EngageTimeout(HandshakeError):
    pass


class AutopilotSilent(HandshakeError):
    pass


@dataclass(frozen=True)
class SendHeartbeat:
    """Send HEARTBEAT (MAV_TYPE_ONBOARD_CONTROLLER) as (sysid, 191)."""


@dataclass(frozen=True)
class SendCommand:
    """Send COMMAND_LONG ``command`` with ``params`` (7) and ``confirmation`` to (sysid, 1)."""

    command: int
    params: tuple[float, ...]
    confirmation: int
    what: str


@dataclass(frozen=True)
class RetryPolicy:
    """Seconds (module docstring for the sources)."""

    ack_timeout_s: float = 0.5
    max_resends: int = 3
    in_progress_timeout_s: float = 1.5  # MAVSDK: retries x timeout after an IN_PROGRESS
    rejected_retry_s: float = 0.5
    rejected_give_up_s: float = 10.0

    def __post_init__(self) -> None:
        for name in ("ack_timeout_s", "in_progress_timeout_s", "rejected_retry_s", "rejected_give_up_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"RetryPolicy.{name} must be > 0 s, got {getattr(self, name)!r}")
        if self.max_resends < 0:
            raise ValueError(f"RetryPolicy.max_resends must be >= 0, got {self.max_resends}")


class _Command:
    """One command until its final ACK: resends, IN_PROGRESS, TEMPORARILY_REJECTED retries."""

    def __init__(self, command: int, params, what: str, policy: RetryPolicy) -> None:
        self.command, self.what, self.policy = command, what, policy
        self.params = tuple(float(p) for p in (*params, 0, 0, 0, 0, 0, 0, 0)[:7])
        self.confirmation = 0
        self.sends = 0
        self.resends = 0
        self.started_ns: int | None = None
        self.deadline_ns: int | None = None  # waiting for an ACK until then
        self.retry_ns: int | None = None  # TEMPORARILY_REJECTED: send again then
        self.rejected_since_ns: int | None = None
        self.in_progress = False
        self.done = False
        self.error: HandshakeError | None = None
        self.last_result: int | None = None

    def _send(self, now: int) -> SendCommand:
        if self.started_ns is None:
            self.started_ns = now
        self.sends += 1
        self.deadline_ns = now + round(self.policy.ack_timeout_s * 1e9)
        self.retry_ns = None
        return SendCommand(self.command, self.params, self.confirmation, self.what)

    def step(self, now: int) -> SendCommand | None:
        if self.done:
            return None
        if self.started_ns is None or (self.retry_ns is not None and now >= self.retry_ns):
            self.confirmation, self.resends = 0, 0
            return self._send(now)
        if self.deadline_ns is not None and now >= self.deadline_ns:
            if self.in_progress or self.resends >= self.policy.max_resends:
                self._fail(CommandTimeout(self.what, self.command, self.sends, (now - self.started_ns) * 1e-9))
                return None
            self.resends += 1
            self.confirmation = min(self.confirmation + 1, 255)
            return self._send(now)
        return None

    def on_ack(self, now: int, result: int) -> None:
        if self.done:
            return
        self.last_result = result
        if result == ACCEPTED:
            self.done, self.deadline_ns, self.retry_ns = True, None, None
        elif self.deadline_ns is None:
            return  # a late answer to a transmission already answered
        elif result == IN_PROGRESS:
            self.in_progress = True
            self.deadline_ns = now + round(self.policy.in_progress_timeout_s * 1e9)
        elif result == TEMPORARILY_REJECTED:
            self.in_progress = False
            if self.rejected_since_ns is None:
                self.rejected_since_ns = now
            if (now - self.rejected_since_ns) * 1e-9 >= self.policy.rejected_give_up_s:
                self._fail(CommandFailed(self.what, self.command, result,
                                         f" for {self.policy.rejected_give_up_s:g} s of retries every "
                                         f"{self.policy.rejected_retry_s:g} s"))
                return
            self.deadline_ns, self.retry_ns = None, now + round(self.policy.rejected_retry_s * 1e9)
        else:
            self._fail(CommandFailed(self.what, self.command, result))

    def _fail(self, error: HandshakeError) -> None:
        self.done, self.error, self.deadline_ns, self.retry_ns = True, error, None, None


class OffboardHandshake:
    """The handshake of one vehicle (module docstring).

    Args:
        streams: ``(msgid, interval_us)`` pairs to request with SET_MESSAGE_INTERVAL, in order.
        policy: the command retry policy.
        prime_s, setpoint_gap_s: the setpoint stream before OFFBOARD is asked for.
        engage_timeout_s: after the arming is accepted, how long the HEARTBEAT may take to show
            OFFBOARD and armed.
        heartbeat_period_s: this companion's HEARTBEAT period.
        wait_autopilot_s: give up if no autopilot HEARTBEAT came within this long (None: wait).
        require_timebase: ask for OFFBOARD only once the time base has converged.
    """

    def __init__(self, streams=(), *, policy: RetryPolicy = RetryPolicy(), prime_s: float = 1.0,
                 setpoint_gap_s: float = 0.5, engage_timeout_s: float = 3.0, heartbeat_period_s: float = 1.0,
                 wait_autopilot_s: float | None = None, require_timebase: bool = True) -> None:  # fmt: skip
        for name, v in (("prime_s", prime_s), ("setpoint_gap_s", setpoint_gap_s),
                        ("engage_timeout_s", engage_timeout_s), ("heartbeat_period_s", heartbeat_period_s)):
            if not v > 0:
                raise ValueError(f"{name} must be > 0 s, got {v!r}")
        self.streams = [(int(m), int(i)) for m, i in streams]
        self.policy = policy
        self._prime_ns, self._gap_ns = round(prime_s * 1e9), round(setpoint_gap_s * 1e9)
        self._engage_ns, self._hb_ns = round(engage_timeout_s * 1e9), round(heartbeat_period_s * 1e9)
        self._wait_ap_ns = None if wait_autopilot_s is None else round(wait_autopilot_s * 1e9)
        self.require_timebase = require_timebase
        self.state = State.WAIT_AUTOPILOT
        self.error: HandshakeError | None = None
        self.yield_reason: str | None = None
        self.notes: list[str] = []  # non-fatal: streams left at their default rate
        self.engaged_mono_ns: int | None = None
        self.engaged_fc_us: float | None = None
        self.hand_back_command: _Command | None = None
        self.last_mode: str | None = None
        self.last_armed: bool | None = None
        self._autopilot: int | None = None
        self._cmd: _Command | None = None
        self._stream_i = 0
        self._t0: int | None = None
        self._next_hb: int | None = None
        self._sp_first: int | None = None
        self._sp_last: int | None = None
        self._engage_deadline: int | None = None

    @property
    def terminal(self) -> bool:
        return self.state in (State.YIELDED, State.FAILED)

    # -- inputs ---------------------------------------------------------------------
    def on_heartbeat(self, now_ns: int, *, autopilot: int, base_mode: int, custom_mode: int,
                     fc_us: float | None = None) -> None:  # fmt: skip
        """The autopilot's HEARTBEAT, received at ``now_ns`` (``fc_us``: that instant in autopilot time)."""
        self._autopilot = autopilot
        armed = bool(base_mode & 128)  # MAV_MODE_FLAG_SAFETY_ARMED
        offboard = (bool(base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
                    and px4.modes_of(custom_mode)[0] == px4.MAIN_OFFBOARD)
        self.last_mode, self.last_armed = px4.mode_name(custom_mode), armed
        if self.state in (State.REQUEST_OFFBOARD, State.ARMING, State.WAIT_ENGAGED) and offboard and armed:
            self.state, self._cmd = State.ENGAGED, None
            self.engaged_mono_ns, self.engaged_fc_us = now_ns, fc_us
        elif self.state == State.ENGAGED and not (offboard and armed):
            why = "disarmed" if not armed else f"the mode was switched to {self.last_mode}"
            self._yield(f"{why} after engagement (by a pilot, the GCS or a PX4 failsafe); not re-requesting OFFBOARD")

    def on_ack(self, now_ns: int, command: int, result: int) -> None:
        """A COMMAND_ACK for ``command`` with ``result`` (MAV_RESULT), received at ``now_ns``."""
        for c in (self._cmd, self.hand_back_command):
            if c is not None and c.command == command:
                c.on_ack(now_ns, result)

    def on_setpoint_sent(self, now_ns: int) -> None:
        if self._sp_last is None or now_ns - self._sp_last > self._gap_ns:
            self._sp_first = now_ns  # the stream (re)starts
        self._sp_last = now_ns

    def primed(self, now_ns: int) -> bool:
        """Setpoints streamed for prime_s and still live."""
        return (self._sp_first is not None and now_ns - self._sp_last <= self._gap_ns
                and now_ns - self._sp_first >= self._prime_ns)

    def hand_back(self, now_ns: int, reason: str) -> None:
        """The companion gives the vehicle back: HOLD (AUTO.LOITER) if OFFBOARD was asked for, then yielded."""
        if self.terminal:
            return
        if self.state in (State.REQUEST_OFFBOARD, State.ARMING, State.WAIT_ENGAGED, State.ENGAGED):
            self.hand_back_command = _Command(
                MAV_CMD_DO_SET_MODE,
                (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, px4.MAIN_AUTO, px4.SUB_AUTO_LOITER),
                "DO_SET_MODE(HOLD)", self.policy)
        self._cmd = None
        self._yield(f"handed back to the autopilot: {reason}")

    # -- the clock ----------------------------------------------------------------------
    def step(self, now_ns: int, *, timebase_ready: bool = True) -> list:
        """What to send now: a list of :class:`SendHeartbeat` / :class:`SendCommand`."""
        out: list = []
        if self._t0 is None:
            self._t0 = self._next_hb = now_ns
        if now_ns >= self._next_hb:
            out.append(SendHeartbeat())
            while self._next_hb <= now_ns:  # drift-free; missed beats are not sent in a burst
                self._next_hb += self._hb_ns
        if self.hand_back_command is not None:
            a = self.hand_back_command.step(now_ns)
            if a is not None:
                out.append(a)
        if self.terminal:
            return out
        if self.state == State.WAIT_AUTOPILOT:
            if self._autopilot is not None:
                if self._autopilot != MAV_AUTOPILOT_PX4:
                    self._fail(NotPx4(self._autopilot))
                    return out
                self._next_stream()
            elif self._wait_ap_ns is not None and now_ns - self._t0 >= self._wait_ap_ns:
                self._fail(AutopilotSilent(f"no HEARTBEAT from the autopilot within {self._wait_ap_ns * 1e-9:g} s"))
                return out
        if self.state == State.REQUEST_STREAMS:
            a = self._cmd.step(now_ns)
            if self._cmd.done:
                if self._cmd.error is not None:
                    self.notes.append(f"{self._cmd.what}: {self._cmd.error}; the autopilot keeps its default rate")
                self._stream_i += 1
                self._next_stream()
            elif a is not None:
                out.append(a)
        if self.state == State.PRIMING:
            if self.primed(now_ns) and (timebase_ready or not self.require_timebase):
                self.state = State.REQUEST_OFFBOARD
                self._cmd = _Command(MAV_CMD_DO_SET_MODE, (MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, px4.MAIN_OFFBOARD, 0),
                                     "DO_SET_MODE(OFFBOARD)", self.policy)
        if self.state in (State.REQUEST_OFFBOARD, State.ARMING):
            a = self._cmd.step(now_ns)
            if a is not None:
                out.append(a)
            if self._cmd.done:
                if self._cmd.error is not None:
                    self._fail(self._cmd.error)
                elif self.state == State.REQUEST_OFFBOARD:
                    self.state = State.ARMING
                    self._cmd = _Command(MAV_CMD_COMPONENT_ARM_DISARM, (1,), "COMPONENT_ARM_DISARM(arm)", self.policy)
                    out.append(self._cmd.step(now_ns))
                else:
                    self.state, self._cmd = State.WAIT_ENGAGED, None
                    self._engage_deadline = now_ns + self._engage_ns
        if self.state == State.WAIT_ENGAGED and now_ns >= self._engage_deadline:
            self._fail(EngageTimeout(f"OFFBOARD and arming were accepted, but the HEARTBEAT still shows "
                                     f"{self.last_mode}, {'armed' if self.last_armed else 'disarmed'} after "
                                     f"{self._engage_ns * 1e-9:g} s"))
        return out

    def _next_stream(self) -> None:
        if self._stream_i < len(self.streams):
            msgid, interval_us = self.streams[self._stream_i]
            self.state = State.REQUEST_STREAMS
            self._cmd = _Command(MAV_CMD_SET_MESSAGE_INTERVAL, (msgid, interval_us),
                                 f"SET_MESSAGE_INTERVAL(msg {msgid}, {interval_us} us)", self.policy)
        else:
            self.state, self._cmd = State.PRIMING, None

    def _yield(self, reason: str) -> None:
        self.state, self.yield_reason, self._cmd = State.YIELDED, reason, None

    def _fail(self, error: HandshakeError) -> None:
        self.state, self.error, self._cmd = State.FAILED, error, None
