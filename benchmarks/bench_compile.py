"""The first run's compile on a machine: wall and CPU time of each kernel group compiled on an
empty numba cache, at LLVM optimization levels side by side (`amcore.jit`, NUMBA_OPT).

    python -m benchmarks.bench_compile [--levels 1 3] [--rounds 2] [--scenario configs/scenarios/two_am_comp_attitude.toml]

Each measurement is a new Python process with an empty NUMBA_CACHE_DIR of its own and
NUMBA_OPT set to the level (the cache does not record the level it was compiled at, so a
shared one would be loaded as it is). It warms one group as `amruntime.jitcache` does: the
control law with the telemetry's kernels (`Pilot.warm_up`, the law's argument types of the
scenario), or the simulator's kernels (`simulator.core.warm_up_kernels`). The levels
alternate within each round. Imports are outside the timed span; CPU is the process's user +
system time over it. A level's compile is the law's wall time when the two groups compile side
by side on two cores, as `am-run` does on an empty cache.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_WARM = textwrap.dedent("""
    import json, sys, time
    from amcore.config import load_scenario
    from amruntime import jitcache
    from companion.pilot import Pilot
    from simulator.core import kernel_group
    spec = load_scenario(sys.argv[2])
    group = (jitcache.law_group(Pilot(spec, spec.ams[0].sysid).warm_up) if sys.argv[1] == "law"
             else kernel_group(spec))
    w0, c0 = time.perf_counter(), time.process_time()
    report = jitcache.warm_groups([group])
    print(json.dumps({"wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
                      "compiled": report.compiled}))
""")


def measure(group: str, level: str, scenario: Path) -> dict:
    """One group compiled on an empty cache at `level`, in a new process."""
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_OPT": level, "NUMBA_CACHE_DIR": cache}
        out = subprocess.run([sys.executable, "-c", _WARM, group, str(scenario)], capture_output=True, text=True,
                             env=env, cwd=ROOT, timeout=1800)
    if out.returncode != 0:
        raise SystemExit(f"bench_compile: warming {group} at level {level} failed:\n{out.stderr}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--levels", nargs="+", default=["1", "3"], choices=["0", "1", "2", "3"])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--scenario", type=Path, default=ROOT / "configs" / "scenarios" / "two_am_comp_attitude.toml")
    a = ap.parse_args()
    print(f"{a.scenario.name}; load average before: {os.getloadavg()[0]:.2f}; {os.cpu_count()} cores")
    print(f"{'round':>5} {'level':>5} {'group':>10} {'wall [s]':>9} {'CPU [s]':>8} {'kernels compiled':>17}")
    for r in range(1, a.rounds + 1):
        for level in a.levels:
            for group in ("law", "simulator"):
                m = measure(group, level, a.scenario)
                print(f"{r:>5} {level:>5} {group:>10} {m['wall_s']:>9.1f} {m['cpu_s']:>8.1f} {m['compiled']:>17}",
                      flush=True)


if __name__ == "__main__":
    main()
