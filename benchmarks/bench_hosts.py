"""What the process count costs the SITL: the same `am-run` with the companions grouped K to a
process, each AM's companion a thread of its group's process (a prototype for measuring, not
a supported way to run the stack).

    python -m benchmarks.bench_hosts [--n 10] [--per-process 1 5 10] [--duration 3] [--attitude] [--robust] [--devices]

Each AM keeps its own companion (`companion.main`, its own MAVLink link, signing key, pilot and
telemetry session); only the process around it is shared: the first companion of a group
runs the group's K companions' mains as threads, the others' processes wait for their
outcome files and exit. The GIL serializes the threads' Python; the law and pinocchio's
calls run in it as they do in a process of their own. K = 1 is `am-run` as shipped (one
`companion` process per AM). Prints, per K, the simulator's real-time factor, its CPU per physics step and
the companion processes' CPU per AM and control step (user + system of each companion
process from the lockstep's start, `amruntime.procstats`, summed and divided by AMs and
control steps), in one run.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path


def _argv_for(argv: list[str], own: int, sysid: int) -> list[str]:
    """The companion arguments of `sysid` from those am-run gave companion `own`."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a == "--sysid":
            out += [a, str(sysid)]
            i += 2
            continue
        if a in ("--outcome", "--telemetry-key-file", "--tlog"):
            out += [a, argv[i + 1].replace(f"am{own}", f"am{sysid}").replace(f"companion-{own}", f"companion-{sysid}")]
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def host(per_process: int, argv: list[str]) -> int:
    """One companion process of am-run: a group's host (its first AM) or a member that waits."""
    from amcore.config import load_scenario
    own = int(argv[argv.index("--sysid") + 1])
    spec = load_scenario(argv[argv.index("--config") + 1])
    sysids = [a.sysid for a in spec.ams]
    k = sysids.index(own)
    group = sysids[k - k % per_process: k - k % per_process + per_process]
    outcome = Path(argv[argv.index("--outcome") + 1])
    if own != group[0]:  # a member: its companion runs in the host's process
        while not outcome.exists():
            time.sleep(0.2)
        return 0
    import signal

    import companion.main as cm
    signal.signal = lambda *_a: None  # handlers belong to the main thread; am-run stops the process
    codes = {}

    def run(s: int) -> None:
        codes[s] = cm.main(_argv_for(argv, own, s))
    threads = [threading.Thread(target=run, args=(s,), daemon=True) for s in group]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return max(codes.values(), default=1)


def measure(path: Path, per_process: int, duration: float, run_dir: Path, telemetry: bool = True) -> dict:
    import sitl.launch as launch
    from amcore.config import load_scenario
    real = launch._command

    def command(name: str) -> list[str]:  # K = 1: the companions' own console script, as shipped
        if name == "companion" and per_process > 1:
            return [sys.executable, "-m", "benchmarks.bench_hosts", "--host", str(per_process), "--"]
        return real(name)
    launch._command = command
    try:
        with open(os.devnull, "w") as quiet, contextlib.redirect_stderr(quiet):
            launch.main([str(path), "--duration", str(duration), "--run-dir", str(run_dir), "--no-progress",
                         *([] if telemetry else ["--no-telemetry"])])
    finally:
        launch._command = real
    outcome = json.loads((run_dir / "outcome.json").read_text())
    spec = load_scenario(path)
    steps = outcome["steps"]
    # amruntime.procstats measures its process's CPU from the lockstep's start: in a shared
    # process each member's figure is the whole process's, so one per group counts
    cpu = {a.sysid: json.loads((run_dir / f"am{a.sysid}.json").read_text())["process"]["cpu_s"] for a in spec.ams}
    sysids = [a.sysid for a in spec.ams]
    groups = [sysids[i:i + per_process] for i in range(0, len(sysids), per_process)]
    comp = [max(cpu[s] for s in g) for g in groups]
    control_steps = steps / spec.control_every
    return {"rtf": outcome["real_time_factor"], "sim_cpu_us": (outcome.get("process") or {}).get("cpu_us_per_step"),
            "comp_cpu_us": 1e6 * sum(comp) / len(spec.ams) / control_steps if comp else float("nan"),
            "verdict": outcome.get("verdict", {}).get("status")}


def main() -> None:
    if len(sys.argv) > 2 and sys.argv[1] == "--host":
        sys.exit(host(int(sys.argv[2]), sys.argv[sys.argv.index("--") + 1:]))
    from benchmarks.bench_sitl import base_scenario, scenario_with
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=10)
    ap.add_argument("--per-process", type=int, nargs="+", default=[1, 5, 10])
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--attitude", action="store_true")
    ap.add_argument("--robust", action="store_true")
    ap.add_argument("--devices", action="store_true")
    ap.add_argument("--no-telemetry", action="store_true", help="am-run --no-telemetry")
    a = ap.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f}; {os.cpu_count()} cores; {a.n} AMs, "
          f"{'attitude' if a.attitude else 'torque'} mode{', robust' if a.robust else ''}, "
          f"[devices] {'on' if a.devices else 'off'}, {a.duration} s simulated, telemetry "
          f"{'off' if a.no_telemetry else 'on'}")
    print(f"{'AMs per process':>16} {'x real time':>12} {'sim CPU/step':>13} {'companions CPU per AM step':>27}  verdict")
    with tempfile.TemporaryDirectory() as tmp:
        path = scenario_with(a.n, Path(tmp), base_scenario(a.attitude, a.robust), a.devices)
        for r in range(a.rounds):
            for k in a.per_process:
                m = measure(path, k, a.duration, Path(tmp) / f"run{k}-{r}", not a.no_telemetry)
                print(f"{k:>16} {m['rtf']:12.2f} {m['sim_cpu_us']:11.0f}us {m['comp_cpu_us']:25.0f}us  {m['verdict']}",
                      flush=True)


if __name__ == "__main__":
    main()
