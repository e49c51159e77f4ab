"""This process's own memory and CPU, for outcome files and benchmarks (Linux /proc; the
resource module elsewhere)."""
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


class CpuMeter:
    """CPU time (user + system) of this process between start() and now [s]."""

    def __init__(self) -> None:
        self._t0 = None

    def start(self) -> None:
        self._t0 = time.process_time()

    def seconds(self) -> float | None:
        return None if self._t0 is None else time.process_time() - self._t0
