"""Where a wall-clock companion's CPU goes, part by part, flying the free-running simulator.

    python -m benchmarks.bench_wallclock [--speed 0.5] [--duration 8] [--scenario two_am_comp_attitude]

Starts `simulator --realtime` (no telemetry, no GCS ports) and runs `companion --clock wall`
for the scenario's first AM in this process (the other AMs stand on the ground), with each
part of its loop wrapped in a thread-CPU timer (`time.thread_time_ns`: what the part cost on
the processor, apart from the time other processes took it):

- law: the controller (`Pilot.command`: the pinocchio terms, the compiled law, the mission);
- inputs: the samples' ages, the estimate carried over its age, the frame (`_inputs` less the bus);
- bus: the servos through dynamixel-sdk (the sync read's request and collect, the sync write);
- link: the autopilot's MAVLink (reading and decoding, TIMESYNC, the handshake, the setpoint);
- ft: the Net F/T RDT client;
- other: the rest of the loop (the timer, the bookkeeping, the outcome, the steps before the engage).

Printed: each part's CPU per engaged control step (its total over the run divided by the
steps the controller ran), the loop's own CPU per step, and its period and latency figures.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from amlink import px4link
from benchmarks.cputime import wrap
from companion import wallclock, wallrun
from companion.devices import arm as arm_mod, netft
from companion.pilot import Pilot

ROOT = Path(__file__).resolve().parents[1]

INSTANCE = 80
PARTS = ("law", "inputs", "bus", "link", "ft")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speed", type=float, default=0.5)
    ap.add_argument("--duration", type=float, default=8.0, help="seconds of the mission flown (autopilot time)")
    ap.add_argument("--scenario", default="two_am_comp_attitude")
    a = ap.parse_args(argv)
    cfg = ROOT / "configs" / "scenarios" / f"{a.scenario}.toml"
    start = 6.0
    acc = dict.fromkeys(PARTS, 0)
    inner = dict.fromkeys(PARTS, 0)  # the bus's time inside _inputs
    wrap(Pilot, "command", acc, "law")
    for name in ("request", "write_torques"):
        wrap(arm_mod.ArmClient, name, acc, "bus")
    for name in ("collect", "read"):  # (called inside _inputs)
        wrap(arm_mod.ArmClient, name, acc, "bus", inner)
    loop_cpu = {"loop": 0}
    wrap(wallclock.WallClockLoop, "run", loop_cpu, "loop")
    wrap(wallclock.WallClockLoop, "_inputs", acc, "inputs")
    for name in ("poll", "send_attitude_target", "send_heartbeat"):
        wrap(px4link.Px4Link, name, acc, "link")
    for name in ("poll", "read"):
        wrap(netft.NetFtClient, name, acc, "ft")
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp)
        sim = subprocess.Popen([sys.executable, "-m", "simulator", "--realtime", "--speed", str(a.speed), "--config",
                                str(cfg), "--no-telemetry", "--gcs", "none", "--instance", str(INSTANCE),
                                "--mission-start", str(start), "--duration", str(start + a.duration),
                                "--run-dir", str(run_dir)], stdout=subprocess.DEVNULL,
                               stderr=open(run_dir / "simulator.log", "w"), cwd=ROOT)
        try:
            deadline = time.monotonic() + 120.0
            while "devices:" not in (run_dir / "simulator.log").read_text():
                if sim.poll() is not None or time.monotonic() > deadline:
                    raise SystemExit("the simulator did not start:\n" + (run_dir / "simulator.log").read_text())
                time.sleep(0.2)
            from companion.main import main as companion
            code = companion(["--sysid", "4", "--clock", "wall", "--config", str(cfg), "--no-telemetry",
                              "--instance", str(INSTANCE), "--mission-start", str(start),
                              "--outcome", str(run_dir / "am4.json"), "--frame-timeout", "3"])
        finally:
            sim.wait(timeout=60)
        summary = json.loads((run_dir / "am4.json").read_text())
    loop = summary["loop"]
    cpu = loop_cpu["loop"]
    n = loop["compute_ms"]["n"] or 1  # the steps the controller ran (take-off and mission)
    acc["inputs"] -= inner["bus"]  # the collect inside _inputs is the bus's
    acc["other"] = cpu - sum(acc.values())
    print(f"companion --clock wall, {a.scenario} AM 4, at {a.speed:g}x; exit {code}, {summary.get('ended')}")
    print(f"  {n} control steps (take-off and mission); the loop's thread: {cpu * 1e-6 / n:.3f} ms CPU per step")
    for k, v in acc.items():
        print(f"  {k:8s} {v * 1e-6 / n:7.3f} ms per step  ({100 * v / cpu:4.1f} %)")
    for k in ("period_ms", "compute_ms", "sample_to_setpoint_ms"):
        print(f"  {k}: {loop.get(k)}")


if __name__ == "__main__":
    main()
