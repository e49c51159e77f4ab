"""Thread-CPU timers wrapped around a running program's methods, for the benchmarks that split
a loop's CPU by part (`bench_freerun.py`, `bench_wallclock.py`)."""
from __future__ import annotations

import time


def wrap(owner, name: str, acc: dict, key: str, nested: dict | None = None) -> None:
    """Replace owner.name (a method of an instance or a class) by one that adds its thread CPU
    time [ns] to acc[key]; and to nested[key], for a part that runs inside another one whose
    total is to be taken out of it."""
    f = getattr(owner, name)
    clock = time.thread_time_ns

    def timed(*a, **kw):
        t0 = clock()
        try:
            return f(*a, **kw)
        finally:
            d = clock() - t0
            acc[key] += d
            if nested is not None:
                nested[key] += d
    timed.__wrapped__ = f
    setattr(owner, name, timed)
