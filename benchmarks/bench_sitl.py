"""Real-time factor of the whole multi-process SITL (simulator + one companion process per AM,
MAVLink over loopback UDP, lockstep) for N = 1, 2, 5, 10 AMs, next to bare PyBullet stepping
of the same world measured in the same run.

    python benchmarks/bench_sitl.py [--duration 3] [--n 1 2 5 10]

Each N runs the ten_am scenario's object (5 kg cylinder, r = 0.6 m) with N AMs evenly spaced
around it, for --duration simulated seconds of the approach phase. The SITL figure is the
simulator's own (simulated time / wall time from the first lockstep step, start-up
excluded). Targets (issue 3): 2 AMs >= 2x real time, 10 AMs >= 0.5x; goals 5x and 1x.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from amcore.config import load_scenario  # noqa: E402
from amcore.mission import am_mission  # noqa: E402
from amcore.model import build_model  # noqa: E402
from simulator.world import World  # noqa: E402

BASE = ROOT / "configs" / "scenarios" / "ten_am.toml"


def scenario_with(n: int, folder: Path) -> Path:
    text = BASE.read_text()
    head = text.split("[[am]]")[0].replace('vehicle = "../vehicles/am3dof.toml"',
                                           f'vehicle = "{ROOT / "configs" / "vehicles" / "am3dof.toml"}"')
    head = re.sub(r'name = "ten_am"', f'name = "bench_{n}am"', head)
    ams = "".join(f"[[am]]\nsysid = {2 + i}\nazimuth_deg = {360.0 * i / n}\n" for i in range(n))
    path = folder / f"bench_{n}am.toml"
    path.write_text(head + ams)
    return path


def bare_rtf(path: Path, duration: float) -> float:
    spec = load_scenario(path)
    model = build_model(spec.vehicle)
    world = World(spec, {a.sysid: am_mission(spec, a, model).initial_state() for a in spec.ams})
    world.connect()
    try:
        hover = model.mass_kg * model.gravity_mps2
        for s in world.sysids:
            world.apply(s, hover, np.zeros(3), np.zeros(model.n))
        steps = int(duration * spec.rate_hz)
        t0 = time.perf_counter()
        for _ in range(steps):
            world.step()
        return duration / (time.perf_counter() - t0)
    finally:
        world.close()


def sitl_rtf(path: Path, duration: float, run_dir: Path) -> tuple[float, float]:
    exe = Path(sys.executable).parent / "am-run"
    cmd = [str(exe) if exe.exists() else sys.executable, *([] if exe.exists() else ["-m", "simulator.launch"]),
           str(path), "--duration", str(duration), "--run-dir", str(run_dir), "--no-progress"]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ))
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"SITL run failed: {p.stderr[-2000:]}")
    return json.loads((run_dir / "outcome.json").read_text())["real_time_factor"], wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--n", type=int, nargs="+", default=[1, 2, 5, 10])
    a = ap.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f}; {os.cpu_count()} cores; {a.duration} s simulated per N")
    print(f"{'N':>3} {'SITL x real time':>17} {'bare PyBullet x real time':>26} {'ratio':>7} {'wall incl. start-up':>20}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in a.n:
            path = scenario_with(n, Path(tmp))
            bare = bare_rtf(path, a.duration)
            rtf, wall = sitl_rtf(path, a.duration, Path(tmp) / f"run{n}")
            print(f"{n:>3} {rtf:17.2f} {bare:26.1f} {bare / rtf:7.0f} {wall:19.1f}s", flush=True)


if __name__ == "__main__":
    main()
