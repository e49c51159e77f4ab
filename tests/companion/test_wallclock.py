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
                 yield_at_s=None) -> None:
        self.clock, self.rate, self.odo_hz, self.odo_until_s = clock, rate, odo_hz, odo_until_s
        self.t_start = clock.t
        self.engage_s, self.yield_at_s = engage_s, yield_at_s
        x = pilot.mission.initial_state()
        self.p = tuple(x.p_WB.tolist())
        self.q = (1.0, 0.0, 0.0, 0.0)
        self.odometry = self.attitude = self.attitude_target = None
        self.odometry_rx_ns = None
        self.sent, self.idle, self.handed_back = [], 0, None
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
    ap_kw = {k: kw.pop(k) for k in list(kw) if k in ("engage_s", "odo_hz", "rate", "odo_until_s", "yield_at_s")}
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
