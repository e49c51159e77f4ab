"""This process's own memory and CPU, for outcome files and benchmarks (Linux /proc; the
resource module elsewhere), and how its main thread spent a run's wall time."""
from __future__ import annotations

import resource
import time


def memory_mib() -> dict:
    """Resident memory now [MiB]: rss (every page mapped in, shared libraries included), pss
    (shared pages divided among the processes that share them) and uss (pages of this
    process alone), and the peak rss; pss and uss where /proc/self/smaps_rollup exists."""
    out = {"max_rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}
    try:
        with open("/proc/self/smaps_rollup") as f:
            kb = {}
            for line in f:
                parts = line.split()
                if len(parts) >= 2 and parts[1].isdigit():
                    kb[parts[0].rstrip(":")] = int(parts[1])
        out.update(rss=kb["Rss"] / 1024.0, pss=kb["Pss"] / 1024.0,
                   uss=(kb.get("Private_Clean", 0) + kb.get("Private_Dirty", 0)) / 1024.0)
    except (OSError, KeyError):
        pass
    return {k: round(v, 1) for k, v in out.items()}


def thread_schedstat() -> tuple[float, float] | None:
    """(on a CPU, runnable but waiting for one) [s]: the calling thread's times so far, as
    Linux's scheduler counts them (/proc/thread-self/schedstat); None where it does not."""
    try:
        with open("/proc/thread-self/schedstat") as f:
            on_cpu_ns, queued_ns, _slices = f.read().split()
        return int(on_cpu_ns) * 1e-9, int(queued_ns) * 1e-9
    except (OSError, ValueError):
        return None


class CpuMeter:
    """CPU time (user + system) of this process between start() and now [s], and how the
    thread that called start() spent the wall time since (`main_thread`)."""

    def __init__(self) -> None:
        self._t0 = None
        self._wall0 = 0.0
        self._sched0: tuple[float, float] | None = None

    def start(self) -> None:
        self._t0 = time.process_time()
        self._wall0 = time.perf_counter()
        self._sched0 = thread_schedstat()

    def seconds(self) -> float | None:
        return None if self._t0 is None else time.process_time() - self._t0

    def main_thread(self) -> dict | None:
        """The wall time since start() of the thread that called it [s], split three ways:
        on_cpu_s, running; queued_s, runnable while every core ran something else (the other
        processes, this one's other threads); blocked_s, the rest: waiting for a datagram, a
        peer or a lock. In a lockstep run the simulator's blocked time is time spent waiting
        for the companions' answers. Call it from the thread that called start(); None before
        start() or where Linux's scheduler statistics are not available."""
        now = thread_schedstat()
        if self._t0 is None or self._sched0 is None or now is None:
            return None
        wall = time.perf_counter() - self._wall0
        on_cpu, queued = now[0] - self._sched0[0], now[1] - self._sched0[1]
        return {"wall_s": round(wall, 4), "on_cpu_s": round(on_cpu, 4), "queued_s": round(queued, 4),
                "blocked_s": round(max(0.0, wall - on_cpu - queued), 4)}
