"""Where a lockstep step's CPU goes in place: the whole SITL (`am-run`, telemetry on) with the
simulator and every companion timed part by part (`benchmarks.inplace_parts`).

    python -m benchmarks.bench_inplace [--n 2] [--duration 3] [--attitude] [--devices] [--actuation-delay D]

Runs the scenario of `bench_sitl.py` (ten_am's object with N AMs, approach phase) through
`am-run`'s own main, with the simulator and the companions started through
`inplace_parts.py` instead of their console scripts, and prints per part the median and
90th percentile of one call's thread CPU time and its CPU per physics step (all calls of the
run over its physics steps). A part's time in place is what it costs between the other
processes on the same cores (caches and branch predictors cold), typically several times
its cost back to back (`bench_world.py`, `bench_controller.py`).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

from amcore.config import load_scenario
from benchmarks.bench_sitl import ATTITUDE, BASE, scenario_with


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=2)
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--attitude", action="store_true")
    ap.add_argument("--devices", action="store_true")
    ap.add_argument("--actuation-delay", type=int, default=0)
    a = ap.parse_args()
    import sitl.launch as launch

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        path = scenario_with(a.n, tmp, ATTITUDE if a.attitude else BASE, a.devices, a.actuation_delay)
        spec = load_scenario(path)
        count = iter(range(10_000))

        def command(name: str) -> list[str]:  # the simulator and the companions, timed by part
            if name in ("simulator", "companion"):
                return [sys.executable, "-m", "benchmarks.inplace_parts", name,
                        str(tmp / f"{name}-{next(count)}.json"), "--"]
            return real(name)

        real, launch._command = launch._command, command
        code = launch.main([str(path), "--duration", str(a.duration), "--run-dir", str(tmp / "run"), "--no-progress"])
        if code not in (0, 4):  # 4: the approach alone is no mission
            raise SystemExit(f"am-run exited {code}")
        outcome = json.loads((tmp / "run" / "outcome.json").read_text())
        steps = outcome["steps"]
        print(f"load average after: {os.getloadavg()[0]:.2f}; {a.n} AMs, {'attitude' if a.attitude else 'torque'} "
              f"mode, [devices] {'on' if a.devices else 'off'}, actuation delay {a.actuation_delay}; "
              f"{outcome['real_time_factor']:.2f}x real time, {steps} physics steps, control every "
              f"{spec.control_every}")
        for role in ("simulator", "companion"):
            files = sorted(tmp.glob(f"{role}-*.json"))
            runs = [json.loads(f.read_text()) for f in files]
            print(f"\n{role} ({len(runs)} process{'es' if len(runs) > 1 else ''}; per call: median and p90 [us]; "
                  f"per physics step: the run's sum / steps{', mean over the processes' if len(runs) > 1 else ''})")
            parts = {}
            for r in runs:
                for part, v in r["parts"].items():
                    parts.setdefault(part, []).append(v)
            for part, vs in parts.items():
                med = sorted(v["median_us"] for v in vs)[len(vs) // 2]
                p90 = sorted(v["p90_us"] for v in vs)[len(vs) // 2]
                per_step = 1e6 * sum(v["sum_s"] for v in vs) / len(vs) / steps
                calls = sum(v["calls"] for v in vs) / len(vs) / steps
                print(f"  {part:50s} {med:8.1f} {p90:8.1f}   {per_step:8.1f} us/step   ({calls:.2f} calls/step)")
            cpu = sum(r["thread_cpu_s"] for r in runs) / len(runs)
            print(f"  {'main thread, start-up included':50s} {'':17s}   {1e6 * cpu / steps:8.1f} us/step")


if __name__ == "__main__":
    main()
