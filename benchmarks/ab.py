"""Before and after in one run: a benchmark run alternately against two source trees.

    python benchmarks/ab.py --base /path/to/old/tree [--rounds 3] -- benchmarks/bench_core.py --n 2
    python benchmarks/ab.py --base /path/to/old/tree -- -m simulator.bench_world

The machine is shared and its load changes from minute to minute, so a figure measured today
is compared only with one measured in the same run: this runs the given benchmark script
(of this tree; with -m, each tree's own module) `--rounds` times against each tree in turn
(base, this, base, this, ...),
with PYTHONPATH set to that tree so that every project module is imported from it, and
prints each round's output under its label. Make the base tree with, for example,
`git archive <commit> | tar -x -C /tmp/base` (numba compiles its kernels there on the first
round, which is therefore also run once before timing, as `--warm`).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(tree: Path, script: list[str]) -> str:
    env = dict(os.environ, PYTHONPATH=str(tree))
    if script[0] != "-m":  # as `python script`, but with the tree, not the script's folder, first on sys.path
        script = ["-c", "import runpy, sys; sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], run_name='__main__')",
                  *script]
    out = subprocess.run([sys.executable, *script], cwd=tree, env=env, capture_output=True, text=True)
    return out.stdout + (f"[exit {out.returncode}] {out.stderr[-2000:]}" if out.returncode else "")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", type=Path, required=True, help="the old tree")
    ap.add_argument("--after", type=Path, default=ROOT, help="the new tree (default: this one)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--warm", action="store_true", help="run once in each tree before timing (numba's compiles)")
    ap.add_argument("script", nargs=argparse.REMAINDER, help="-- then the benchmark script and its arguments")
    a = ap.parse_args()
    script = a.script[1:] if a.script[:1] == ["--"] else a.script
    if script[0] != "-m":
        script = [str((ROOT / script[0]).resolve()), *script[1:]]
    trees = {"before": a.base.resolve(), "after": a.after.resolve()}
    if a.warm:
        for tree in trees.values():
            run(tree, script)
    for r in range(a.rounds):
        for label, tree in trees.items():
            print(f"== {label} (round {r + 1}, {tree})", flush=True)
            print(run(tree, script), flush=True)


if __name__ == "__main__":
    main()
