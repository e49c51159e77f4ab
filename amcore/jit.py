"""The JIT behind amcore.law: numba in nopython mode, machine code cached on disk.

`kernel` compiles a function with numba and caches the result in numba's on-disk cache
(`__pycache__` beside amcore/law.py, or NUMBA_CACHE_DIR). The first process that calls a
kernel compiles it; every later process loads the machine code from the cache. Keeping
processes that start together from all compiling is the callers' part
(amruntime.jitcache, which holds a file lock around the first call).

All kernels live in one file (amcore/law.py): numba's cache is keyed on the source file of
each kernel, so a change to a callee in another file would not invalidate its callers.

error_model="numpy": a division by zero gives inf or nan as in numpy (the law checks its
divisors where it matters and raises itself). NUMBA_DISABLE_JIT=1 runs the same functions
as plain Python (for a debugger; slow).

LLVM's optimization level: 1 (`OPT_LEVEL`), not numba's default 3, unless NUMBA_OPT is set.
On a machine's first run the kernels compile in about four fifths of the time, and they run
as fast and give the same bits (docs/benchmarks.md, "LLVM's optimization level"): none asks
for fast-math, so no level may reorder or fuse their floating-point operations. Set as
NUMBA_OPT in this process's environment (children inherit it, and numba's own re-reading of
its environment keeps it), before the first compile.
"""
from __future__ import annotations

import os

OPT_LEVEL = "1"
os.environ.setdefault("NUMBA_OPT", OPT_LEVEL)

import numba  # noqa: E402 (after NUMBA_OPT)

numba.core.config.reload_config()  # numba may have been imported already (its config read)


def kernel(fn):
    """Compile `fn` with numba (nopython, no GIL held, cached on disk)."""
    return numba.njit(cache=True, nogil=True, error_model="numpy")(fn)


def kernels(module) -> list:
    """The compiled functions of a module (numba dispatchers)."""
    return [v for v in vars(module).values() if isinstance(v, numba.core.registry.CPUDispatcher)]
