"""The time base against a synthetic autopilot clock: offset, speed 0.5 / 1 / 2, jittery legs.

The bounds are the module's (amlink/timebase.py): each sample within B = rate * J / 2 for legs
jittering over J; the converged fit within 2 B up to one exchange period past its newest sample
(the least-squares line's Lebesgue constant, <= 1.86 for 8..32 evenly spaced samples), its rate
within 4 B / span; plus the autopilot's 1 us quantization.
"""
from __future__ import annotations

import random

import pytest

from amlink.timebase import Timebase

MS = 1_000_000
PERIOD = 100 * MS  # 10 Hz exchanges


class Autopilot:
    """fc_us(t) = boot_us + rate * (t - t0) / 1000, answering as PX4: tc1 = floor(us) * 1000."""

    def __init__(self, rate: float, boot_us: float = 987_654_321.0, t0: int = 5_000 * 10**9) -> None:
        self.rate, self.boot_us, self.t0 = rate, boot_us, t0

    def fc_us(self, t: float) -> float:
        return self.boot_us + self.rate * (t - self.t0) / 1000.0

    def tc1(self, t: float) -> int:
        return int(self.fc_us(t)) * 1000


def exchange(tb: Timebase, ap: Autopilot, t0: int, up: float, down: float) -> bool:
    ts1 = tb.request(t0)
    return tb.on_answer(ap.tc1(t0 + up), ts1, int(t0 + up + down))


def run(rate, jitter_ns, seed, *, n=60, base_ns=200_000, asym_ns=0, spikes=0.0, check=None):
    rng = random.Random(seed)
    ap = Autopilot(rate)
    tb = Timebase()
    t = ap.t0 + 1234
    for _ in range(n):
        up = base_ns + rng.uniform(0, jitter_ns)
        down = base_ns + asym_ns + rng.uniform(0, jitter_ns)
        if spikes and rng.random() < spikes:  # a scheduling hiccup: one leg 20-60 ms late
            up += rng.uniform(20, 60) * MS
        exchange(tb, ap, t, up, down)
        if check is not None and tb.converged:
            check(tb, ap, t)
        t += PERIOD
    return tb, ap, t


@pytest.mark.parametrize("rate", [0.5, 1.0, 2.0])
@pytest.mark.parametrize("jitter_ms", [0.0, 1.0, 4.0])
def test_offset_and_rate_recovered_within_the_stated_bounds(rate, jitter_ms):
    J = jitter_ms * MS
    B_us = rate * J / 2 / 1000.0
    worst = {"e": 0.0, "r": 0.0}

    def check(tb, ap, t):
        span = (tb.samples - 1) * PERIOD
        for q in range(0, PERIOD + 1, PERIOD // 5):
            e = abs(tb.fc_time_us(t + q) - ap.fc_us(t + q))
            assert e <= 2 * B_us + 2.0, (t, q, e)
            worst["e"] = max(worst["e"], e)
        r = abs(tb.rate - rate)
        assert r <= 4 * B_us * 1000 / span + 1e-5
        worst["r"] = max(worst["r"], r)

    for seed in range(8):
        tb, ap, t = run(rate, J, seed, check=check)
        assert tb.converged and tb.accepted == 60
        assert tb.mono_ns(tb.fc_time_us(t)) == pytest.approx(t, abs=2)
        assert abs(tb.mono_ns(ap.fc_us(t)) - t) <= (2 * B_us + 2.0) * 1000 / rate
    if jitter_ms:
        assert worst["e"] > 0.05 * B_us  # the check saw the jitter (the bound is not vacuous)


def test_an_asymmetry_of_the_legs_biases_by_half_of_it():
    asym = 3 * MS
    tb, ap, t = run(2.0, 0.0, 0, asym_ns=asym)
    # the autopilot read its clock asym / 2 before the midpoint: the estimate lags by rate * asym / 2
    assert ap.fc_us(t) - tb.fc_time_us(t) == pytest.approx(2.0 * asym / 2 / 1000, abs=2.0)


def test_slow_round_trips_are_not_used_and_spikes_do_not_move_the_estimate():
    tb, ap, t = run(1.0, 0.5 * MS, 3, n=200, spikes=0.15)
    assert tb.rejected_rtt > 10 and tb.converged
    assert abs(tb.fc_time_us(t) - ap.fc_us(t)) <= 2 * 250.0 + 2.0  # 2 B, B = rate * J / 2 = 250 us


def test_not_ready_before_a_sample_and_converged_after_min_samples_over_half_a_second():
    tb, ap = Timebase(), Autopilot(1.0)
    assert tb.fc_time_us(10**12) is None and tb.mono_ns(1.0) is None and tb.rate is None and not tb.ready
    t = ap.t0
    for k in range(8):
        exchange(tb, ap, t, 100_000, 100_000)
        assert tb.ready and tb.converged == (k == 7)  # 8 samples spanning 0.7 s
        t += PERIOD
    assert tb.rtt_ns == 200_000


def test_answers_to_no_request_of_ours_are_not_samples():
    tb, ap = Timebase(), Autopilot(1.0)
    ts1 = tb.request(ap.t0)
    assert not tb.on_answer(ap.tc1(ap.t0), ts1 + 1, ap.t0 + MS)  # not our ts1
    assert tb.on_answer(ap.tc1(ap.t0), ts1, ap.t0 + MS)
    assert not tb.on_answer(ap.tc1(ap.t0), ts1, ap.t0 + MS)  # a duplicate
    t = ap.t0 + PERIOD
    ts1 = tb.request(t)
    assert not tb.on_answer(0, ts1, t + MS)  # tc1 0 is a request, not an answer
    assert not tb.on_answer(ap.tc1(t), tb.request(t + MS), t)  # received before it was sent
    assert tb.unmatched == 4 and tb.accepted == 1
    with pytest.raises(ValueError, match="ts1"):
        tb.request(0)


def test_a_rate_change_is_followed():
    """SITL's speed changes from 1 to 2 at t1: the estimate follows within one window."""
    tb = Timebase()
    ap1 = Autopilot(1.0)
    t = ap1.t0
    for _ in range(40):
        exchange(tb, ap1, t, 200_000, 200_000)
        t += PERIOD
    t1 = t
    ap2 = Autopilot(2.0, boot_us=ap1.fc_us(t1), t0=t1)
    for _ in range(45):
        exchange(tb, ap2, t, 200_000, 200_000)
        t += PERIOD
    assert tb.rate == pytest.approx(2.0, rel=1e-6) and tb.converged
    assert abs(tb.fc_time_us(t) - ap2.fc_us(t)) < 2.0


def test_a_time_jump_resets_after_five_deviant_samples():
    """The autopilot reboots: its clock starts again near zero."""
    tb = Timebase()
    ap = Autopilot(1.0)
    t = ap.t0
    for _ in range(20):
        exchange(tb, ap, t, 100_000, 100_000)
        t += PERIOD
    rebooted = Autopilot(1.0, boot_us=1_000.0, t0=t)
    results = []
    for _ in range(16):
        results.append(exchange(tb, rebooted, t, 100_000, 100_000))
        t += PERIOD
    assert results[:5] == [False] * 5 and results[5]  # 5 rejected, the 6th starts the new estimate
    assert tb.resets == 1 and tb.rejected_deviation == 6 and tb.converged
    assert abs(tb.fc_time_us(t) - rebooted.fc_us(t)) < 2.0


def test_bad_parameters_are_named():
    with pytest.raises(ValueError, match="max_rtt_ns"):
        Timebase(max_rtt_ns=0)
    with pytest.raises(ValueError, match="min_samples"):
        Timebase(min_samples=1)


def test_a_slow_link_converges_with_its_cut_at_twice_its_fastest_round_trip():
    """20 ms of latency up and 0-4 ms of jitter (a 10 ms link delay at half speed): PX4's 10 ms
    cut would take no sample; the cut moves to twice the fastest round trip, the samples within
    it converge, and the estimate is off by half the legs' asymmetry, as any two-way exchange."""
    rng = random.Random(4)
    ap, tb = Autopilot(0.5), Timebase()
    t = ap.t0 + 1234
    for k in range(60):
        up = 20 * MS + rng.uniform(0, 4 * MS)
        down = 0.2 * MS + rng.uniform(0, 0.5 * MS) + (80 * MS if k % 10 == 5 else 0)  # every 10th: a spike
        exchange(tb, ap, t, up, down)
        t += PERIOD
    assert tb.converged and tb.rejected_rtt == 6 and tb.accepted == 54
    assert 2 * 20 * MS <= tb.rtt_cut_ns <= 2 * 21 * MS
    # the legs' mean asymmetry, 22 - 0.45 ms: the estimate runs rate * 21.55 / 2 ms ahead of the
    # autopilot's clock (it places each reading at the midpoint, before the autopilot made it),
    # within the fit's bound for the 4 ms of jitter (2 B, B = rate * J / 2)
    ahead_us = tb.fc_time_us(t) - ap.fc_us(t)
    assert ahead_us == pytest.approx(0.5 * 21.55 * MS / 2 / 1000, abs=2 * 0.5 * 4 * MS / 2 / 1000)


def test_a_local_link_keeps_px4_s_cut():
    tb = Timebase()
    ap = Autopilot(1.0)
    exchange(tb, ap, ap.t0 + 1, 0.3 * MS, 0.3 * MS)
    assert tb.rtt_cut_ns == 10 * MS
    assert not exchange(tb, ap, ap.t0 + 100 * MS, 9 * MS, 2 * MS)  # 11 ms: beyond PX4's MAX_RTT_SAMPLE
