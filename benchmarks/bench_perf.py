"""Where the CPU goes by library, sampled by Linux `perf`: the Python interpreter, numpy,
numba's compiled code and its runtime (allocation, reference counts, dispatch), the C
library's malloc and memcpy, PyBullet, pinocchio, the kernel.

    python -m benchmarks.bench_perf [--what trial law sitl] [--duration S] [--window S] [--freq HZ]

The timers of `bench_trial_step.py` and `bench_inplace.py` say which of the project's parts
takes the time; this says what kind of work it is, inside all parts at once. Sampling
(`perf record -F`, the CPU clock; no hardware counters needed) starts after the start-up,
attached to the running process(es), so imports, compilation and loading the kernels are
left out.

- trial: one campaign trial in process (`sitl.inprocess.run`, two_am_comp, default
  randomization, trial 0 of seed 1, as `bench_trial_step.py`), after a 0.2 s warm-up run.
- law: `amcore.law.control_law` called back to back on one step's arguments (as
  `bench_controller.py`'s "compiled law alone"). numba's reference counts (`NRT_incref`,
  `NRT_decref`: an atomic add each) are told apart from the rest of the compiled code by
  their addresses, which the process prints.
- sitl: the multi-process SITL of `bench_sitl.py` (2 AMs, attitude mode, devices on,
  ten_am_robust_attitude's vehicle and law options, the approach), every process of `am-run`
  attached --attach-after seconds after both companions started; rows per process kind.

Needs `perf` (Debian: linux-perf) and `kernel.perf_event_paranoid` <= 2 for a process of
one's own; exits 2 saying so when it is missing. A sample in a library counts for that
library whoever called it: PyBullet's getters called from Python count as PyBullet, the
interpreter's work to call them as the interpreter.
"""
from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# (category, substrings of the shared object's file name), first match wins
CATEGORIES = (
    ("numba: reference counts (NRT_incref/decref)", ()),  # by address, see `classify`
    ("numba: compiled code", ("[JIT]", "perf-")),
    ("numba: runtime, dispatch, unboxing", ("_nrt_python", "_dispatcher", "_helperlib")),
    ("Python interpreter", ("libpython", "python3")),
    ("numpy", ("_multiarray_umath", "_umath", "openblas", "_generator", "_pcg64", "_bounded_integers")),
    ("C library (malloc, free, memcpy)", ("libc.so", "libc-")),
    ("libm", ("libm.so",)),
    ("PyBullet", ("pybullet",)),
    ("pinocchio (with boost.python, eigenpy)", ("pinocchio", "boost_python", "eigenpy")),
    ("OpenSSL / hashlib", ("libcrypto", "_hashlib")),
    ("zenoh", ("zenoh",)),
    ("Python's C modules (math, array, struct, ...)", ("cpython-3",)),
    ("kernel", ("[kernel", "[vdso]")),
)
OTHER = "other"
_LINE = re.compile(r"^\s*(\d+)\s+([0-9a-f]+)\s+(.*?)\s+\(([^()]*)\)\s*$")


def classify(dso: str, ip: int, refcount_range: tuple[int, int] | None = None) -> str:
    """The category of one sample: its shared object, or its address for numba's reference counts."""
    if refcount_range is not None and refcount_range[0] <= ip < refcount_range[1]:
        return CATEGORIES[0][0]
    base = dso.rsplit("/", 1)[-1]
    for name, keys in CATEGORIES:
        if any(k in base for k in keys):
            return name
    return OTHER


def parse_script(text: str, refcount_range: tuple[int, int] | None = None):
    """`perf script -F pid,ip,sym,dso` output -> (Counter per (pid, category), Counter per (pid, dso, symbol))."""
    cats, syms = collections.Counter(), collections.Counter()
    for line in text.splitlines():
        m = _LINE.match(line)
        if m is None:
            continue
        pid, ip, sym, dso = int(m.group(1)), int(m.group(2), 16), m.group(3), m.group(4)
        cats[pid, classify(dso, ip, refcount_range)] += 1
        syms[pid, Path(dso).name or dso, sym if sym != "[unknown]" else hex(ip)] += 1
    return cats, syms


def _perf() -> str:
    exe = shutil.which("perf")
    if exe is None:
        print("bench_perf: `perf` not found (Debian: apt install linux-perf)", file=sys.stderr)
        sys.exit(2)
    return exe


def record(pids: list[int], seconds: float, freq: int, out: Path) -> None:
    p = subprocess.run([_perf(), "record", "-F", str(freq), "-p", ",".join(map(str, pids)), "-o", str(out),
                        "--", "sleep", str(seconds)], capture_output=True, text=True)
    if p.returncode != 0 or not out.exists():
        print(f"bench_perf: perf record failed ({p.returncode}): {p.stderr.strip()[-800:]}\n"
              "(kernel.perf_event_paranoid must be <= 2 to sample one's own processes)", file=sys.stderr)
        sys.exit(2)


def script(data: Path) -> str:
    return subprocess.run([_perf(), "script", "-i", str(data), "-F", "pid,ip,sym,dso"], capture_output=True,
                          text=True, check=True).stdout


def report(cats, syms, groups: dict[int, str], top: int, us_per_step: float | None = None) -> None:
    """Per group of processes: each category's share of the samples (and, given the CPU per
    step, that share of it), then the top symbols."""
    by_group = collections.defaultdict(collections.Counter)
    sym_group = collections.defaultdict(collections.Counter)
    for (pid, cat), k in cats.items():
        by_group[groups.get(pid, "other processes")][cat] += k
    for (pid, dso, sym), k in syms.items():
        sym_group[groups.get(pid, "other processes")][dso, sym] += k
    for g, c in by_group.items():
        total = sum(c.values())
        print(f"\n{g}: {total} samples")
        for name in [n for n, _ in CATEGORIES] + [OTHER]:
            if c[name]:
                share = c[name] / total
                per = f"  {share * us_per_step:6.1f} us per physics step" if us_per_step else ""
                print(f"  {name:<48} {100.0 * share:6.1f} %{per}")
        print(f"  top {top} symbols:")
        for (dso, sym), k in sym_group[g].most_common(top):
            print(f"    {100.0 * k / total:5.1f} %  {sym[:60]:<60} {dso}")


# ----------------------------------------------------------------------------- the sampled children
def _print_refcount_addresses() -> None:
    """Where numba's NRT_incref and NRT_decref lie in this process (each a few bytes of code)."""
    from numba.core.runtime import nrt
    lib = nrt.rtsys.library
    inc, dec = (lib.get_pointer_to_function(f) for f in ("NRT_incref", "NRT_decref"))
    print(f"refcounts {min(inc, dec):x} {max(inc, dec) + 0x20:x}", flush=True)


def _child_trial(duration: float) -> None:
    from benchmarks.bench_trial_step import _trial_spec

    import sitl.inprocess as ip
    with tempfile.TemporaryDirectory() as tmp:
        spec = _trial_spec(ROOT / "configs" / "scenarios" / "two_am_comp.toml", Path(tmp))
        ip.run(spec, 0.2)
        _print_refcount_addresses()
        print("ready", flush=True)
        c0 = time.thread_time()
        ip.run(spec, duration)
        steps = round(duration / spec.dt_s)
        print(f"main thread CPU per physics step: {(time.thread_time() - c0) / steps * 1e6:.1f} us "
              f"({steps} steps)", flush=True)


def _child_law(duration: float) -> None:
    import numpy as np

    from amcore import law
    from amcore.config import load_scenario
    from amcore.control import ControllerMemory, ControllerParams, step
    from amcore.mission import am_mission
    from amcore.model import AmState, build_model, create_data
    from amcore.so3 import exp_so3
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    model = build_model(spec.vehicle)
    mission = am_mission(spec, spec.ams[0], model)
    params = ControllerParams.from_vehicle(spec.vehicle, mission.frame)
    x, rng = mission.initial_state(), np.random.default_rng(0)
    st = AmState(x.p_WB, x.R_WB @ exp_so3(0.05 * rng.normal(size=3)), 0.1 * rng.normal(size=3),
                 0.1 * rng.normal(size=3), x.q + 0.05 * rng.normal(size=3), 0.1 * rng.normal(size=3))
    args, compiled = [], law.control_law

    def capture(*a):
        args.append(a)
        return compiled(*a)
    law.control_law = capture
    try:
        step(model, create_data(model), params, st, mission.reference(5.0), rng.normal(size=6), ControllerMemory(), 0.0)
    finally:
        law.control_law = compiled
    a = args[0]
    compiled(*a)
    _print_refcount_addresses()
    print("ready", flush=True)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < duration:
        for _ in range(1000):
            compiled(*a)
        n += 1000
    print(f"control_law: {(time.perf_counter() - t0) / n * 1e6:.2f} us per call ({n} calls)", flush=True)


def _run_child(what: str, duration: float, window: float, freq: int, top: int) -> None:
    proc = subprocess.Popen([sys.executable, "-m", "benchmarks.bench_perf", "--child", what, "--duration",
                             str(duration)], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    refcounts = None
    for line in proc.stdout:
        if line.startswith("refcounts"):
            refcounts = tuple(int(v, 16) for v in line.split()[1:3])
        if line.startswith("ready"):
            break
    else:
        sys.exit(f"bench_perf: the {what} child ended before it was ready (exit {proc.wait()})")
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "perf.data"
        record([proc.pid], window, freq, data)
        rest = proc.stdout.read()
        proc.wait()
        cats, syms = parse_script(script(data), refcounts)
    print(rest.strip())
    m = re.search(r"CPU per physics step: ([0-9.]+) us", rest)
    report(cats, syms, {proc.pid: what}, top, float(m.group(1)) if m else None)


def _descendants(pid: int) -> list[int]:
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                kids = [int(c) for c in (task / "children").read_text().split()]
            except OSError:
                continue
            out += kids
            todo += kids
    return out


def _kind(pid: int) -> str:
    """A process's kind from its command line: companion, simulator, ground station, or the
    name of what it runs."""
    try:
        argv = [a.decode(errors="replace") for a in Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0") if a]
    except OSError:
        return "gone"
    text = " ".join(argv)
    for keys, name in ((("companion",), "companion"), (("simulator",), "simulator"),
                       (("ground-station", "ground_station", "recorder", "telemetry"), "ground station")):
        if any(k in text for k in keys):
            return name
    runs = [a for a in argv[1:] if not a.startswith("-")] or argv or ["?"]
    return Path(runs[0]).name


def _run_sitl(duration: float, window: float, freq: int, top: int, attach_after: float) -> None:
    from benchmarks.bench_sitl import am_run_command, base_scenario, scenario_with
    with tempfile.TemporaryDirectory() as tmp:
        path = scenario_with(2, Path(tmp), base_scenario(attitude=True, robust=True), devices=True)
        run = subprocess.Popen(am_run_command(path, duration, Path(tmp) / "run"), stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
        deadline, pids = time.monotonic() + 120.0, []
        while time.monotonic() < deadline and run.poll() is None:  # the simulator and both companions up
            pids = _descendants(run.pid)
            kinds = [_kind(p) for p in pids]
            if kinds.count("companion") == 2 and "simulator" in kinds:
                break
            time.sleep(0.2)
        time.sleep(attach_after)
        pids = _descendants(run.pid)
        if run.poll() is not None or not pids:
            sys.exit("bench_perf: am-run ended before it could be attached to; raise --duration")
        groups = {p: _kind(p) for p in pids}
        data = Path(tmp) / "perf.data"
        record(pids, window, freq, data)
        run.wait()
        cats, syms = parse_script(script(data))
    report(cats, syms, groups, top)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--what", nargs="+", choices=("trial", "law", "sitl"), default=["trial", "law"])
    ap.add_argument("--duration", type=float, default=None,
                    help="simulated seconds (trial: 20, sitl: 12) or wall seconds (law: 8)")
    ap.add_argument("--window", type=float, default=5.0, help="seconds sampled")
    ap.add_argument("--freq", type=int, default=1999, help="samples per second")
    ap.add_argument("--top", type=int, default=12, help="symbols listed per group")
    ap.add_argument("--attach-after", type=float, default=3.0,
                    help="sitl: wall seconds from the companions' start to the sampling's")
    ap.add_argument("--child", choices=("trial", "law"), help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child == "trial":
        return _child_trial(a.duration)
    if a.child == "law":
        return _child_law(a.duration)
    print(f"load average before: {os.getloadavg()[0]:.2f}; {os.cpu_count()} cores; {a.freq} samples/s")
    for what in a.what:
        print(f"\n=== {what}")
        if what == "sitl":
            _run_sitl(a.duration or 12.0, a.window, a.freq, a.top, a.attach_after)
        else:
            _run_child(what, a.duration or {"trial": 20.0, "law": 8.0}[what], a.window, a.freq, a.top)


if __name__ == "__main__":
    main()
