"""The autopilot's clock in the companion's monotonic clock, from TIMESYNC exchanges (pure: no I/O).

TIMESYNC (MAVLink common.xml): a request carries ``tc1 = 0`` and ``ts1`` = the requester's time
[ns]; the answer echoes ``ts1`` and carries ``tc1`` = the responder's time [ns] when it answered.
PX4 answers with ``tc1 = hrt_absolute_time() * 1000``, its boot time at 1 us resolution
(PX4-Autopilot src/modules/mavlink/mavlink_timesync.cpp, ``MavlinkTimesync::handle_message``).

One exchange sent at ``t0`` and answered at ``t1`` (this process's monotonic clock, ns) is one
sample: the autopilot read its clock somewhere in ``[t0, t1]``.  Placed at the midpoint
``m = (t0 + t1) / 2`` -- equal legs, the assumption PX4's own ``Timesync::update`` makes -- the
sample is off by ``rate * (d_down - d_up) / 2``, at most ``rate * rtt / 2``.

Model: ``fc_us(t) = c + rate * (t - t_ref) / 1000``, a line fitted by weighted least squares to
the newest ``window`` samples, each weighted ``1 / (rtt + rtt_floor)**2`` (its error bound grows
with its round trip).  PX4's ``Timesync`` smooths the offset and its derivative with a double
exponential filter; a line over a window gives the clock rate directly, so an autopilot whose
clock runs at another speed -- PX4 SITL with a speed factor, whose boot time runs at the
simulation's rate -- is followed, and a rate that changes is followed within a window.

Kept from PX4 (src/lib/timesync/Timesync.hpp and Timesync.cpp, the constants' names): samples
with a round trip of ``MAX_RTT_SAMPLE`` (10 ms) or more are not used -- or, on a link whose
fastest round trip so far is longer than half of that, of ``RTT_CUT_FACTOR`` (2) times that
fastest one or more: PX4's cut is for its own links, serial or local UDP, and would take no
sample at all from a link with 10 ms of latency each way, where a round trip twice the link's
best still bounds its sample within ``rate * rtt / 2``; once converged, a sample
more than ``MAX_DEVIATION_SAMPLE`` (100 ms of autopilot time) off the estimate is not used, and
more than ``MAX_CONSECUTIVE_HIGH_DEVIATION`` (5) of them in a row reset the estimate (a time
jump: the autopilot rebooted, or its speed changed abruptly); the sample that triggers the reset
starts the new estimate.  PX4 calls itself converged after ``CONVERGENCE_WINDOW`` (500) samples;
a fitted line needs fewer: ``min_samples`` (8) spanning at least ``min_span_ns`` (0.5 s).

Bounds (tests/amlink/test_timebase.py checks them).  With one-way delays in ``[d_min, d_max]``
each sample is within ``B = rate * (d_max - d_min) / 2`` of the autopilot's clock (plus its 1 us
quantization).  A least-squares line through samples each within +-B is within ``L * B``, ``L``
the sum of the absolute weights the fit gives the samples at the query time (equal weights:
1.86 for 8 evenly spaced samples queried one period past the newest, 1.71 for 32; the RTT
weights shift weight onto the samples with the tighter bounds), so the estimate from the
converged fit up to one exchange period ahead is within ``2 * B``; its rate within
``4 * B / span`` (span: the window's length).  A constant asymmetry of the legs adds
``rate * (d_down - d_up) / 2``, which no two-way exchange can observe.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

MAX_RTT_SAMPLE_NS = 10_000_000  # PX4 Timesync.hpp MAX_RTT_SAMPLE = 10_ms
RTT_CUT_FACTOR = 2  # on a slow link: samples of this many times its fastest round trip or more are not used
MAX_DEVIATION_SAMPLE_US = 100_000.0  # PX4 Timesync.hpp MAX_DEVIATION_SAMPLE = 100_ms
MAX_CONSECUTIVE_HIGH_DEVIATION = 5  # PX4 Timesync.hpp
WINDOW = 32  # samples in the fit: 3.2 s at the 10 Hz a PX4 link exchanges TIMESYNC
MIN_SAMPLES = 8
MIN_SPAN_NS = 500_000_000
RTT_FLOOR_NS = 50_000  # keeps the weight of a near-zero round trip finite
MAX_OUTSTANDING = 16  # requests remembered for matching their answers


@dataclass(frozen=True)
class _Sample:
    m_ns: int  # midpoint of the exchange [ns, companion monotonic]
    fc_us: float  # the autopilot's clock then [us]
    rtt_ns: int


class Timebase:
    """The autopilot's clock ``fc_us`` as a function of the companion's ``mono_ns``.

    Use: ``ts1 = tb.request(now_ns)`` for each TIMESYNC request sent (``tc1 = 0``, ``ts1``), and
    ``tb.on_answer(tc1, ts1, rx_ns)`` for each answer received.  Counters: ``accepted``,
    ``rejected_rtt``, ``rejected_deviation``, ``unmatched`` (an answer to no request of ours, a
    duplicate, or malformed), ``resets``.
    """

    def __init__(self, *, max_rtt_ns: int = MAX_RTT_SAMPLE_NS, window: int = WINDOW,
                 min_samples: int = MIN_SAMPLES, min_span_ns: int = MIN_SPAN_NS,
                 max_deviation_us: float = MAX_DEVIATION_SAMPLE_US,
                 max_high_deviation: int = MAX_CONSECUTIVE_HIGH_DEVIATION,
                 rtt_floor_ns: int = RTT_FLOOR_NS) -> None:  # fmt: skip
        if not max_rtt_ns > 0:
            raise ValueError(f"max_rtt_ns must be > 0, got {max_rtt_ns}")
        if not 2 <= min_samples <= window:
            raise ValueError(f"need 2 <= min_samples <= window, got min_samples={min_samples}, window={window}")
        if not (min_span_ns >= 0 and max_deviation_us > 0 and max_high_deviation >= 0 and rtt_floor_ns > 0):
            raise ValueError("min_span_ns >= 0, max_deviation_us > 0, max_high_deviation >= 0, rtt_floor_ns > 0")
        self.max_rtt_ns, self.min_samples, self.min_span_ns = int(max_rtt_ns), min_samples, int(min_span_ns)
        self.max_deviation_us, self.max_high_deviation = float(max_deviation_us), max_high_deviation
        self.rtt_floor_ns = int(rtt_floor_ns)
        self._samples: deque[_Sample] = deque(maxlen=window)
        self._outstanding: deque[int] = deque(maxlen=MAX_OUTSTANDING)
        self._fit: tuple[int, float, float] | None = None  # (t_ref_ns, c_us, rate)
        self._high_deviation = 0
        self.accepted = self.rejected_rtt = self.rejected_deviation = self.unmatched = self.resets = 0
        self.last_rtt_ns: int | None = None
        self.min_rtt_ns: int | None = None  # the fastest round trip answered so far

    # -- the exchange --------------------------------------------------------------
    def request(self, mono_ns: int) -> int:
        """The ``ts1`` [ns] of a TIMESYNC request sent at ``mono_ns``: the send time itself."""
        ts1 = int(mono_ns)
        if ts1 <= 0:
            raise ValueError(f"a TIMESYNC request's ts1 must be > 0 ns, got {ts1}")
        self._outstanding.append(ts1)
        return ts1

    def on_answer(self, tc1_ns: int, ts1_ns: int, rx_ns: int) -> bool:
        """Take an answer (``tc1`` [ns, autopilot], the echoed ``ts1``) received at ``rx_ns``;
        True if it became a sample."""
        if ts1_ns not in self._outstanding or tc1_ns <= 0 or rx_ns < ts1_ns:
            self.unmatched += 1
            return False
        self._outstanding.remove(ts1_ns)  # a duplicate answer is unmatched
        rtt = int(rx_ns - ts1_ns)
        self.last_rtt_ns = rtt
        self.min_rtt_ns = rtt if self.min_rtt_ns is None else min(self.min_rtt_ns, rtt)
        if rtt >= self.rtt_cut_ns:
            self.rejected_rtt += 1
            return False
        s = _Sample(int(ts1_ns + rtt // 2), tc1_ns / 1000.0, rtt)
        if self.converged and abs(s.fc_us - self._predict(s.m_ns)) > self.max_deviation_us:
            self.rejected_deviation += 1
            self._high_deviation += 1
            if self._high_deviation <= self.max_high_deviation:
                return False
            self.reset()
            self.resets += 1
        self._high_deviation = 0
        self._samples.append(s)
        self._refit()
        self.accepted += 1
        return True

    @property
    def rtt_cut_ns(self) -> int:
        """The round trip [ns] from which a sample is not used: max_rtt_ns (PX4's 10 ms), or on
        a slower link RTT_CUT_FACTOR times its fastest round trip so far (module doc)."""
        return max(self.max_rtt_ns, RTT_CUT_FACTOR * (self.min_rtt_ns or 0))

    def reset(self) -> None:
        """Forget every sample (outstanding requests stay matchable)."""
        self._samples.clear()
        self._fit = None
        self._high_deviation = 0

    # -- the estimate --------------------------------------------------------------
    @property
    def ready(self) -> bool:
        """An estimate exists (one sample or more); see :attr:`converged` for its quality."""
        return self._fit is not None

    @property
    def converged(self) -> bool:
        """At least ``min_samples`` samples spanning at least ``min_span_ns``."""
        s = self._samples
        return len(s) >= self.min_samples and s[-1].m_ns - s[0].m_ns >= self.min_span_ns

    @property
    def rate(self) -> float | None:
        """The autopilot's clock rate against ours (autopilot us per companion us; 1.0 = same
        speed, 2.0 = a SITL speed factor of 2); None before the first sample."""
        return None if self._fit is None else self._fit[2]

    @property
    def rtt_ns(self) -> int | None:
        """The median round trip of the samples in the fit [ns]; None before the first."""
        if not self._samples:
            return None
        r = sorted(s.rtt_ns for s in self._samples)
        return r[len(r) // 2]

    @property
    def samples(self) -> int:
        return len(self._samples)

    def fc_time_us(self, mono_ns: int) -> float | None:
        """The autopilot's clock [us] at companion time ``mono_ns``; None before the first sample."""
        return None if self._fit is None else self._predict(mono_ns)

    def mono_ns(self, fc_us: float) -> int | None:
        """The companion time [ns] at which the autopilot's clock reads ``fc_us``; None before the first sample."""
        if self._fit is None:
            return None
        t_ref, c, rate = self._fit
        return t_ref + round((fc_us - c) * 1000.0 / rate)

    def _predict(self, mono_ns: int) -> float:
        t_ref, c, rate = self._fit
        return c + rate * (mono_ns - t_ref) * 1e-3

    def _refit(self) -> None:
        """Weighted least squares of fc_us on m_ns over the window; rate 1 while one sample (or
        a degenerate fit) leaves it undetermined."""
        s = self._samples
        m0 = s[0].m_ns
        w = [1.0 / float(x.rtt_ns + self.rtt_floor_ns) ** 2 for x in s]
        W = math.fsum(w)
        xs = [float(x.m_ns - m0) for x in s]
        xm = math.fsum(wi * xi for wi, xi in zip(w, xs)) / W
        fm = math.fsum(wi * x.fc_us for wi, x in zip(w, s)) / W
        sxx = math.fsum(wi * (xi - xm) ** 2 for wi, xi in zip(w, xs))
        rate = 1.0
        if len(s) >= 2 and sxx > 0.0:
            sxy = math.fsum(wi * (xi - xm) * (x.fc_us - fm) for wi, xi, x in zip(w, xs, s))
            fitted = 1e3 * sxy / sxx  # us per ns -> us per us
            if math.isfinite(fitted) and fitted > 0.0:
                rate = fitted
        t_ref = m0 + round(xm)
        self._fit = (t_ref, fm + rate * (t_ref - m0 - xm) * 1e-3, rate)
