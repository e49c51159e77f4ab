"""The compiled law is compiled once per machine: processes starting together share one
compile through the lock (amruntime.jitcache), and a run after the warm-up compiles nothing."""
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
from amruntime import jitcache
from companion.pilot import Pilot
from sitl.inprocess import run

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "configs" / "scenarios" / "two_am_comp.toml"

_WARM = textwrap.dedent("""
    import json, sys
    from amcore.config import load_scenario
    from amruntime import jitcache
    from companion.pilot import Pilot
    spec = load_scenario(sys.argv[1])
    report = jitcache.warm(Pilot(spec, spec.ams[0].sysid).warm_up)
    print(json.dumps({"compiled": report.compiled, "seconds": report.seconds}))
""")


def _start(cache: Path, script: str = _WARM, *args: str) -> subprocess.Popen:
    """`script` in a new Python process with the numba cache in `cache` (args: its argv; default
    the scenario)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    return subprocess.Popen([sys.executable, "-c", script, *(args or (str(SCENARIO),))], stdout=subprocess.PIPE,
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


def test_warm_up_covers_the_robust_options_once_they_act():
    """The robust options' compiled shaping (amcore.law.adapted_reference) acts from the first
    contact on, which the warm-up's steps at rest do not reach: the warm-up compiles it itself,
    and the grasp's first second adds no specialization."""
    spec = load_scenario(SCENARIO.parent / "two_am_robust_attitude.toml")
    jitcache.warm(Pilot(spec, spec.ams[0].sysid).warm_up)
    before = {k.py_func.__name__: len(k.signatures) for k in kernels(law)}
    assert before["adapted_reference"] >= 1
    run(spec, duration_s=spec.mission.approach_end_s + 1.0)
    assert {k.py_func.__name__: len(k.signatures) for k in kernels(law)} == before


_GROUPS = textwrap.dedent("""
    import json, os, sys, time
    from pathlib import Path
    from amruntime import jitcache
    log, go = sys.argv[1], Path(sys.argv[2])
    def first_call(name):
        def call():
            t0 = time.time()
            time.sleep(1.0)
            with open(log, "a") as f:
                f.write(json.dumps([os.getpid(), name, t0, time.time()]) + "\\n")
        return call
    print("ready", flush=True)
    while not go.exists():
        time.sleep(0.01)
    jitcache.warm_groups([jitcache.Group("a.lock", (), first_call("a")), jitcache.Group("b.lock", (), first_call("b"))])
""")


def test_processes_starting_together_warm_different_groups_side_by_side(tmp_path):
    """Two processes warming the same two groups at once: while one holds the first group's
    lock, the other takes the second group, so the two groups' first calls overlap in time;
    a group is never warmed by two processes at once, and each process warms both."""
    log, go = tmp_path / "log.jsonl", tmp_path / "go"
    procs = [_start(tmp_path / "cache", _GROUPS, str(log), str(go)) for _ in range(2)]
    for p in procs:
        assert p.stdout.readline().strip() == "ready", p.stderr.read()
    go.touch()
    for p in procs:
        _, err = p.communicate(timeout=60)
        assert p.returncode == 0, err
    calls = [json.loads(line) for line in log.read_text().splitlines()]
    assert sorted((pid, name) for pid, name, _, _ in calls) == sorted(
        (p.pid, name) for p in procs for name in ("a", "b"))
    first = {name: min((c for c in calls if c[1] == name), key=lambda c: c[2]) for name in ("a", "b")}
    assert first["a"][0] != first["b"][0]  # two processes ...
    assert first["a"][2] < first["b"][3] and first["b"][2] < first["a"][3]  # ... at the same time
    for name in ("a", "b"):  # the lock: one process at a time per group
        (_, _, _, end), (_, _, start, _) = sorted((c for c in calls if c[1] == name), key=lambda c: c[2])
        assert end <= start


@pytest.fixture
def first_run(monkeypatch) -> list[tuple[list[str], int]]:
    """The law looks uncached (a first run); each `jitcache.warm_groups` call is recorded as
    (its groups' locks, the child processes alive when it starts) before it runs."""
    import multiprocessing

    calls = []
    real = jitcache.warm_groups

    def warm_groups(groups):
        calls.append(([g.lock for g in groups], len(multiprocessing.active_children())))
        return real(groups)
    monkeypatch.setattr(jitcache, "looks_cached", lambda: False)
    monkeypatch.setattr(jitcache, "warm_groups", warm_groups)
    return calls


def test_am_run_compiles_the_simulators_kernels_beside_the_law(first_run, capsys):
    """On a first run (the law not cached), am-run's warm-up starts a second process for the
    simulator's kernels before it compiles the law, and waits for it before going on."""
    import multiprocessing

    from sitl import launch

    launch._warm_kernels(load_scenario(SCENARIO), SCENARIO)
    # the law and the simulator's group here, one child beside
    assert first_run == [([jitcache.LAW_LOCK, jitcache.SIMULATOR_LOCK], 1)]
    assert multiprocessing.active_children() == []
    assert "warning" not in capsys.readouterr().err


def test_am_run_warms_the_simulators_kernels_itself_if_the_second_process_fails(first_run, tmp_path, capfd):
    from sitl import launch

    launch._warm_kernels(load_scenario(SCENARIO), tmp_path / "gone.toml")  # the child cannot read it: it fails
    assert [locks for locks, _ in first_run] == [[jitcache.LAW_LOCK, jitcache.SIMULATOR_LOCK]]
    assert "compiling the simulator's kernels in a second process failed (exit 1)" in capfd.readouterr().err
