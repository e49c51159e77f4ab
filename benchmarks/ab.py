"""Before and after in one run: a benchmark run alternately against two source trees.

    python -m benchmarks.ab --base /path/to/old/tree [--rounds 3] -- -m benchmarks.bench_core --n 2
    python -m benchmarks.ab --base /path/to/old/tree -- -m benchmarks.bench_world

The machine is shared and its load changes from minute to minute, so a figure measured today
is compared only with one measured in the same run: this runs the given benchmark module
`--rounds` times against each tree in turn (base, this, base, this, ...), each tree's own
copy of it, from that tree's root and with PYTHONPATH set to it, so that every module (the
project's, the benchmark's, the tests' helpers) is imported from that tree. Make the base
tree with, for example, `git archive <commit> | tar -x -C /tmp/base`; to time a benchmark the
base commit does not have, copy this tree's `benchmarks/` into it. numba compiles its kernels
in each tree on the first round, which is therefore also run once before timing, as `--warm`.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(tree: Path, module: list[str]) -> str:
    """`python -m MODULE ARGS` in `tree`; its output, or its exit status and error output."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, *module], cwd=tree, env=env, capture_output=True, text=True)
    return out.stdout + (f"[exit {out.returncode}] {out.stderr[-2000:]}" if out.returncode else "")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", type=Path, required=True, help="the old tree")
    ap.add_argument("--after", type=Path, default=ROOT, help="the new tree (default: this one)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--warm", action="store_true", help="run once in each tree before timing (numba's compiles)")
    ap.add_argument("module", nargs=argparse.REMAINDER, help="-- then -m, the benchmark module and its arguments")
    a = ap.parse_args()
    module = a.module[1:] if a.module[:1] == ["--"] else a.module
    if module[:1] != ["-m"] or len(module) < 2:
        ap.error("give the benchmark as a module: -- -m benchmarks.NAME [its arguments]")
    trees = {"before": a.base.resolve(), "after": a.after.resolve()}
    if a.warm:
        for tree in trees.values():
            run(tree, module)
    for r in range(a.rounds):
        for label, tree in trees.items():
            print(f"== {label} (round {r + 1}, {tree})", flush=True)
            print(run(tree, module), flush=True)


if __name__ == "__main__":
    main()
