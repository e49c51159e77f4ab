"""Compiling the control law once per machine, not once per process.

amcore.law (and telemetry.kernels) is compiled by numba on its first call and cached on disk (amcore.jit). Ten
companions starting together would otherwise all find the cache empty and compile at once
(each for tens of seconds, on a 2-core machine for minutes). `warm` makes the first call
while holding an exclusive lock on a file beside the cache: the first process compiles and
writes the cache, the others wait on the lock and then load what it wrote. am-run warms
once before it starts any companion, and every companion, the in-process runner and each
trial worker warm at start-up (then a cache hit, a fraction of a second); the standalone
simulator warms its own group (below) before it listens.

The simulator's kernels (its autopilot, allocation, devices and estimator) are a second
group with a lock of its own (`warm_groups`): a process that finds one group's lock taken
compiles another group meanwhile, so that two processes starting together on an empty cache
compile the two groups side by side, on two cores, rather than one after the other. The
groups' kernels live in different source files, so neither compile touches the other's
cache entries.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
import time
from collections.abc import Callable, Iterator
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


LAW_LOCK = "amstack-jit.lock"  # the control law's and the telemetry's kernels
SIMULATOR_LOCK = "amstack-jit-simulator.lock"  # the simulator's (simulator.core.kernel_group)


@contextlib.contextmanager
def _exclusive(path: Path, wait: bool = True) -> Iterator[bool]:
    """Hold an exclusive lock on `path` (created if missing); yields True. With wait=False,
    yields False at once if another process holds it (and holds nothing)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            yield False
            return
        try:
            yield True
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@dataclass(frozen=True)
class CompileReport:
    compiled: int  # kernels this process compiled (cache misses); 0: all loaded from the cache or already in memory
    seconds: float  # wall time of the first call, waiting for the lock included


@dataclass(frozen=True)
class Group:
    """Kernels compiled together under one machine-wide lock: `first_call()` calls each of
    them with a run's argument types; `modules` hold them (for counting what was compiled)."""

    lock: str  # the lock file's name in cache_dir()
    modules: tuple
    first_call: Callable[[], object]


def law_group(first_call) -> Group:
    """The control law (amcore.law, through `first_call`, e.g. Pilot.warm_up) and the
    telemetry's kernels (telemetry.kernels.warm_up)."""
    return Group(LAW_LOCK, (law, telemetry_kernels), lambda: (first_call(), telemetry_kernels.warm_up()))


def warm(first_call) -> CompileReport:
    """Run `first_call()` (a first call into amcore.law, e.g. Pilot.warm_up) and the telemetry
    kernels' (telemetry.kernels.warm_up) holding the machine-wide lock; report how many
    kernels this process compiled."""
    return warm_groups([law_group(first_call)])


def warm_groups(groups: list[Group]) -> CompileReport:
    """Each group's first call, holding its lock: first every group whose lock is free, in
    order, then the rest, each as soon as its lock is free. Report how many kernels this
    process compiled (cache misses) and the wall time, waiting included."""
    t0 = time.perf_counter()
    ks = [k for g in groups for m in g.modules for k in kernels(m)]
    before = sum(sum(k.stats.cache_misses.values()) for k in ks)
    pending = list(groups)
    while pending:
        for g in pending:  # a group nobody compiles now
            with _exclusive(cache_dir() / g.lock, wait=False) as held:
                if held:
                    g.first_call()
                    pending.remove(g)
                    break
        else:  # every lock is taken: wait for the first
            g = pending.pop(0)
            with _exclusive(cache_dir() / g.lock):
                g.first_call()
    compiled = sum(sum(k.stats.cache_misses.values()) for k in ks) - before
    return CompileReport(compiled=compiled, seconds=time.perf_counter() - t0)
