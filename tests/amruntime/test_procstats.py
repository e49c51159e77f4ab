"""amruntime.procstats: how a thread's wall time splits between running, waiting for a core and
being blocked, as the outcome files and benchmarks/bench_sitl.py report it."""
from __future__ import annotations

import threading
import time

import pytest

from amruntime import procstats

linux_schedstat = pytest.mark.skipif(procstats.thread_schedstat() is None,
                                     reason="no Linux scheduler statistics (/proc/thread-self/schedstat)")


def _spin(seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def test_main_thread_is_none_before_start():
    assert procstats.CpuMeter().main_thread() is None


@linux_schedstat
def test_a_busy_thread_is_on_a_cpu_and_a_sleeping_one_blocked():
    busy = procstats.CpuMeter()
    busy.start()
    _spin(0.3)
    b = busy.main_thread()
    asleep = procstats.CpuMeter()
    asleep.start()
    time.sleep(0.3)
    s = asleep.main_thread()
    for split in (b, s):  # the three parts add up to the wall time
        assert split["on_cpu_s"] + split["queued_s"] + split["blocked_s"] == pytest.approx(split["wall_s"], abs=2e-3)
        assert split["wall_s"] >= 0.3
    # spinning: on a CPU or waiting for one, never blocked for long; sleeping: blocked, hardly ever running
    assert b["on_cpu_s"] + b["queued_s"] > 0.9 * b["wall_s"]
    assert b["blocked_s"] < 0.1 * b["wall_s"]
    assert s["blocked_s"] > 0.9 * s["wall_s"]
    assert s["on_cpu_s"] < 0.05


@linux_schedstat
def test_the_split_is_of_the_thread_that_started_the_meter():
    # another thread spinning meanwhile does not count as this thread's time on a CPU
    meter = procstats.CpuMeter()
    meter.start()
    t = threading.Thread(target=_spin, args=(0.3,))
    t.start()
    t.join()
    split = meter.main_thread()
    assert split["blocked_s"] > 0.8 * split["wall_s"]
    assert meter.seconds() >= 0.2  # while the process's CPU time counts every thread


@linux_schedstat
def test_a_thread_that_shares_its_cores_is_queued():
    # more spinning processes than cores: this thread, spinning too, waits for a core part of the time
    import os
    import subprocess
    import sys
    n = (os.cpu_count() or 1) + 1
    spinners = [subprocess.Popen([sys.executable, "-c", "import time\nend = time.time() + 1.5\nwhile time.time() < end: pass"])
                for _ in range(n)]
    try:
        time.sleep(0.2)  # the spinners started
        meter = procstats.CpuMeter()
        meter.start()
        _spin(0.5)
        split = meter.main_thread()
    finally:
        for p in spinners:
            p.kill()
            p.wait()
    assert split["queued_s"] > 0.1 * split["wall_s"]
    assert split["on_cpu_s"] + split["queued_s"] + split["blocked_s"] == pytest.approx(split["wall_s"], abs=2e-3)
    assert split["blocked_s"] < 0.1 * split["wall_s"]
