"""Real-time factor of the whole multi-process SITL (simulator + one companion process per AM,
MAVLink over loopback UDP, lockstep) for N = 2, 5, 10, 20 AMs, next to bare PyBullet stepping
of the same world measured in the same run, and how the processes' CPU and memory grow with N.

    python -m benchmarks.bench_sitl [--duration 3] [--n 2 5 10 20] [--attitude] [--robust] [--devices]
                                    [--actuation-delay D] [--physics-rate HZ] [--substeps 2] [--sitl-only]

--attitude runs ten_am_attitude (SET_ATTITUDE_TARGET at 250 Hz, the emulated autopilot at
1 kHz) instead of ten_am (torque setpoints at 1 kHz); --devices turns [devices] on (the
sensors as devices and the flight controller's estimator, configs/randomize/default.toml's
levels); --robust starts from ten_am_robust(_attitude) instead (the hexarotor and the law's
options, with which the grasp takes an actuation delay of up to 3 ms: docs/flight_controller.md);
--physics-rate steps the world at HZ instead of the scenario's 1 kHz (the emulated autopilot's
loops at most as fast; a modelling choice measured in docs/benchmarks.md, "A lower physics
rate"); --substeps 2 integrates PyBullet's contacts and joints in two substeps of each step
([scenario].physics_substeps); --sitl-only leaves out the echo, UDP and bare PyBullet columns.

A SITL run whose verdict is a failure is named under its row. With --attitude --devices
without --robust that is the rule: the paper's quadrotor, flown by the law as written on
sensors at the default levels, saturates its rotors from the first step (the figures are
those of that run; --robust flies the same approach without failing).

Each N runs the ten_am scenario's object (a cylinder, r = 0.6 m, 1 kg here) with N AMs evenly spaced
around it, for --duration simulated seconds of the approach phase. The SITL figure is the
simulator's own (simulated time / wall time from the first lockstep step, start-up
excluded). Targets (issue 15): 2 AMs >= 3x real time, 10 AMs >= 0.7x; goals 5x and 1x.

Per process, from the outcome files of the SITL run (amruntime.procstats): CPU per step
(user + system, all threads, telemetry included) of a companion and of the simulator, and
a companion's resident memory at the end: rss (shared libraries counted whole in every
process), pss (shared pages divided among the processes sharing them: what N companions
really add up to) and uss (its own pages). Target for a companion: <= 120 MiB (goal 80).

"CPU cap": the real-time factor at which the simulator's and the N companions' CPU per step
(the two columns above; the recorder's not counted) would fill every core of this machine:
cores x step / (sim CPU + N x companion CPU / control_every). The simulator's CPU is per
physics step, a companion's per control step (attitude mode: one physics step in four). The lockstep cannot run faster than that however
the processes are scheduled, so a target above it needs less CPU per step, not better waiting.

Under each row, how the simulator's and a companion's main thread spent the run's wall time
(amruntime.procstats, from Linux's scheduler statistics): on a CPU, queued for one (ready,
while the cores ran other processes or threads), and blocked. In lockstep the simulator is
blocked while it waits for the companions' answers, and a companion while it waits for its
next frame. The run is no faster than the simulator's main thread: a simulator on a CPU for
most of the wall time is the bound, whatever the CPU cap says.

More columns take the whole apart, measured in the same run:
- "echo": the same simulator and lockstep with `echo_companion.py` in place of each
  companion (same client, codec and signing; it answers every frame at once with a hover
  setpoint, no controller, no telemetry). What the simulator, MAVLink and the processes
  cost when the controller costs nothing: an upper bound on the SITL's real-time factor.
- "echo+Xus" (with --echo-spin-us X): the same, each echo busy-waiting X us per step: a
  controller's compute time without its memory traffic and telemetry.
- "in-proc": `sitl.inprocess` on the same scenario: the same world, flight controllers
  and pilots called in one loop of one process, on one core, without MAVLink, sockets,
  telemetry or processes to switch between. What the lockstep's process boundary costs.
- "UDP": one Python process exchanging a datagram per step with N forked processes that
  answer at once (no MAVLink, no physics): the floor of the lockstep's message pattern.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from amcore.config import load_scenario
from amcore.mission import am_mission
from amcore.model import build_model
from simulator.verdict import MISSION_FAILED
from simulator.world import World

ROOT = Path(__file__).resolve().parents[1]

BASE = ROOT / "configs" / "scenarios" / "ten_am.toml"
ATTITUDE = ROOT / "configs" / "scenarios" / "ten_am_attitude.toml"
ROBUST = ROOT / "configs" / "scenarios" / "ten_am_robust.toml"
ROBUST_ATTITUDE = ROOT / "configs" / "scenarios" / "ten_am_robust_attitude.toml"
DEVICES = ROOT / "configs" / "randomize" / "default.toml"


def devices_table() -> str:
    """[devices] of the default randomization, as TOML tables of a scenario."""
    import tomllib
    d = tomllib.loads(DEVICES.read_text())["randomize"]["devices"]
    out = "[devices]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in d.items() if not isinstance(v, dict))
    for name, sub in d.items():
        if isinstance(sub, dict):
            out += f"[devices.{name}]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in sub.items())
    return out


def base_scenario(attitude: bool, robust: bool = False) -> Path:
    """The scenario the N-AM runs start from."""
    return (ROBUST_ATTITUDE if attitude else ROBUST) if robust else (ATTITUDE if attitude else BASE)


def _set_key(head: str, table: str, key: str, value) -> str:
    """The scenario text `head` with `key = value` in its [table] (replaced if there, else added)."""
    line = f"{key} = {value}\n"
    m = re.search(rf"(?ms)^\[{table}\]\n(.*?)(?=^\[|\Z)", head)
    if m is None:
        return head + f"\n[{table}]\n" + line
    body = re.sub(rf"(?m)^{key} = .*\n", "", m.group(1))
    return head[:m.start(1)] + line + body + head[m.end(1):]


def scenario_with(n: int, folder: Path, base: Path = BASE, devices: bool = False, delay_steps: int = 0,
                  physics_hz: float | None = None, substeps: int = 1) -> Path:
    text = base.read_text()
    head = re.sub(r'(?m)^vehicle = "\.\./vehicles/(\w+\.toml)"',
                  lambda m: f'vehicle = "{ROOT / "configs" / "vehicles" / m.group(1)}"', text.split("[[am]]")[0])
    # an overlay's base beside it: from the copy, by its absolute path
    head = re.sub(r'(?m)^base = "([\w.]+\.toml)"', lambda m: f'base = "{base.parent / m.group(1)}"', head)
    head = re.sub(r'name = "ten_am\w*"', f'name = "bench_{n}am"', head)
    head = _set_key(head, "object", "mass_kg", 1.0)  # liftable by any N (the approach is what runs)
    if delay_steps:  # [flight_controller].actuation_delay_steps
        head = _set_key(head, "flight_controller", "actuation_delay_steps", delay_steps)
    if physics_hz is not None:  # [scenario].rate_hz, and the emulated autopilot's loops at most as fast
        fc_hz = load_scenario(base).vehicle.flight_controller.rate_hz
        head = _set_key(head, "scenario", "rate_hz", float(physics_hz))
        head = _set_key(head, "flight_controller", "rate_hz", float(min(fc_hz, physics_hz)))
    if substeps != 1:  # [scenario].physics_substeps
        head = _set_key(head, "scenario", "physics_substeps", int(substeps))
    ams = "".join(f"[[am]]\nsysid = {2 + i}\nazimuth_deg = {360.0 * i / n}\n" for i in range(n))
    path = folder / f"bench_{n}am.toml"
    path.write_text(head + (devices_table() if devices else "") + ams)
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


def am_run_command(path: Path, duration: float, run_dir: Path) -> list[str]:
    """`am-run` of a scenario for `duration` simulated seconds into `run_dir`, without a progress bar."""
    exe = Path(sys.executable).parent / "am-run"
    return [str(exe) if exe.exists() else sys.executable, *([] if exe.exists() else ["-m", "sitl.launch"]),
            str(path), "--duration", str(duration), "--run-dir", str(run_dir), "--no-progress"]


def sitl_rtf(path: Path, duration: float, run_dir: Path) -> tuple[float, float, dict]:
    cmd = am_run_command(path, duration, run_dir)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ))
    wall = time.perf_counter() - t0
    if p.returncode not in (0, MISSION_FAILED):  # 2 s of the approach: the verdict may call it failed
        raise RuntimeError(f"SITL run failed: {p.stderr[-2000:]}")
    outcome = json.loads((run_dir / "outcome.json").read_text())
    comps = [json.loads(f.read_text()).get("process", {}) for f in sorted(run_dir.glob("am*.json"))]
    proc = {"sim_cpu_us": (outcome.get("process") or {}).get("cpu_us_per_step"),
            "comp_cpu_us": _median([c.get("cpu_us_per_step") for c in comps]),
            **{k: _median([c.get("memory_mib", {}).get(k) for c in comps]) for k in ("rss", "pss", "uss")},
            "sim_split": time_split([(outcome.get("process") or {}).get("main_thread")]),
            "comp_split": time_split([c.get("main_thread") for c in comps]),
            "verdict": outcome.get("verdict") or {}}
    return outcome["real_time_factor"], wall, proc


def inprocess_rtf(path: Path, duration: float) -> float:
    """x real time of `sitl.inprocess` on the same scenario: the same world, flight
    controllers and companions' pilots called in one loop of one process (one core), frames
    rounded as the wire rounds them, no MAVLink, sockets or telemetry; start-up excluded."""
    p = subprocess.run([sys.executable, "-m", "sitl.inprocess", str(path), "--duration", str(duration)],
                       capture_output=True, text=True, env=dict(os.environ))
    if p.returncode not in (0, MISSION_FAILED):
        raise RuntimeError(f"in-process run failed: {p.stderr[-2000:]}")
    return json.loads(p.stdout)["real_time_factor"]


def time_split(threads: list[dict | None]) -> tuple[float, float, float] | None:
    """Per cent of the wall time the main threads (`amruntime.procstats.CpuMeter.main_thread`)
    spent on a CPU, queued for one and blocked: the medians over the threads given (None
    where no process reported them: a machine without Linux's scheduler statistics)."""
    ts = [t for t in threads if t and t.get("wall_s")]
    if not ts:
        return None
    return tuple(_median([100.0 * t[k] / t["wall_s"] for t in ts]) for k in ("on_cpu_s", "queued_s", "blocked_s"))


def _median(xs) -> float:
    xs = [x for x in xs if x is not None]
    return float(np.median(xs)) if xs else float("nan")


def echo_rtf(path: Path, duration: float, run_dir: Path, spin_us: float = 0.0) -> float:
    """The SITL with echo companions (no controller, no telemetry; each busy-waits spin_us
    before answering); see the module doc."""
    spec = load_scenario(path)
    bin_dir = Path(sys.executable).parent
    sim_exe = bin_dir / "simulator"
    sim_cmd = [str(sim_exe)] if sim_exe.exists() else [sys.executable, "-m", "simulator"]
    sim = subprocess.Popen(sim_cmd + ["--config", str(path), "--bind", "udp:127.0.0.1:0", "--run-dir", str(run_dir),
                                      "--progress", "jsonl", "--no-telemetry", "--duration", str(duration)],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
    echoes: list[subprocess.Popen] = []
    try:
        bind = None
        while bind is None:
            line = sim.stdout.readline()
            if not line:
                raise RuntimeError(f"the simulator did not start (exit {sim.wait()})")
            event = json.loads(line)
            bind = event.get("connect") if event.get("event") == "ready" else None
        echoes = [subprocess.Popen([sys.executable, "-m", "benchmarks.echo_companion", "--sysid", str(am.sysid),
                                    "--sim", bind, "--config", str(path), "--spin-us", str(spin_us)],
                                   stderr=subprocess.DEVNULL, cwd=ROOT)
                  for am in spec.ams]
        sim.stdout.read()
        if sim.wait(timeout=600) not in (0, MISSION_FAILED):  # echoes fly no mission: its verdict fails
            raise RuntimeError(f"echo SITL run failed (simulator exit {sim.returncode})")
        for e in echoes:
            e.wait(timeout=30)
    finally:
        for p in [sim, *echoes]:
            if p.poll() is None:
                p.kill()
                p.wait()
    outcome = json.loads((run_dir / "outcome.json").read_text())
    ignored = {s: link["other_mode"] for s, link in outcome["fc_link"].items() if link["other_mode"]}
    if ignored:  # the echo answered in the wrong mode: the autopilot's work would be left out
        raise RuntimeError(f"echo SITL run: setpoints of the other mode ignored {ignored}")
    return outcome["real_time_factor"]


def udp_rtf(n: int, steps: int = 3000) -> float:
    """One process sends a 200-byte datagram to each of n forked processes per step and waits
    for their n 60-byte answers: the lockstep's message pattern alone, as x real time at 1 kHz."""
    hub = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    hub.bind(("127.0.0.1", 0))
    hub_addr = hub.getsockname()
    leaves, pids = [], []
    try:
        for _ in range(n):
            leaf = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            leaf.bind(("127.0.0.1", 0))
            leaves.append(leaf.getsockname())
            pid = os.fork()
            if pid == 0:  # the child answers until it reads b"q"
                try:
                    hub.close()
                    while leaf.recv(2048) != b"q":
                        leaf.sendto(b"a" * 60, hub_addr)
                finally:
                    os._exit(0)
            leaf.close()
            pids.append(pid)
        frame = b"f" * 200
        t0 = time.perf_counter()
        for _ in range(steps):
            for addr in leaves:
                hub.sendto(frame, addr)
            for _ in range(n):
                hub.recv(2048)
        wall = time.perf_counter() - t0
    finally:
        for addr in leaves:
            hub.sendto(b"q", addr)
        for pid in pids:
            os.waitpid(pid, 0)
        hub.close()
    return steps * 1e-3 / wall


def cpu_cap(sim_cpu_us: float, comp_cpu_us: float, n: int, step_us: float, cores: int | None = None,
            control_every: int = 1) -> float:
    """The real-time factor at which the simulator's and n companions' CPU per step fill every
    core (see the module doc): cores * step / (sim + n * companion / control_every); the
    simulator's CPU is per physics step, a companion's per control step (one in
    control_every physics steps)."""
    cores = os.cpu_count() if cores is None else cores
    return cores * step_us / (sim_cpu_us + n * comp_cpu_us / control_every)


def run_cap(path: Path, proc: dict, n: int) -> float:
    """`cpu_cap` of a SITL run of the scenario at `path` with n AMs, from `sitl_rtf`'s CPU figures."""
    sp = load_scenario(path)
    return cpu_cap(proc["sim_cpu_us"], proc["comp_cpu_us"], n, 1e6 / sp.rate_hz, control_every=sp.control_every)


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--n", type=int, nargs="+", default=[2, 5, 10, 20])
    ap.add_argument("--attitude", action="store_true", help="attitude mode (ten_am_attitude) instead of torque mode")
    ap.add_argument("--robust", action="store_true",
                    help="start from ten_am_robust(_attitude): the hexarotor and the law's options")
    ap.add_argument("--devices", action="store_true", help="[devices] on: sensors as devices and the estimator")
    ap.add_argument("--sitl-only", action="store_true", help="only the SITL column (and its CPU and memory)")
    ap.add_argument("--actuation-delay", type=int, default=0, metavar="D",
                    help="[flight_controller].actuation_delay_steps: setpoints act D physics steps after their "
                         "frames, the simulator stepping meanwhile (default 0: on arrival)")
    ap.add_argument("--physics-rate", type=float, default=None, metavar="HZ",
                    help="[scenario].rate_hz (default: the scenario's, 1 kHz), the emulated autopilot's loops at "
                         "most as fast ([flight_controller].rate_hz)")
    ap.add_argument("--substeps", type=int, default=1, choices=(1, 2),
                    help="[scenario].physics_substeps: PyBullet's substeps per physics step (default 1)")
    ap.add_argument("--echo-spin-us", type=float, default=None,
                    help="also run echo companions that busy-wait this long per step (a controller's compute)")
    a = ap.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f}; {os.cpu_count()} cores; {a.duration} s simulated per N; "
          f"actuation delay {a.actuation_delay} steps; "
          + (f"physics at {a.physics_rate:g} Hz; " if a.physics_rate else "")
          + (f"{a.substeps} PyBullet substeps a step; " if a.substeps > 1 else "") +
          f"{'attitude' if a.attitude else 'torque'} mode{', ten_am_robust' if a.robust else ''}; "
          f"[devices] {'on' if a.devices else 'off'}")
    print("x real time (simulated s / wall s), each column measured in this run:")
    spin = a.echo_spin_us
    spin_head = f" {'echo+' + format(spin, 'g') + 'us':>12}" if spin is not None else ""
    print(f"{'N':>3} {'SITL':>7} {'echo':>7}{spin_head} {'in-proc':>8} {'UDP':>7} {'bare PyBullet':>14} {'bare/SITL':>10} "
          f"{'wall incl. start-up':>20} | {'sim CPU/step':>12} {'comp CPU/step':>13} {'CPU cap':>8} {'comp rss':>9} "
          f"{'pss':>6} {'uss':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in a.n:
            path = scenario_with(n, Path(tmp), base_scenario(a.attitude, a.robust), a.devices, a.actuation_delay,
                                 a.physics_rate, a.substeps)
            nan = float("nan")
            bare = nan if a.sitl_only else bare_rtf(path, a.duration)
            rtf, wall, proc = sitl_rtf(path, a.duration, Path(tmp) / f"run{n}")
            echo = nan if a.sitl_only else echo_rtf(path, a.duration, Path(tmp) / f"echo{n}")
            spun = f" {echo_rtf(path, a.duration, Path(tmp) / f'spin{n}', spin):12.2f}" if spin is not None else ""
            inproc = nan if a.sitl_only else inprocess_rtf(path, a.duration)
            udp = nan if a.sitl_only else udp_rtf(n)
            cap = run_cap(path, proc, n)
            print(f"{n:>3} {rtf:7.2f} {echo:7.2f}{spun} {inproc:8.2f} {udp:7.1f} {bare:14.1f} {bare / rtf:10.0f} {wall:19.1f}s | "
                  f"{proc['sim_cpu_us']:10.0f}us {proc['comp_cpu_us']:11.0f}us {cap:7.2f}x {proc['rss']:6.0f}MiB "
                  f"{proc['pss']:6.0f} "
                  f"{proc['uss']:6.0f}", flush=True)
            if proc["sim_split"] and proc["comp_split"]:
                print("    main threads, per cent of the run's wall time on a CPU / queued for one / blocked: "
                      "simulator {:.0f} / {:.0f} / {:.0f}, a companion {:.0f} / {:.0f} / {:.0f}".format(
                          *proc["sim_split"], *proc["comp_split"]), flush=True)
            if proc["verdict"].get("status") == "failed":  # the figures are those of a run that failed its mission
                print(f"    N = {n}: the SITL run's {proc['verdict'].get('text', 'mission FAILED')}", flush=True)
    print("SITL: the product (am-run, telemetry on). echo: same lockstep, companions without a controller"
          + (f" (echo+{spin:g}us: each busy-waits {spin:g} us per step)" if spin is not None else "") + ".\n"
          "in-proc: the same scenario and pilots in one process on one core (sitl.inprocess).\n"
          "UDP: the message pattern alone. Targets: 2 AMs >= 3x, 10 AMs >= 0.7x (goals 5x, 1x); companion memory\n"
          "<= 120 MiB (goal 80). CPU per step: user + system of the whole process over the run, all threads.\n"
          "Main threads: the simulator's blocked time is its wait for the companions' answers; queued, the time it\n"
          "was ready to run while the cores ran the companions, the recorder or its own other threads.")


if __name__ == "__main__":
    main()
