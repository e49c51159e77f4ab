"""Compiling the control law once per machine, not once per process.

amcore.law (and telemetry.kernels) is compiled by numba on its first call and cached on disk (amcore.jit). Ten
companions starting together would otherwise all find the cache empty and compile at once
(each for tens of seconds, on a 2-core machine for minutes). `warm` makes the first call
while holding an exclusive lock on a file beside the cache: the first process compiles and
writes the cache, the others wait on the lock and then load what it wrote. am-run warms
once before it starts any companion, and every companion, the in-process runner and each
trial worker warm at start-up (then a cache hit, a fraction of a second).
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from amcore import law
from amcore.jit import kernels
from telemetry import kernels as telemetry_kernels


def cache_dir() -> Path:
    """Where numba caches amcore.law: NUMBA_CACHE_DIR if set, else amcore's __pycache__ if it
    can be written, else a per-user folder in the temporary directory (for the lock file only:
    numba then uses its own per-user cache)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env:
        return Path(env)
    here = Path(law.__file__).resolve().parent / "__pycache__"
    with contextlib.suppress(OSError):
        here.mkdir(exist_ok=True)
    if os.access(here, os.W_OK):
        return here
    return Path(tempfile.gettempdir()) / f"amstack-numba-{os.getuid()}"


def looks_cached() -> bool:
    """Whether the cache holds the control law already (its index file exists; whether it
    matches this source and machine, numba decides when loading)."""
    return any(cache_dir().rglob("law.control_law-*.nbi"))


@contextlib.contextmanager
def _exclusive(path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@dataclass(frozen=True)
class CompileReport:
    compiled: int  # kernels this process compiled (cache misses); 0: all loaded from the cache or already in memory
    seconds: float  # wall time of the first call, waiting for the lock included


def warm(first_call) -> CompileReport:
    """Run `first_call()` (a first call into amcore.law, e.g. Pilot.warm_up) and the telemetry
    kernels' (telemetry.kernels.warm_up) holding the machine-wide lock; report how many
    kernels this process compiled."""
    t0 = time.perf_counter()
    ks = kernels(law) + kernels(telemetry_kernels)
    with _exclusive(cache_dir() / "amstack-jit.lock"):
        before = sum(sum(k.stats.cache_misses.values()) for k in ks)
        first_call()
        telemetry_kernels.warm_up()
        compiled = sum(sum(k.stats.cache_misses.values()) for k in ks) - before
    return CompileReport(compiled=compiled, seconds=time.perf_counter() - t0)
