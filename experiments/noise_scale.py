"""Grasp success against the sensors' noise and bias scale (issue 23's table).

For each scenario and control mode, one `am-trials` campaign per scale of
`configs/randomize/sensors_only.toml` (the nominal scenario, only the sensors varied; each
trial draws its own noise and biases) with `[devices].scale` set to that scale. The same
campaign seed is used in every cell, so each column flies the same per-trial seeds. In
attitude mode a scenario's `<name>_attitude.toml` sibling flies, where there is one.

    python experiments/noise_scale.py --out runs/noise --trials 10 --seed 2400 \\
        [--scenario configs/scenarios/two_am_robust.toml ...] [--scales 0 0.5 1 2 3 5] \\
        [--modes torque attitude] [--workers 2] [--set options.lateral_admittance_hz=0.3]

Prints a markdown table (success / trials per cell, with the median share of saturated
steps) and writes it to <out>/table.md; each cell's campaign stays in <out>/<cell>/.
A cell whose folder already holds a finished campaign (summary.json) is read, not rerun.
"""
from __future__ import annotations

import argparse
import csv
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RANDOMIZE = ROOT / "configs" / "randomize" / "sensors_only.toml"
TRIALS = Path(sys.executable).with_name("am-trials")


def flown(scenario: Path, mode: str) -> Path:
    """The scenario a mode flies: in attitude mode its `<name>_attitude.toml` sibling if there is
    one (250 Hz setpoints, the rotors' lag and attitude mode's options), else the scenario itself
    with only [flight_controller].mode changed."""
    sibling = scenario.with_name(f"{scenario.stem}_attitude.toml")
    return sibling if mode == "attitude" and sibling.exists() else scenario


def cell(out: Path, scenario: Path, mode: str, scale: float, a) -> tuple[int, int, float]:
    """(successes, trials, median saturated share) of one campaign, run unless already done."""
    folder = out / f"{scenario.stem}-{mode}-x{scale:g}"
    scenario = flown(scenario, mode)
    if not (folder / "summary.json").exists():
        if folder.exists():
            raise SystemExit(f"{folder}: an unfinished campaign; remove it to rerun")
        cmd = [str(TRIALS), str(scenario), "--trials", str(a.trials), "--seed", str(a.seed), "--out", str(folder),
               "--workers", str(a.workers), "--no-plots", "--no-progress", "--randomize", str(RANDOMIZE),
               "--set", f"devices.scale={scale!r}", "--set", f'flight_controller.mode="{mode}"']
        for s in a.set:
            cmd += ["--set", s]
        subprocess.run(cmd, check=True)
    with open(folder / "trials.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    steps = 20_000 * 2  # AM steps of a 20 s two-AM mission at 1 kHz (the share's denominator)
    sat = statistics.median(int(r["saturated_steps"]) / steps for r in rows) if rows else float("nan")
    return sum(r["verdict"] == "success" for r in rows), len(rows), sat


def main() -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--seed", type=int, default=2400)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scenario", type=Path, nargs="+",
                    default=[ROOT / "configs" / "scenarios" / "two_am_robust.toml",
                             ROOT / "configs" / "scenarios" / "two_am_robust_quad.toml"])
    ap.add_argument("--scales", type=float, nargs="+", default=[0.0, 0.5, 1.0, 2.0, 3.0, 5.0])
    ap.add_argument("--modes", nargs="+", default=["torque", "attitude"], choices=["torque", "attitude"])
    ap.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE",
                    help="passed to every campaign (am-trials --set)")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    head = "| scenario, mode | " + " | ".join(f"{s:g}x" for s in a.scales) + " |"
    lines = [head, "|" + "---|" * (len(a.scales) + 1)]
    for scenario in a.scenario:
        for mode in a.modes:
            cells = []
            for scale in a.scales:
                ok, n, sat = cell(a.out, scenario, mode, scale, a)
                cells.append(f"{ok}/{n} ({100 * sat:.2g} %)")
            lines.append(f"| {flown(scenario, mode).stem}, {mode} | " + " | ".join(cells) + " |")
            print(lines[-1], flush=True)
    table = "\n".join(lines) + "\n\nCells: successes/trials (median share of AM steps with the rotors saturated).\n"
    (a.out / "table.md").write_text(table)
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
