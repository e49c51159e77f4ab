"""Sim-time link impairment: statistics, exact delays, determinism, never newer-then-older."""

from __future__ import annotations

import math

import pytest

from amlink.impair import ImpairedChannel, ImpairedLink, LinkImpairment, ZeroOrderHold

N = 20_000


def schedule(imp: LinkImpairment, n: int = N, stream: int = 0) -> list[list[tuple[int, int]]]:
    """Arrivals (sent step, item) at each of ``n`` steps when step k sends item k."""
    ch = ImpairedChannel(imp, imp.rng(stream))
    out = []
    for k in range(n):
        ch.send(k, k)
        out.append(ch.deliver(k))
    return out


def test_ideal_link_delivers_every_setpoint_at_its_own_step():
    imp = LinkImpairment()
    assert imp.is_ideal
    assert schedule(imp, 100) == [[(k, k)] for k in range(100)]


@pytest.mark.parametrize("loss", [0.05, 0.2, 0.5])
def test_loss_rate_matches_within_five_sigma(loss):
    arrivals = schedule(LinkImpairment(loss=loss, seed=3))
    delivered = sum(len(a) for a in arrivals)
    sigma = math.sqrt(loss * (1 - loss) / N)
    assert abs((1 - delivered / N) - loss) < 5 * sigma


def test_duplicate_rate_matches_and_copies_come_one_step_later():
    imp = LinkImpairment(duplicate=0.1, seed=4)
    ch = ImpairedChannel(imp, imp.rng())
    first: dict[int, int] = {}
    copies = 0
    for k in range(N):
        ch.send(k, k)
        for sent, _item in ch.deliver(k):
            if sent in first:
                copies += 1
                assert k == first[sent] + 1
            else:
                first[sent] = k
    assert abs(copies / N - 0.1) < 5 * math.sqrt(0.09 / N)
    assert ch.stats.duplicated == copies


@pytest.mark.parametrize("delay_s,rate_hz,steps", [(0.005, 1000.0, 5), (0.02, 500.0, 10), (0.0004, 1000.0, 0)])
def test_fixed_delay_shifts_every_setpoint_by_whole_steps(delay_s, rate_hz, steps):
    arrivals = schedule(LinkImpairment(delay_s=delay_s, rate_hz=rate_hz), 200)
    for k, a in enumerate(arrivals):
        assert a == ([(k - steps, k - steps)] if k >= steps else [])
    link = ImpairedLink(LinkImpairment(delay_s=delay_s, rate_hz=rate_hz))
    held = [link.step(k, f"sp{k}") for k in range(50)]
    assert held == [None] * steps + [f"sp{k}" for k in range(50 - steps)]  # zero-order hold of a delayed stream


def test_jitter_stays_within_its_bound_and_spreads():
    imp = LinkImpairment(delay_s=0.002, jitter_s=0.003, rate_hz=1000.0, seed=5)
    lags = [k - sent for k, a in enumerate(schedule(imp, 5000)) for sent, _ in a]
    assert min(lags) == 2 and max(lags) == 5 and set(lags) == {2, 3, 4, 5}


def test_same_seed_same_schedule_other_seed_or_stream_differs():
    imp = LinkImpairment(loss=0.1, jitter_s=0.004, reorder=0.2, duplicate=0.05, seed=11)
    assert schedule(imp, 3000) == schedule(imp, 3000)
    assert schedule(imp, 3000) != schedule(LinkImpairment(**{**imp.__dict__, "seed": 12}), 3000)
    assert schedule(imp, 3000, stream=2) != schedule(imp, 3000, stream=3)


def test_reordering_happens_but_the_flight_controller_never_goes_back_in_time():
    imp = LinkImpairment(loss=0.1, jitter_s=0.003, reorder=0.3, duplicate=0.1, seed=6)
    arrivals = schedule(imp, N)
    order = [sent for a in arrivals for sent, _ in a]
    assert any(b < a for a, b in zip(order, order[1:]))  # out-of-order arrivals exist
    hold = ZeroOrderHold()
    applied = []
    for a in arrivals:
        hold.update(a)
        applied.append(hold.step)
    assert all(b >= a for a, b in zip(applied, applied[1:]))  # never newer-then-older
    assert hold.stale > 0


def test_zero_order_hold_keeps_the_last_command_through_losses():
    link = ImpairedLink(LinkImpairment(loss=0.5, seed=7))
    held = [link.step(k, k) for k in range(2000)]
    for k, h in enumerate(held):
        assert h is None or h <= k
        if h is not None and k > 0 and held[k - 1] is not None:
            assert h >= held[k - 1]
    assert link.channel.stats.lost > 0 and held[-1] is not None


def test_skipped_steps_deliver_late_and_time_only_goes_forward():
    imp = LinkImpairment(delay_s=0.003)
    ch = ImpairedChannel(imp, imp.rng())
    ch.send(0, "a")
    assert ch.deliver(10) == [(0, "a")]  # not lost because the caller skipped steps
    with pytest.raises(ValueError):
        ch.deliver(10)
    with pytest.raises(ValueError):
        ch.send(5, "b")


@pytest.mark.parametrize("kw", [dict(loss=1.5), dict(delay_s=-1.0), dict(jitter_s=math.inf), dict(rate_hz=0.0),
                                dict(reorder_max_steps=0)])  # fmt: skip
def test_parameters_are_validated(kw):
    with pytest.raises(ValueError):
        LinkImpairment(**kw)


def test_draws_taken_in_blocks_are_the_streams_draws_five_at_a_time():
    imp = LinkImpairment(loss=0.3, jitter_s=0.002, reorder=0.2, duplicate=0.1, seed=9)
    ch, rng = ImpairedChannel(imp, imp.rng(4)), imp.rng(4)
    for _ in range(600):  # more than one block
        assert ch._draw5() == rng.random(5).tolist()
