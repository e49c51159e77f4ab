"""The wall-clock loop against a scripted autopilot, servo bus and F/T sensor on a fake clock:
the mission clock from the engage, the idle stream before it, 30 Hz odometry under a 250 Hz
loop, stale inputs held then handed back, a mode switched away yielded to."""
from __future__ import annotations

import numpy as np
import pytest

from amcore.config import load_scenario
from amcore.mission import TAKEOFF_S
from amlink.px4samples import Attitude, Odometry
from companion.devices import DeviceError
from companion.pilot import Pilot
from companion.sampling import StalenessLimits
from companion.wallclock import WallClockLoop

SCENARIO = "configs/scenarios/two_am_comp_attitude.toml"


class Clock:
    def __init__(self) -> None:
        self.t = 10_000_000_000

    def __call__(self) -> int:
        return self.t


class FakeAutopilot:
    """Engages at `engage_s` of its own clock (= ours + 5 s, at `rate`); odometry every
    1 / odo_hz of the vehicle standing still at `p`."""

    def __init__(self, clock: Clock, pilot: Pilot, engage_s=2.0, odo_hz=30.0, rate=1.0, odo_until_s=1e9,
                 yield_at_s=None, armed=False) -> None:
        self.armed = armed
        self.clock, self.rate, self.odo_hz, self.odo_until_s = clock, rate, odo_hz, odo_until_s
        self.t_start = clock.t
        self.engage_s, self.yield_at_s = engage_s, yield_at_s
        x = pilot.mission.initial_state()
        self.p = tuple(x.p_WB.tolist())
        self.q = (1.0, 0.0, 0.0, 0.0)
        self.odometry = self.attitude = self.attitude_target = None
        self.odometry_rx_ns = None
        self.sent, self.idle, self.handed_back = [], 0, None
        self.idle_targets = []
        self.engaged_fc_us = None
        self.error = None
        self._next_odo = 0.0

    def _fc_s(self, now_ns):
        return 5.0 + (now_ns - self.t_start) * 1e-9 * self.rate

    def wait(self, s):
        self.clock.t += max(1, round(s * 1e9))

    def poll(self, now_ns=None):
        fc = self._fc_s(self.clock.t)
        while fc >= self._next_odo and self._next_odo <= 5.0 + self.odo_until_s:
            t_us = self._next_odo * 1e6
            self.odometry = Odometry(t_us, self.p, self.q, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0, 100, 1)
            self.attitude = Attitude(t_us, self.q, (0.0, 0.0, 0.0))
            self.odometry_rx_ns = self.clock.t
            self._next_odo += 1.0 / self.odo_hz

    def clock_rate(self):
        return self.rate

    def fc_time_us(self, now_ns):
        return self._fc_s(now_ns) * 1e6

    def silent_for_s(self, now_ns):
        return 0.0

    @property
    def state(self):
        fc = self._fc_s(self.clock.t)
        if self.handed_back:
            return "yielded"
        if self.yield_at_s is not None and fc >= 5.0 + self.yield_at_s:
            self.error = "the mode was switched to POSCTL after engagement"
            return "yielded"
        if fc >= 5.0 + self.engage_s:
            self.engaged_fc_us = self.engaged_fc_us or fc * 1e6
            return "engaged"
        return "priming"

    def stream_idle(self, att):
        self.idle += 1
        self.idle_targets.append(att)
        if not self.armed:
            assert att.thrust_normalized == 0.0

    def send_setpoint(self, att):
        self.sent.append((self.clock.t, att))

    def hand_back(self, reason):
        self.handed_back = reason


class FakeArm:
    def __init__(self, n, clock, fail_after=None):
        self.n, self.clock, self.fail_after = n, clock, fail_after
        self.reads, self.written, self.current = 0, [], False

    def read(self):
        self.reads += 1
        if self.fail_after is not None and self.reads > self.fail_after:
            raise DeviceError("servo bus tcp:127.0.0.1:7200: no servo answering ID 1")
        from companion.devices.arm import JointSample
        self.clock.t += 300_000  # a 0.3 ms bus transaction
        return JointSample(np.array([0.0, 0.9, -0.9])[: self.n], np.zeros(self.n), np.zeros(self.n), self.clock.t,
                           300_000)

    def start_current_control(self):
        self.current = True

    def write_torques(self, tau):
        assert self.current, "current control before the first torque"
        self.written.append(np.array(tau))


@pytest.fixture(scope="module")
def spec():
    return load_scenario(SCENARIO)


def _loop(spec, **kw):
    clock = Clock()
    pilot = Pilot(spec, spec.ams[0].sysid)
    ap_kw = {k: kw.pop(k) for k in list(kw) if k in ("engage_s", "odo_hz", "rate", "odo_until_s", "yield_at_s",
                                                        "armed")}
    ap = FakeAutopilot(clock, pilot, **ap_kw)
    arm = FakeArm(pilot.model.n, clock, kw.pop("fail_after", None))
    loop = WallClockLoop(pilot, ap, arm, None, clock=clock, **kw)
    return loop, ap, arm, clock, pilot


def test_mission_clock_starts_at_the_engage_and_the_loop_keeps_its_rate(spec):
    loop, ap, arm, clock, pilot = _loop(spec, engage_s=1.0, odo_hz=30.0)
    stop_at = clock.t + round(6.0 * 1e9)
    res = loop.run(stop=lambda: clock.t >= stop_at)
    assert res.code == 0 and res.why == "stopped"
    assert ap.idle >= 200  # ~1 s of idle stream at 250 Hz before the engage
    assert loop.t0_fc_us == pytest.approx(ap.engaged_fc_us + TAKEOFF_S * 1e6)
    # ~5 s engaged at 250 Hz, a setpoint and a torque write every step
    assert len(ap.sent) == len(arm.written) == res.steps
    assert abs(res.steps - 5.0 * 250) <= 3
    period = np.diff([t for t, _ in ap.sent]) * 1e-9
    assert np.median(period) == pytest.approx(0.004, abs=1e-6)
    assert res.stats["deadline_misses"] == 0
    # 30 Hz odometry: its age when read spans up to a period (plus the bus read)
    age = res.stats["sample_age_ms"]["odometry"]
    assert 30.0 < age["max"] < 34.0
    # in the take-off, the thrust rises from the ground's towards hover
    thrusts = [a.thrust_normalized for _, a in ap.sent]
    assert 0.0 < thrusts[0] < 1.0 and all(np.isfinite(thrusts))


def test_an_armed_vehicle_is_flown_by_the_controller_from_the_priming_on(spec):
    """A companion started while its vehicle is armed (a restart; PX4 may be in OFFBOARD, or go
    there when its failover clears on the first setpoint) primes OFFBOARD with the controller's
    own setpoints, so the take-over is bumpless; its mission clock counts from the first."""
    logs = []
    loop, ap, arm, clock, pilot = _loop(spec, engage_s=1.0, armed=True, log=logs.append)
    stop_at = clock.t + round(1.5 * 1e9)
    loop.run(stop=lambda: clock.t >= stop_at)
    before = [a for t, a in ap.sent if ap._fc_s(t) < 5.0 + 1.0]
    assert len(before) >= 200 and arm.current  # ~1 s of the controller's setpoints before the engage
    assert 0.0 < before[0].thrust_normalized < 1.0
    assert ap.idle <= 2 and any("the vehicle is armed" in m for m in logs), logs
    assert loop.t0_fc_us == pytest.approx(5.0e6 + TAKEOFF_S * 1e6, abs=1e4)


def test_the_idle_target_before_the_controller_flies(spec):
    """Before any HEARTBEAT: nothing. Disarmed: level, zero thrust. Armed (before the controller
    flies): the reported attitude at the AM's hover thrust, m g over thrust 1's force; nothing
    without a report."""
    loop, ap, arm, clock, pilot = _loop(spec)
    ap.attitude = Attitude(0, (0.9998477, 0.0, 0.0174524, 0.0), (0.0, 0.0, 0.0))
    ap.armed = None
    assert loop._idle_target() is None
    ap.armed = False
    idle = loop._idle_target()
    assert idle.thrust_normalized == 0.0 and np.allclose(idle.quat_wxyz[1:3], 0.0)
    ap.armed = True
    hover = pilot.model.mass_kg * spec.vehicle.gravity_mps2 / pilot.thrust_max_n
    assert 0.2 < hover < 0.9
    idle = loop._idle_target()
    assert idle.thrust_normalized == pytest.approx(hover) and np.allclose(idle.quat_wxyz, ap.attitude.q_WB_wxyz)
    ap.attitude = None
    assert loop._idle_target() is None


def test_an_autopilot_clock_at_half_speed_halves_the_loops_wall_rate(spec):
    loop, ap, arm, clock, _ = _loop(spec, engage_s=0.5, rate=0.5)
    stop_at = clock.t + round(4.0 * 1e9)
    res = loop.run(stop=lambda: clock.t >= stop_at)
    period = np.diff([t for t, _ in ap.sent]) * 1e-9
    assert np.median(period) == pytest.approx(0.008, abs=1e-6)  # 250 Hz of the autopilot's time
    assert res.stats["deadline_misses"] == 0


def test_stale_odometry_holds_then_hands_back(spec):
    limits = StalenessLimits()
    loop, ap, arm, clock, _ = _loop(spec, engage_s=0.5, odo_until_s=1.5, limits=limits)
    res = loop.run(stop=lambda: False)
    assert res.code == 1 and "handed back" in res.why and "odometry" in res.why
    assert ap.handed_back is not None
    # held: the last setpoint re-sent while stale, for handback_s after the limit
    assert res.held_steps == pytest.approx(limits.handback_s * 250, abs=3)
    last_fresh = 5.0 + 1.5
    t_end = ap._fc_s(clock.t)
    assert t_end == pytest.approx(last_fresh + limits.odometry_hold_s + limits.handback_s, abs=0.02)


def test_a_silent_servo_bus_holds_then_hands_back(spec):
    loop, ap, arm, clock, _ = _loop(spec, engage_s=0.5, fail_after=400)
    res = loop.run(stop=lambda: False)
    assert res.code == 1 and "joints" in res.why
    assert loop.arm_errors > 100


def test_a_mode_switched_away_is_yielded_to(spec):
    loop, ap, arm, clock, _ = _loop(spec, engage_s=0.5, yield_at_s=2.0)
    res = loop.run(stop=lambda: False)
    assert res.code == 0 and res.why.startswith("yielded") and "POSCTL" in res.why
    assert ap.handed_back is None  # it does not fight back, nor ask for anything


@pytest.mark.parametrize("stall_s, rate, yields", [(1.2, 1.0, True), (0.8, 1.0, False), (1.6, 0.5, False),
                                                   (2.4, 0.5, True)])
def test_a_stall_past_the_offboard_loss_timeout_yields_without_sending(spec, stall_s, rate, yields):
    """The process stops for stall_s of wall time once engaged (SIGSTOP, a starved host). Past
    COM_OF_LOSS_T of the autopilot's clock (1 s; at half speed, 2 s of wall time) PX4 has failed
    over: the loop yields and sends nothing more, since a late setpoint would clear the failover.
    Under it, the loop flies on."""
    loop, ap, arm, clock, _ = _loop(spec, engage_s=0.5, rate=rate)
    stalled = []

    def stall(t, phase, res):
        if not stalled and t > -TAKEOFF_S + 0.5:
            stalled.append(len(ap.sent))
            clock.t += round(stall_s * 1e9)

    loop.on_step = stall
    stop_at = clock.t + round(5.0 / rate * 1e9)
    res = loop.run(stop=lambda: clock.t >= stop_at)
    assert stalled
    if yields:
        assert res.code == 0 and res.why.startswith("yielded") and "COM_OF_LOSS_T" in res.why, res.why
        assert len(ap.sent) == stalled[0] and ap.handed_back is None
    else:
        assert res.why == "stopped" and len(ap.sent) > stalled[0] + 100


class SplitArm(FakeArm):
    """An arm client with the split sync read (request, collect): records the order of events."""

    def __init__(self, n, clock, events):
        super().__init__(n, clock)
        self.events, self._out = events, False

    @property
    def requested(self):
        return self._out

    def request(self):
        assert not self._out, "a second request before the first was collected"
        self._out = True
        self.events.append("request")

    def collect(self):
        assert self._out, "collect without a request"
        self._out = False
        self.events.append("collect")
        return FakeArm.read(self)

    def read(self):
        self.events.append("read")
        return FakeArm.read(self)


def test_the_servo_read_is_requested_before_the_link_is_served_and_collected_each_step(spec):
    clock = Clock()
    pilot = Pilot(spec, spec.ams[0].sysid)
    ap = FakeAutopilot(clock, pilot, engage_s=0.5)
    events = []
    polled = ap.poll

    def poll(now_ns=None):
        events.append("poll")
        return polled(now_ns)

    ap.poll = poll
    arm = SplitArm(pilot.model.n, clock, events)
    loop = WallClockLoop(pilot, ap, arm, None, clock=clock)
    stop_at = clock.t + round(2.0 * 1e9)
    res = loop.run(stop=lambda: clock.t >= stop_at)
    assert res.steps > 100 and len(arm.written) == res.steps
    engaged = events[events.index("request"):]
    # every engaged step: request, then the link, then the answers; never a blocking read
    assert "read" not in engaged and not arm.requested
    steps = [engaged[k:k + 3] for k in range(0, len(engaged) - 2, 3)]
    assert all(s == ["request", "poll", "collect"] for s in steps[1:])
    assert engaged.count("collect") == res.steps


class _Tb:
    ready, converged = True, True

    def __init__(self, rate, rtt_ns):
        self.rate, self.rtt_ns = rate, rtt_ns


class _Store:
    def __init__(self, samples):
        self.samples = samples

    def latest(self, source):
        return self.samples.get(source)


class _Link:
    """What Autopilot.fc_time_us reads of a Px4Link: a TIMESYNC line that runs 2 % fast, the store."""

    def __init__(self, samples, rate=1.0, rtt_ns=400_000):
        self.timebase, self.store = _Tb(rate * 1.02, rtt_ns), _Store(samples)
        self.rate = rate

    def attach(self, _hs):
        pass

    def fc_time_us(self, now_ns):
        return now_ns * 1e-3 * self.timebase.rate


def test_the_autopilot_time_is_anchored_on_the_newest_sample_not_on_the_fitted_line():
    from amlink.px4samples import Sample
    from companion.autopilot import ANCHOR_MAX_NS, Autopilot

    now = 1_000_000_000
    # attitude sent at autopilot time 500.0 ms, received 0.2 ms later, 3 ms ago
    att = Sample("attitude", None, 500_000, now - 3_000_000, 1, 0)
    odo = Sample("odometry", None, 480_000, now - 20_000_000, 1, 0)
    ap = Autopilot(_Link({"attitude": att, "odometry": odo}, rate=0.5), handshake=None)
    t = ap.fc_time_us(now)
    # carried 3 ms at the autopilot's rate (x 1.02 as the line says) plus half the 0.4 ms round trip
    assert t == pytest.approx(500_000 + 3_000 * 0.51 + 200 * 0.51)
    # the odometry's age from it: what the autopilot's clock ran since, not the line's 2 % drift
    assert (t - odo.fc_us) * 1e-3 == pytest.approx(21.6, abs=0.1)
    # a silent autopilot (nothing for longer than ANCHOR_MAX_NS): the line, so ages keep growing
    late = now + ANCHOR_MAX_NS + 1
    assert ap.fc_time_us(late) == pytest.approx(late * 1e-3 * 0.51)


@pytest.mark.parametrize("mission_start_s, first_t, blend_s", [
    (9.0, -3.0, 3.0),  # engaged 3 s before the team's start: the take-off blends into it
    (6.5, -0.5, 3.0),  # engaged late, 0.5 s before it: the blend lasts [mission].join_blend_s
    (5.5, 0.5, 3.0),  # engaged after it (a restart): the mission joined in progress, the restart's blend
])
def test_a_shared_mission_start_counts_whenever_the_companion_engages(spec, mission_start_s, first_t, blend_s):
    """--mission-start is the team's clock: the companion engaged at autopilot time 6.0 s keeps
    it, and its references blend from where the vehicle is at its first step."""
    logs = []
    loop, ap, arm, clock, pilot = _loop(spec, engage_s=1.0, mission_start_s=mission_start_s, log=logs.append)
    stop_at = clock.t + round(2.5 * 1e9)
    res = loop.run(stop=lambda: clock.t >= stop_at)
    assert res.code == 0
    assert loop.t0_fc_us == pytest.approx(mission_start_s * 1e6)
    blend = pilot._blend
    assert blend is not None and blend.t0 == pytest.approx(first_t, abs=0.01) and blend.duration_s == blend_s
    assert any("joining the mission" in m for m in logs) == (first_t > 0)
