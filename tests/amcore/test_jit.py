"""amcore.jit: the kernels compile at LLVM's optimization level 1 unless NUMBA_OPT says
otherwise, and the level leaves every result as it was, bit for bit."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

_LEVEL = textwrap.dedent("""
    import sys
    if sys.argv[1] == "numba first":  # numba imported and its config read before amcore.jit
        import numba
    import amcore.jit, numba
    print(int(numba.config.OPT))
""")

# eqs. Com_controller, Rd, ori_controller and the discrete damping's matrix exponential on
# seeded random arguments; each result's bytes in hex
_RESULTS = textwrap.dedent("""
    import numpy as np
    from amcore import law
    rng = np.random.default_rng(20261128)
    out = []
    for _ in range(20):
        v = lambda: rng.normal(size=3)
        K, D, L = (np.diag(rng.uniform(1.0, 10.0, 3)) for _ in range(3))
        R = law.expm_small(law.hat(0.3 * v()))
        f = law.com_law(1.5 + rng.random(), 9.81, K, D, 0.1 * v(), v(), v(), v(), v(), R, v(), v(), v(), v(), 0.05,
                        True)
        f_d = f[0] + np.array([0.0, 0.0, 20.0])
        Rd = law.desired_attitude(f_d, f[1], f[2], np.array([1.0, 0.0, 0.0]), 0.1 * v(), 0.1 * v())
        u2 = law.orientation_law(R, v(), *Rd, 2.0, 0.3, law.inv(L), L, v(), v())
        E = law.discrete_damping(L, D, 0.004)
        for a in (*f[:4], *Rd, *u2, E, R):
            out.append(np.asarray(a, dtype=np.float64).tobytes().hex())
    print(" ".join(out))
""")


def _env(**set_: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_OPT"}  # this process's amcore.jit set it
    return {**env, **set_}


@pytest.mark.parametrize("order", ["amcore.jit first", "numba first"])
def test_the_kernels_compile_at_level_1_unless_numba_opt_says_otherwise(order):
    for env, level in ((_env(), "1"), (_env(NUMBA_OPT="3"), "3"), (_env(NUMBA_OPT="0"), "0")):
        out = subprocess.run([sys.executable, "-c", _LEVEL, order], capture_output=True, text=True, env=env, cwd=ROOT,
                             timeout=120)
        assert out.returncode == 0, out.stderr
        assert out.stdout.strip() == level, (env.get("NUMBA_OPT"), out.stdout)


def test_the_optimization_level_leaves_the_results_as_they_were(tmp_path):
    """Compiled afresh (an empty cache each) at level 1 and at numba's default 3, the kernels
    give the same bits: none uses fast-math, so no level may reorder or fuse their arithmetic."""
    outs = {}
    for level in ("1", "3"):
        env = _env(NUMBA_OPT=level, NUMBA_CACHE_DIR=str(tmp_path / f"cache-{level}"))
        out = subprocess.run([sys.executable, "-c", _RESULTS], capture_output=True, text=True, env=env, cwd=ROOT,
                             timeout=600)
        assert out.returncode == 0, out.stderr
        outs[level] = out.stdout.split()
    assert len(outs["1"]) == 20 * 14  # 4 + 3 + 5 results, E and R
    assert outs["1"] == outs["3"]


_CALLER = textwrap.dedent("""
    from kpkg import a
    print(a.h(1.0), sum(a.h.stats.cache_misses.values()), sum(a.h.stats.cache_hits.values()))
""")


def _write_package(root: Path, f_body: str, g_body: str) -> None:
    """kpkg: a.h calls b.f by name, b.f calls c.g through its module; each in its own file."""
    pkg = root / "kpkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "c.py").write_text(f"from amcore.jit import kernel\n\n@kernel\ndef g(x):\n    return {g_body}\n")
    (pkg / "b.py").write_text(f"from amcore.jit import kernel\nfrom . import c\n\n@kernel\ndef f(x):\n"
                              f"    return {f_body} + c.g(x)\n")
    (pkg / "a.py").write_text("from amcore.jit import kernel\nfrom .b import f\n\n@kernel\ndef h(x):\n"
                              "    return 10.0 * f(x)\n")


def _call(root: Path, cache: Path) -> tuple[float, int, int]:
    path = os.pathsep.join(filter(None, (str(root), os.environ.get("PYTHONPATH"))))
    env = _env(NUMBA_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1", PYTHONPATH=path)
    out = subprocess.run([sys.executable, "-c", _CALLER], capture_output=True, text=True, env=env,
                         cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr
    value, misses, hits = out.stdout.split()
    return float(value), int(misses), int(hits)


def test_a_changed_callee_in_another_file_recompiles_its_callers(tmp_path):
    """A kernel's cache entry is keyed on its callees' files too (amcore.jit): after a callee
    changes, directly (b.f) or through another kernel (c.g, called by b.f through its module),
    a new process compiles the caller afresh and gets the new result; unchanged, it loads it."""
    cache = tmp_path / "cache"
    _write_package(tmp_path, "x", "2.0 * x")
    assert _call(tmp_path, cache) == (30.0, 1, 0)  # 10 (1 + 2): compiled
    assert _call(tmp_path, cache) == (30.0, 0, 1)  # loaded from the cache
    _write_package(tmp_path, "x + 100.0", "2.0 * x")  # the direct callee changed
    assert _call(tmp_path, cache) == (1030.0, 1, 0)
    _write_package(tmp_path, "x + 100.0", "3.0 * x + 1000.0")  # the callee's callee changed
    assert _call(tmp_path, cache) == (11040.0, 1, 0)
    assert _call(tmp_path, cache) == (11040.0, 0, 1)


def test_the_estimators_kernels_are_keyed_on_the_quaternion_helpers():
    from amcore import estimator, jit, quat_kernels
    from simulator import device_kernels, fc_kernels
    helpers = os.path.abspath(quat_kernels.__file__)
    for k in (estimator.predict, estimator.estimator_update, device_kernels.suite_step, fc_kernels.rate_loops):
        assert helpers in jit.source_files(k.py_func), k
    assert jit.source_files(quat_kernels.quat_mul.py_func) == []
