"""A campaign's success inside and outside the vehicle's load envelope.

    python experiments/envelope.py DIR [DIR ...] [--max-mass-kg 1.5] [--max-squeeze-n 12]

Reads each DIR/trials.csv (`am-trials`) and splits its trials by whether the drawn object
can be held at all by this team: two pads need a normal force of at least m g / (2 mu) each
to hold mass m at pad friction mu (no margin), and the AM can neither push more than
--max-squeeze-n nor carry an object above --max-mass-kg. The defaults are what two AMs of
configs/vehicles/am3dof.toml were measured to hold (docs/robust_grasp.md, squeeze sizing).
Prints success with its Wilson 95 % interval in each part, and the failure classes.
"""
from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

from trials.report import read_csv, wilson_interval

G = 9.81


def inside(row: dict, max_mass_kg: float, max_squeeze_n: float, n_ams: int = 2) -> bool:
    m, mu = float(row["object_mass_kg"]), float(row["pad_friction"])
    return m <= max_mass_kg and m * G / (n_ams * mu) <= max_squeeze_n


def describe(rows: list[dict]) -> str:
    refused = sum(r["verdict"] == "refused" for r in rows)
    rows = [r for r in rows if r["verdict"] != "refused"]  # refused before flight: never flown
    if not rows:
        return f"no trials flown ({refused} refused)" if refused else "no trials"
    ok = sum(r["verdict"] == "success" for r in rows)
    lo, hi = wilson_interval(ok, len(rows))
    classes = collections.Counter(r["failure_class"] for r in rows if r["verdict"] != "success")
    failed = ", ".join(f"{c} {n}" for c, n in classes.most_common())
    return (f"{ok}/{len(rows)} succeeded ({100 * ok / len(rows):.0f} %, Wilson 95 % {100 * lo:.0f}-{100 * hi:.0f} %)"
            + (f"; {failed}" if failed else "") + (f"; {refused} refused before flight" if refused else ""))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dirs", nargs="+", type=Path)
    ap.add_argument("--max-mass-kg", type=float, default=1.5)
    ap.add_argument("--max-squeeze-n", type=float, default=12.0)
    a = ap.parse_args(argv)
    for d in a.dirs:
        path = d / "trials.csv"
        if not path.is_file():
            print(f"envelope: error: {path}: no such file (an am-trials --out folder?)", file=sys.stderr)
            return 2
        rows = read_csv(path)
        ins = [r for r in rows if inside(r, a.max_mass_kg, a.max_squeeze_n)]
        out = [r for r in rows if not inside(r, a.max_mass_kg, a.max_squeeze_n)]
        print(f"{d}: all {describe(rows)}")
        print(f"  inside the envelope (m <= {a.max_mass_kg:g} kg, m g / (2 mu) <= {a.max_squeeze_n:g} N): "
              f"{describe(ins)}")
        print(f"  outside: {describe(out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
