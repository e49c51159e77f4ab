"""The JIT behind the compiled kernels: numba in nopython mode, machine code cached on disk.

`kernel` compiles a function with numba and caches the result in numba's on-disk cache
(`__pycache__` beside the kernel's source file, or NUMBA_CACHE_DIR). The first process that
calls a kernel compiles it; every later process loads the machine code from the cache.
Keeping processes that start together from all compiling is the callers' part
(amruntime.jitcache, which holds a file lock around the first call).

The cache is keyed on every source file a kernel's machine code comes from. Numba's own key
is the kernel's file alone, so a change to a callee in another file (amcore.quat_kernels'
quaternion helpers, called from the estimator, the devices and the emulated autopilot) would
leave its callers' stale machine code in the cache. Here the key is the kernel's file and the
files of the kernels it calls, found in its code's global names (a kernel by name, or an
attribute of a module), transitively. The key is taken at a kernel's first compile, when
every module it names has been imported.

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

import functools
import hashlib
import inspect
import os
import types

OPT_LEVEL = "1"
os.environ.setdefault("NUMBA_OPT", OPT_LEVEL)

import numba  # noqa: E402 (after NUMBA_OPT)
from numba.core import caching  # noqa: E402

numba.core.config.reload_config()  # numba may have been imported already (its config read)

_Dispatcher = numba.core.registry.CPUDispatcher


def _names(code: types.CodeType):
    """The global names a code object and the functions defined in it use."""
    yield from code.co_names
    for c in code.co_consts:
        if isinstance(c, types.CodeType):
            yield from _names(c)


def callees(py_func) -> list:
    """The kernels (numba dispatchers) `py_func` calls, directly or through them, itself
    not included, each once."""
    seen: dict[int, object] = {}
    stack = [py_func]
    while stack:
        f = stack.pop()
        names = set(_names(f.__code__))
        for name in names:
            v = f.__globals__.get(name)
            found = [v] if isinstance(v, _Dispatcher) else (
                [getattr(v, a) for a in names if isinstance(getattr(v, a, None), _Dispatcher)]
                if isinstance(v, types.ModuleType) else [])
            for d in found:
                if id(d.py_func) not in seen and d.py_func is not py_func:
                    seen[id(d.py_func)] = d
                    stack.append(d.py_func)
    return list(seen.values())


def source_files(py_func) -> list[str]:
    """The source files of the kernels `py_func` calls (`callees`), other than its own, sorted."""
    own = os.path.abspath(inspect.getfile(py_func))
    files = {os.path.abspath(inspect.getfile(d.py_func)) for d in callees(py_func)}
    return sorted(files - {own})


@functools.lru_cache(maxsize=None)
def _hash(path: str, mtime_ns: int, size: int) -> bytes:  # keyed as numba's: a changed file is hashed again
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).digest()


def _file_hash(path: str) -> bytes:
    st = os.stat(path)
    return _hash(path, st.st_mtime_ns, st.st_size)


class _KeyedCache(caching.FunctionCache):
    """numba's FunctionCache, its index stamped with the hashes of the callees' files beside
    numba's own stamp (the kernel's file), taken at the first load or save."""

    def __init__(self, py_func) -> None:  # numba's, less the stamp taken now
        self._name = repr(py_func)
        self._py_func = py_func
        self._impl = self._impl_class(py_func)
        self._cache_path = self._impl.locator.get_cache_path()
        self._index = None
        self.enable()

    @property
    def _cache_file(self):
        if self._index is None:
            stamp = (self._impl.locator.get_source_stamp(),
                     tuple(_file_hash(f) for f in source_files(self._py_func)))
            self._index = caching.IndexDataCacheFile(cache_path=self._cache_path,
                                                     filename_base=self._impl.filename_base,
                                                     source_stamp=stamp)
        return self._index


def kernel(fn):
    """Compile `fn` with numba (nopython, no GIL held), cached on disk keyed on its own and its
    callees' source files."""
    d = numba.njit(nogil=True, error_model="numpy")(fn)
    d._cache = _KeyedCache(d.py_func)
    return d


def kernels(module) -> list:
    """The compiled functions of a module (numba dispatchers)."""
    return [v for v in vars(module).values() if isinstance(v, _Dispatcher)]
