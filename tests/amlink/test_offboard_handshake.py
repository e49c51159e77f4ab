"""The offboard handshake: pure (time-driven, no sockets) and over the link against the PX4-like
endpoint of tests/amlink/px4_fake.py."""
from __future__ import annotations

from collections import deque

import pytest
from pymavlink.dialects.v20 import common as mc

from amlink import px4
from amlink import offboard_handshake as oh
from amlink.offboard_handshake import OffboardHandshake, SendCommand, SendHeartbeat, State
from amlink.px4link import Px4Link

from .px4_fake import FakeClock, FakePx4

MS = 1_000_000
S = 1_000_000_000
SYSID = 2
POSCTL = px4.custom_mode(px4.MAIN_POSCTL)
OFFBOARD = px4.custom_mode(px4.MAIN_OFFBOARD)
ARMED = 128 | 1


# -- pure ---------------------------------------------------------------------------------
class Driver:
    """Steps a handshake every 20 ms with a 50 Hz setpoint stream; collects what it sends."""

    def __init__(self, hs: OffboardHandshake, t: int = 10 * S) -> None:
        self.hs, self.t = hs, t
        self.sent: list[tuple[int, object]] = []

    def run(self, seconds: float, *, setpoints: bool = True, each=None) -> None:
        end = self.t + round(seconds * S)
        while self.t < end:
            if setpoints:
                self.hs.on_setpoint_sent(self.t)
            if each is not None:
                each(self)
            for a in self.hs.step(self.t):
                self.sent.append((self.t, a))
            self.t += 20 * MS

    def commands(self, command=None):
        return [(t, a) for t, a in self.sent
                if isinstance(a, SendCommand) and (command is None or a.command == command)]

    def heartbeat(self, custom=POSCTL, base=1, autopilot=oh.MAV_AUTOPILOT_PX4):
        self.hs.on_heartbeat(self.t, autopilot=autopilot, base_mode=base, custom_mode=custom, fc_us=self.t / 1e3 + 5)


def acking(results: dict[int, deque]):
    """An `each` hook that answers the last command sent with the next scripted result of its id."""
    answered = set()

    def each(d: Driver) -> None:
        for t, a in d.commands():
            if id(a) in answered:
                continue
            answered.add(id(a))
            q = results.get(a.command)
            if q:
                r = q.popleft()
                if r is not None:
                    d.hs.on_ack(d.t, a.command, r)
    return each


def test_heartbeats_at_1_hz_drift_free_from_the_first_step():
    d = Driver(OffboardHandshake())
    d.run(5.0, setpoints=False)
    beats = [t - 10 * S for t, a in d.sent if isinstance(a, SendHeartbeat)]
    assert beats == [0, S, 2 * S, 3 * S, 4 * S]
    assert d.hs.state == State.WAIT_AUTOPILOT and not d.commands()


def test_full_sequence_streams_then_offboard_after_a_second_of_setpoints_then_arm():
    hs = OffboardHandshake(streams=[(331, 4000), (83, 4000)])
    d = Driver(hs)
    d.run(0.2, setpoints=False)
    d.heartbeat()
    results = {oh.MAV_CMD_SET_MESSAGE_INTERVAL: deque([oh.ACCEPTED, oh.UNSUPPORTED]),
               oh.MAV_CMD_DO_SET_MODE: deque([oh.ACCEPTED]), oh.MAV_CMD_COMPONENT_ARM_DISARM: deque([oh.ACCEPTED])}
    first_sp = d.t
    d.run(2.0, each=acking(results))
    cmds = [a for _, a in d.commands()]
    assert [a.command for a in cmds] == [511, 511, 176, 400]
    assert cmds[0].params[:2] == (331.0, 4000.0) and cmds[1].params[:2] == (83.0, 4000.0)
    assert cmds[2].params[:3] == (1.0, 6.0, 0.0)  # CUSTOM_MODE_ENABLED, main mode OFFBOARD
    assert cmds[3].params[0] == 1.0
    t_mode = d.commands(176)[0][0]
    assert t_mode - first_sp >= S  # >= 1 s of setpoints first
    assert hs.state == State.WAIT_ENGAGED and len(hs.notes) == 1 and "UNSUPPORTED" in hs.notes[0]
    d.heartbeat(OFFBOARD, ARMED)
    assert hs.state == State.ENGAGED and hs.engaged_mono_ns == d.t and hs.engaged_fc_us == d.t / 1e3 + 5


def test_offboard_waits_for_the_time_base():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    for _ in range(100):  # 2 s primed, time base not converged: no mode request
        hs.on_setpoint_sent(d.t)
        assert not [a for a in hs.step(d.t, timebase_ready=False) if isinstance(a, SendCommand)]
        d.t += 20 * MS
    assert hs.state == State.PRIMING
    assert any(isinstance(a, SendCommand) for a in hs.step(d.t, timebase_ready=True))


def test_a_gap_in_the_setpoints_restarts_the_priming():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(0.8)
    d.t += 600 * MS  # the stream stalls for 0.6 s > setpoint_gap_s
    d.run(0.8)
    assert not d.commands() and hs.state == State.PRIMING
    d.run(0.3)
    assert d.commands(176)


def test_denied_offboard_is_a_typed_error_naming_command_and_result():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(2.0, each=acking({176: deque([oh.DENIED])}))
    assert hs.state == State.FAILED and isinstance(hs.error, oh.CommandFailed)
    assert (hs.error.command, hs.error.result) == (176, oh.DENIED) and "DENIED" in str(hs.error)
    assert not d.commands(400)


@pytest.mark.parametrize("result", [oh.FAILED, oh.UNSUPPORTED, oh.CANCELLED])
def test_other_final_refusals_of_arming_fail(result):
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(2.0, each=acking({176: deque([oh.ACCEPTED]), 400: deque([result])}))
    assert hs.state == State.FAILED and hs.error.command == 400 and hs.error.result == result
    assert oh.result_name(result) in str(hs.error)


def test_temporarily_rejected_retried_every_half_second_then_accepted():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    TR = oh.TEMPORARILY_REJECTED
    d.run(4.0, each=acking({176: deque([TR, TR, TR, oh.ACCEPTED]), 400: deque([oh.ACCEPTED])}))
    sends = d.commands(176)
    assert len(sends) == 4 and all(a.confirmation == 0 for _, a in sends)
    gaps = [b[0] - a[0] for a, b in zip(sends, sends[1:])]
    assert gaps == [520 * MS] * 3  # each answered one 20 ms step after it went; again 0.5 s after the answer
    assert hs.state == State.WAIT_ENGAGED


def test_temporarily_rejected_for_ten_seconds_fails():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(13.0, each=acking({400: deque(), 176: deque([oh.TEMPORARILY_REJECTED] * 100)}))
    assert hs.state == State.FAILED and hs.error.result == oh.TEMPORARILY_REJECTED
    sends = d.commands(176)
    assert 20 <= len(sends) <= 22 and (sends[-1][0] - sends[0][0]) == pytest.approx(10 * S, abs=0.6 * S)


def test_no_ack_resent_with_confirmation_plus_one_then_timeout():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(4.0)
    sends = d.commands(176)
    assert [a.confirmation for _, a in sends] == [0, 1, 2, 3]
    assert [b[0] - a[0] for a, b in zip(sends, sends[1:])] == [500 * MS] * 3
    assert hs.state == State.FAILED and isinstance(hs.error, oh.CommandTimeout) and hs.error.sends == 4


def test_in_progress_waits_without_resending():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(1.2)
    (t0, _), = d.commands(176)
    hs.on_ack(d.t, 176, oh.IN_PROGRESS)
    d.run(1.2)
    assert len(d.commands(176)) == 1 and hs.state == State.REQUEST_OFFBOARD
    hs.on_ack(d.t, 176, oh.ACCEPTED)
    d.run(0.1)
    assert hs.state == State.ARMING


def test_switched_away_after_engagement_yields_and_never_rerequests():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(2.0, each=acking({176: deque([oh.ACCEPTED]), 400: deque([oh.ACCEPTED])}))
    d.heartbeat(OFFBOARD, ARMED)
    assert hs.state == State.ENGAGED
    n = len(d.commands())
    d.heartbeat(POSCTL, ARMED)
    assert hs.state == State.YIELDED and "POSCTL" in hs.yield_reason
    d.run(20.0, each=lambda d: d.heartbeat(POSCTL, ARMED))
    assert len(d.commands()) == n  # nothing more asked for
    assert any(isinstance(a, SendHeartbeat) for t, a in d.sent if t >= d.t - S)  # still announcing itself


def test_disarm_after_engagement_yields():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(2.0, each=acking({176: deque([oh.ACCEPTED]), 400: deque([oh.ACCEPTED])}))
    d.heartbeat(OFFBOARD, ARMED)
    d.heartbeat(OFFBOARD, 1)
    assert hs.state == State.YIELDED and "disarmed" in hs.yield_reason


def test_engage_timeout_when_the_heartbeat_never_shows_offboard_armed():
    hs = OffboardHandshake(engage_timeout_s=3.0)
    d = Driver(hs)
    d.heartbeat()
    d.run(6.0, each=acking({176: deque([oh.ACCEPTED]), 400: deque([oh.ACCEPTED])}))
    assert hs.state == State.FAILED and isinstance(hs.error, oh.EngageTimeout) and "POSCTL" in str(hs.error)


def test_not_px4_fails_and_silence_can_time_out():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat(autopilot=3)  # ArduPilot
    d.run(0.1)
    assert hs.state == State.FAILED and isinstance(hs.error, oh.NotPx4)
    hs = OffboardHandshake(wait_autopilot_s=2.0)
    d = Driver(hs)
    d.run(2.5)
    assert hs.state == State.FAILED and isinstance(hs.error, oh.AutopilotSilent)


def test_hand_back_asks_for_hold_and_yields():
    hs = OffboardHandshake()
    d = Driver(hs)
    d.heartbeat()
    d.run(2.0, each=acking({176: deque([oh.ACCEPTED]), 400: deque([oh.ACCEPTED])}))
    d.heartbeat(OFFBOARD, ARMED)
    hs.hand_back(d.t, "odometry stale")
    assert hs.state == State.YIELDED and "odometry stale" in hs.yield_reason
    d.run(0.1)
    (_, a), = [(t, a) for t, a in d.commands(176) if a.params[1] == px4.MAIN_AUTO]
    assert a.params[:3] == (1.0, 4.0, 3.0)  # AUTO.LOITER = HOLD
    hs.on_ack(d.t, 176, oh.ACCEPTED)
    assert hs.hand_back_command.done and hs.hand_back_command.error is None


def test_control_streams_at_the_loop_rate():
    assert oh.control_streams(250.0) == [(331, 4000), (31, 4000), (83, 4000), (105, 4000)]
    with pytest.raises(ValueError, match="rate_hz"):
        oh.control_streams(0)


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match="prime_s"):
        OffboardHandshake(prime_s=0)
    with pytest.raises(ValueError, match="ack_timeout_s"):
        oh.RetryPolicy(ack_timeout_s=-1)


# -- over the link, against the PX4-like endpoint ---------------------------------------------
def fly(link, fake, clock, hs, seconds, *, dt_ms=20, odometry=True, each=None):
    """The lead's loop in miniature: setpoints at 50 Hz, the fake's heartbeat at 1 Hz and
    ODOMETRY at 50 Hz, the link polled each step."""
    steps = round(seconds * 1000 / dt_ms)
    for k in range(steps):
        clock.advance(dt_ms * MS)
        if k % round(1000 / dt_ms) == 0:
            fake.heartbeat()
        if odometry:
            fake.odometry((0, 0, -1), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0))
        link.send_attitude_target((1, 0, 0, 0), (0, 0, 0), 0.0)
        fake.serve(0.001)
        link.poll(0.001)
        fake.serve(0.0)
        link.poll(0.0)
        if each is not None:
            each(k)


@pytest.fixture
def rig():
    clock = FakeClock()
    link = Px4Link(SYSID, "udpin:127.0.0.1:0", clock=clock).open()
    fake = FakePx4(SYSID, clock, rate=1.0)
    fake.dest = ("127.0.0.1", link.local_address[1])
    yield clock, link, fake
    link.close()
    fake.close()


def test_link_engages_against_the_px4_like_endpoint(rig):
    clock, link, fake = rig
    hs = OffboardHandshake(streams=[(mc.MAVLINK_MSG_ID_ODOMETRY, 10_000), (mc.MAVLINK_MSG_ID_HIGHRES_IMU, 10_000)])
    fake.interval_results[mc.MAVLINK_MSG_ID_HIGHRES_IMU] = mc.MAV_RESULT_DENIED
    link.attach(hs)
    t_start = clock()
    fly(link, fake, clock, hs, 3.0)
    assert hs.state == State.ENGAGED, (hs.state, hs.error)
    assert fake.main_mode == px4.MAIN_OFFBOARD and fake.armed
    assert len(hs.notes) == 1 and "DENIED" in hs.notes[0]
    (t_mode, m), = [(t, m) for t, m in fake.commands if m.command == mc.MAV_CMD_DO_SET_MODE]
    assert t_mode - fake.setpoints[0][0] >= S and (m.param1, m.param2) == (1, 6)
    assert [m.command for _, m in fake.commands] == [511, 511, 176, 400]
    beats = [t for t, _ in fake.heartbeats]
    assert len(beats) >= 2 and all(b - a == S for a, b in zip(beats, beats[1:]))
    assert link.timebase.converged
    assert hs.engaged_fc_us == pytest.approx(fake.fc_us(hs.engaged_mono_ns), abs=2.0)
    assert hs.engaged_mono_ns > t_start


def test_link_offboard_denied_is_a_typed_error(rig):
    clock, link, fake = rig
    fake.results[mc.MAV_CMD_DO_SET_MODE] = deque([mc.MAV_RESULT_DENIED])
    hs = OffboardHandshake()
    link.attach(hs)
    fly(link, fake, clock, hs, 2.5)
    assert hs.state == State.FAILED and isinstance(hs.error, oh.CommandFailed)
    assert hs.error.command == mc.MAV_CMD_DO_SET_MODE and hs.error.result == mc.MAV_RESULT_DENIED
    assert not fake.commands_of(mc.MAV_CMD_COMPONENT_ARM_DISARM) and not fake.armed


def test_link_temporarily_rejected_then_accepted(rig):
    clock, link, fake = rig
    TR = mc.MAV_RESULT_TEMPORARILY_REJECTED
    fake.results[mc.MAV_CMD_DO_SET_MODE] = deque([TR, TR])
    fake.results[mc.MAV_CMD_COMPONENT_ARM_DISARM] = deque([TR])
    hs = OffboardHandshake()
    link.attach(hs)
    fly(link, fake, clock, hs, 4.0)
    assert hs.state == State.ENGAGED, (hs.state, hs.error)
    modes = [t for t, m in fake.commands if m.command == mc.MAV_CMD_DO_SET_MODE]
    arms = [t for t, m in fake.commands if m.command == mc.MAV_CMD_COMPONENT_ARM_DISARM]
    assert len(modes) == 3 and len(arms) == 2
    assert all(b - a >= 500 * MS for a, b in zip(modes, modes[1:]))


def test_link_switched_away_after_engagement_yields_without_rerequest(rig):
    clock, link, fake = rig
    hs = OffboardHandshake()
    link.attach(hs)
    fly(link, fake, clock, hs, 3.0)
    assert hs.state == State.ENGAGED
    fake.set_mode(px4.MAIN_POSCTL)  # the pilot takes over
    fly(link, fake, clock, hs, 5.0)
    assert hs.state == State.YIELDED and "POSCTL" in hs.yield_reason
    assert len(fake.commands_of(mc.MAV_CMD_DO_SET_MODE)) == 1 and fake.main_mode == px4.MAIN_POSCTL


def test_link_stale_setpoints_make_px4_refuse_offboard(rig):
    """PX4's offboard check: no setpoint within COM_OF_LOSS_T -> TEMPORARILY_REJECTED (the fake
    plays it); the handshake does not even ask before a second of setpoints."""
    clock, link, fake = rig
    hs = OffboardHandshake()
    link.attach(hs)
    for _ in range(150):  # 3 s, no setpoints
        clock.advance(20 * MS)
        fake.heartbeat()
        fake.serve(0.001)
        link.poll(0.001)
    assert hs.state == State.PRIMING and not fake.commands_of(mc.MAV_CMD_DO_SET_MODE)
