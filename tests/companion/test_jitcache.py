"""The compiled law is compiled once per machine: processes starting together share one
compile through the lock (companion.jitcache), and a run after the warm-up compiles nothing."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from amcore import law
from amcore.config import load_scenario
from amcore.jit import kernels
from companion import jitcache
from companion.pilot import Pilot
from simulator.inprocess import run

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "configs" / "scenarios" / "two_am_comp.toml"

_WARM = textwrap.dedent("""
    import json, sys
    from amcore.config import load_scenario
    from companion import jitcache
    from companion.pilot import Pilot
    spec = load_scenario(sys.argv[1])
    report = jitcache.warm(Pilot(spec, spec.ams[0].sysid).warm_up)
    print(json.dumps({"compiled": report.compiled, "seconds": report.seconds}))
""")


def _start(cache: Path) -> subprocess.Popen:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    return subprocess.Popen([sys.executable, "-c", _WARM, str(SCENARIO)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)


def test_processes_starting_together_compile_once(tmp_path):
    cache = tmp_path / "numba-cache"
    procs = [_start(cache) for _ in range(3)]
    reports = []
    for p in procs:
        out, err = p.communicate(timeout=900)
        assert p.returncode == 0, err
        reports.append(json.loads(out))
    compiled = [r["compiled"] for r in reports]
    assert sum(1 for c in compiled if c > 0) == 1, reports  # one compiled, the others loaded its work
    # a later process loads everything from the cache
    late = _start(cache)
    out, err = late.communicate(timeout=600)
    assert late.returncode == 0, err
    assert json.loads(out)["compiled"] == 0


def test_a_run_after_the_warm_up_compiles_nothing_new():
    """The warm-up calls the law with the argument types of a run (read-only wire arrays, the
    frame's quaternion): a mission afterwards adds no specialization (none compiled mid-run,
    where the simulator would wait on it)."""
    spec = load_scenario(SCENARIO)
    jitcache.warm(Pilot(spec, spec.ams[0].sysid).warm_up)
    before = {k.py_func.__name__: len(k.signatures) for k in kernels(law)}
    out = run(spec, duration_s=0.3)
    assert out["steps"] == 300
    after = {k.py_func.__name__: len(k.signatures) for k in kernels(law)}
    assert after == before


@pytest.mark.parametrize("name", ["two_am_comp_attitude.toml", "two_am_robust.toml"])
def test_warm_up_covers_the_other_modes(name):
    spec = load_scenario(SCENARIO.parent / name)
    jitcache.warm(Pilot(spec, spec.ams[0].sysid).warm_up)
    before = {k.py_func.__name__: len(k.signatures) for k in kernels(law)}
    run(spec, duration_s=0.2)
    assert {k.py_func.__name__: len(k.signatures) for k in kernels(law)} == before
