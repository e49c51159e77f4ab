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
