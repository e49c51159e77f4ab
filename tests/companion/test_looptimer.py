"""The wall-clock loop's timer: drift-free deadlines, misses counted, no catch-up bursts."""
from companion.looptimer import DeadlineTimer, LoopStats


class FakeClock:
    def __init__(self, t_ns: int = 1_000_000_000) -> None:
        self.t = t_ns

    def __call__(self) -> int:
        return self.t


def test_deadlines_do_not_drift_with_late_wakeups():
    clk = FakeClock()
    timer = DeadlineTimer(4_000_000, clk)  # 250 Hz
    timer.start()
    t0 = clk.t
    for k in range(1000):
        clk.t = t0 + k * 4_000_000 + 300_000  # every wake-up 0.3 ms late
        assert timer.fire() == 300_000
    # the 1000th deadline is where 1000 periods put it, not 1000 * 0.3 ms later
    assert timer.deadline_ns() == t0 + 1000 * 4_000_000
    assert timer.misses == 0 and timer.worst_late_ns == 300_000


def test_a_miss_is_counted_and_past_deadlines_are_skipped():
    clk = FakeClock()
    timer = DeadlineTimer(4_000_000, clk)
    timer.start()
    t0 = clk.t
    clk.t = t0 + 10 * 4_000_000 + 1_000  # the first step starts ten periods late
    late = timer.fire()
    assert late == 10 * 4_000_000 + 1_000
    assert timer.misses == 1 and timer.skipped == 10
    assert timer.deadline_ns() == t0 + 11 * 4_000_000  # the next deadline ahead, no burst
    assert timer.wait_s() > 0


def test_period_change_keeps_the_next_deadline():
    clk = FakeClock()
    timer = DeadlineTimer(4_000_000, clk)
    timer.start()
    clk.t += 4_000_000
    timer.fire()
    nxt = timer.deadline_ns()
    timer.set_period(8_000_000)  # an autopilot clock at half speed
    assert timer.deadline_ns() == nxt
    clk.t = nxt
    timer.fire()
    assert timer.deadline_ns() == nxt + 8_000_000


def test_stats_report_quantiles_misses_and_ages():
    clk = FakeClock()
    timer = DeadlineTimer(4_000_000, clk)
    stats = LoopStats()
    timer.start()
    for k in range(100):
        clk.t = timer.deadline_ns() + (k % 10) * 10_000
        late = timer.fire()
        stats.step_started(clk.t, late)
        stats.sample_age("odometry", 5_000_000 + k, stale=k >= 98)
        stats.sent(clk.t, clk.t - 2_000_000, clk.t + 100_000)
    d = stats.to_dict(timer)
    assert d["deadline_misses"] == 0
    assert d["stale_steps"]["odometry"] == 2
    assert abs(d["period_ms"]["p50"] - 4.0) < 0.1
    assert d["lateness_ms"]["max"] == 0.09
    assert abs(d["sample_to_setpoint_ms"]["p50"] - 2.1) < 1e-9
    assert d["sample_age_ms"]["odometry"]["n"] == 100
