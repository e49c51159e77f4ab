"""How many project modules a reader opens to follow one setpoint: the law's output through the
companion, the link and the simulator, and the sensor frame back, measured rather than read.

    python -m benchmarks.count_modules [--mode torque|attitude|both] [--from S] [--to S] [--all]
                                          [--functions] [--json FILE]

One lockstep run per mode, the multi-process SITL as am-run starts it (the simulator and one
companion process per AM over MAVLink on loopback UDP), with no telemetry and no GCS link, so
that what runs is the setpoint's path: torque mode flies configs/scenarios/two_am_comp.toml,
attitude mode two_am_robust_attitude.toml (SET_ATTITUDE_TARGET to the emulated autopilot, the
sensors as devices, the autopilot's estimator). Each process runs under a tracer
(`sys.settrace`: one call per Python function call, on the main thread, where the frames and
setpoints travel) that keeps the functions called while the run's clock is in the window
[--from, --to) (default [0.5, 1.0) s; the simulator's clock at its lockstep step, a companion's
the frame's time), plus those on the stack when the window opens (the processes' loops). The
first steps, the handshake and the kernels' compile or load come before it and are left out.

Compiled kernels (numba, amcore.jit) run as machine code that no tracer sees: a kernel called
from Python in the window counts with its file and the files of the kernels it calls, found
as amcore.jit finds them for its cache key (the global names in their code, transitively).
For that the child process makes numba's dispatcher call go through a Python function that notes
the kernel; the numbers are the same (the call itself is unchanged).

A project module is a file under amcore/, amlink/, amruntime/, companion/, simulator/, sitl/ or
telemetry/. Files reached only from the loops' bookkeeping are listed apart ("aside", not
counted; `ASIDES`): a companion's error summary (`Pilot.record`) and telemetry step, and the
simulator's state digest and ground truth (`SitlCore.observe`, `SitlCore._truth`: the outcome,
telemetry), the GCS session (`Lockstep._meanwhile`), the companions' HEARTBEATs relayed to the
GCS and the progress display; --all counts them too. The runs end at --to + 0.1 s, too early
for a mission verdict: am-run's "mission failed" (exit 4, e.g. the first steps' saturation on
the devices' estimates counted over 1.1 s) is expected and accepted.

It measures the tree it imports: to measure another checkout, run this file by path with that
tree first on PYTHONPATH (`PYTHONPATH=/other/tree python benchmarks/count_modules.py`).
"""
from __future__ import annotations

import argparse
import inspect
import json
import os
import sys
import tempfile
import threading
from pathlib import Path

PACKAGES = ("amcore", "amlink", "amruntime", "companion", "simulator", "sitl", "telemetry")
# mode: (scenario, with [devices] as the trials fly it: configs/randomize/default.toml's [randomize.devices])
SCENARIOS = {"torque": ("two_am_comp.toml", False), "attitude": ("two_am_robust_attitude.toml", True)}
# (file under the tree, qualified name): where a process's clock is read to open and close the window
MARKERS = {("simulator/lockstep.py", "Lockstep.step"): lambda f: f.f_locals["self"].core.time_s,
           ("companion/pilot.py", "Pilot.command"): lambda f: f.f_locals["frame"].time_s}
# bookkeeping beside the setpoint's path: what these call is "aside" unless the path calls it too
ASIDES = {("companion/pilot.py", "Pilot.record"), ("telemetry/wiring.py", "CompanionTelemetry.step"),
          ("simulator/lockstep.py", "Lockstep._meanwhile"), ("simulator/main.py", "main.<locals>.<lambda>"),
          ("simulator/core.py", "SitlCore.observe"), ("simulator/core.py", "SitlCore._truth"),
          ("simulator/gcs_link.py", "GcsLink.forward_heartbeat")}  # a companion's HEARTBEAT, relayed to the GCS


def tree_root() -> Path:
    """The checkout whose packages this interpreter imports."""
    import amcore
    return Path(amcore.__file__).resolve().parent.parent


def project_file(filename: str, root: Path) -> str | None:
    """`filename` relative to the tree when it is a project module, else None."""
    try:
        rel = Path(filename).resolve().relative_to(root)
    except ValueError:
        return None
    return rel.as_posix() if rel.parts and rel.parts[0] in PACKAGES and rel.suffix == ".py" else None


# ----------------------------------------------------------------------------- in each traced process
class Tracer:
    """The functions a process calls while its clock is in [t_from, t_to), split into the path and
    the asides, with the compiled kernels it calls from Python meanwhile."""

    def __init__(self, root: Path, t_from: float, t_to: float) -> None:
        self.root, self.t_from, self.t_to = root, t_from, t_to
        self.recording = False
        self.done = False
        self.window: list[float] = []
        self.path: set = set()  # code objects
        self.aside: set = set()
        self.kernels_path: dict[int, object] = {}
        self.kernels_aside: dict[int, object] = {}
        self._depth = 0  # open aside frames
        self._kind: dict = {}  # code -> 0 plain, 1 marker, 2 aside
        self._clock: dict = {}
        self._main = threading.get_ident()

    def _classify(self, code) -> int:
        rel = project_file(code.co_filename, self.root)
        key = (rel, code.co_qualname)
        if key in MARKERS:
            self._clock[code] = MARKERS[key]
            return 1
        return 2 if key in ASIDES else 0

    def __call__(self, frame, event, arg):  # sys.settrace's global function: 'call' events only
        code = frame.f_code
        kind = self._kind.get(code)
        if kind is None:
            kind = self._kind[code] = self._classify(code)
        if kind == 1:
            self._tick(frame, self._clock[code](frame))
        if not self.recording:
            return None
        if self._depth or kind == 2:
            self.aside.add(code)
        else:
            self.path.add(code)
        if kind == 2:
            self._depth += 1
            frame.f_trace_lines = False
            return self._aside_frame
        return None

    def _aside_frame(self, frame, event, arg):
        if event == "return":
            self._depth -= 1
        return self._aside_frame

    def _tick(self, frame, t: float) -> None:
        if not self.recording and not self.done and t >= self.t_from:
            self.recording = True
            self.window.append(t)
            f = frame.f_back
            while f is not None:  # the loops that are running when the window opens
                self.path.add(f.f_code)
                f = f.f_back
        elif self.recording and t >= self.t_to:
            self.recording, self.done = False, True
            self.window.append(t)
            sys.settrace(None)

    def kernel_called(self, dispatcher) -> None:
        if self.recording and threading.get_ident() == self._main:
            (self.kernels_aside if self._depth else self.kernels_path)[id(dispatcher)] = dispatcher

    def files(self) -> dict:
        from amcore.jit import source_files

        def of_code(codes) -> set[str]:
            return {f for f in (project_file(c.co_filename, self.root) for c in codes) if f}

        def of_kernels(ds) -> set[str]:
            out = set()
            for d in ds.values():
                for name in [inspect.getfile(d.py_func), *source_files(d.py_func)]:
                    rel = project_file(name, self.root)
                    if rel:
                        out.add(rel)
            return out

        path = of_code(self.path) | of_kernels(self.kernels_path)
        aside = (of_code(self.aside) | of_kernels(self.kernels_aside)) - path
        kernels = sorted({f"{project_file(inspect.getfile(d.py_func), self.root)}:{d.py_func.__name__}"
                          for d in {**self.kernels_path, **self.kernels_aside}.values()})
        functions = sorted({f"{project_file(c.co_filename, self.root)}:{c.co_qualname}" for c in self.path
                            if project_file(c.co_filename, self.root)})
        return {"path": sorted(path), "aside": sorted(aside), "kernels": kernels, "functions": functions,
                "window": self.window}


def _note_kernel_calls(tracer: Tracer) -> None:
    """numba's dispatchers called from Python pass through `tracer` (the call itself unchanged)."""
    from numba._dispatcher import Dispatcher as _CDispatcher
    from numba.core.registry import CPUDispatcher

    call = _CDispatcher.__call__

    def __call__(self, *args, **kwargs):
        tracer.kernel_called(self)
        return call(self, *args, **kwargs)

    CPUDispatcher.__call__ = __call__


def child(role: str, out_dir: str, t_from: float, t_to: float, argv: list[str]) -> int:
    """Run the simulator's or a companion's main under a Tracer; its findings to out_dir."""
    tracer = Tracer(tree_root(), t_from, t_to)
    _note_kernel_calls(tracer)
    if role == "simulator":
        from simulator.main import main
    else:
        from companion.main import main
    sys.settrace(tracer)
    try:
        return main(argv)
    finally:
        sys.settrace(None)
        found = {"role": role, **tracer.files()}
        Path(out_dir, f"{role}-{os.getpid()}.json").write_text(json.dumps(found, indent=1))


# ----------------------------------------------------------------------------- the parent
def _traced_command(out_dir: str, t_from: float, t_to: float):
    """sitl.launch's way of starting a process, with the simulator and the companions traced."""
    from sitl import launch

    plain = launch._command
    me = ["-m", __spec__.name] if __spec__ is not None else [os.path.abspath(__file__)]

    def command(name: str) -> list[str]:
        if name not in ("simulator", "companion"):
            return plain(name)
        return [sys.executable, *me, "--child", name, "--out", out_dir, "--from", str(t_from), "--to", str(t_to),
                "--"]
    return command


def _with_devices(scenario: Path, folder: Path) -> Path:
    """An overlay of `scenario` with the [devices] every trial gets (configs/randomize/default.toml)."""
    import tomllib

    from amcore.toml_write import dumps

    levels = tomllib.loads((scenario.parents[1] / "randomize" / "default.toml").read_text())["randomize"]["devices"]
    out = folder / f"{scenario.stem}_devices.toml"
    out.write_text(dumps({"base": str(scenario), "devices": levels}))
    return out


def measure(mode: str, t_from: float, t_to: float) -> dict:
    """One am-run of `mode`'s scenario, its processes traced: the modules they ran in the window."""
    from sitl import launch

    root = tree_root()
    name, devices = SCENARIOS[mode]
    scenario = root / "configs" / "scenarios" / name
    with tempfile.TemporaryDirectory(prefix="count_modules-") as tmp:
        out_dir = Path(tmp, "found")
        out_dir.mkdir()
        if devices:
            scenario = _with_devices(scenario, Path(tmp))
        plain = launch._command
        launch._command = _traced_command(str(out_dir), t_from, t_to)
        try:
            code = launch.main([str(scenario), "--run-dir", str(Path(tmp, "run")), "--duration", str(t_to + 0.1),
                                "--no-telemetry", "--gcs", "none", "--no-progress"])
        finally:
            launch._command = plain
        found = [json.loads(p.read_text()) for p in sorted(out_dir.glob("*.json"))]
    if code not in (0, 4) or not found:
        raise RuntimeError(f"am-run {scenario.name} ended with exit code {code}")
    for f in found:
        if len(f["window"]) != 2:
            raise RuntimeError(f"the {f['role']}'s clock did not cross [{t_from}, {t_to}) s: {f['window']}")
    path = sorted(set().union(*(f["path"] for f in found)))
    aside = sorted(set().union(*(f["aside"] for f in found)) - set(path))
    kernels = sorted(set().union(*(f["kernels"] for f in found)))
    functions = sorted(set().union(*(f["functions"] for f in found)))
    return {"mode": mode, "scenario": name + (" with the trials' [devices]" if devices else ""), "root": str(root),
            "exit_code": code, "path": path, "aside": aside, "kernels": kernels, "functions": functions,
            "by_process": {f["role"]: sorted(set(f["path"])) for f in found}}


def report(r: dict, include_aside: bool, functions: bool = False) -> str:
    files = sorted(r["path"] + r["aside"]) if include_aside else r["path"]
    lines = [f"{r['mode']} mode ({r['scenario']}, tree {r['root']}): {len(files)} project modules"
             + (" (asides included)" if include_aside else f" on the path, {len(r['aside'])} more aside")]
    sim, comp = set(r["by_process"].get("simulator", [])), set(r["by_process"].get("companion", []))
    for f in files:
        where = "both" if f in sim and f in comp else "simulator" if f in sim else "companion" if f in comp else "aside"
        lines.append(f"  {f:40s} {where}")
        if functions:
            lines += [f"      {q.split(':', 1)[1]}" for q in r["functions"] if q.split(":", 1)[0] == f]
    if r["aside"] and not include_aside:
        lines.append("  aside (bookkeeping only): " + ", ".join(r["aside"]))
    lines.append("  kernels called from Python: " + ", ".join(k.split(":")[1] for k in r["kernels"]))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--child"]:
        sep = argv.index("--")
        ap = argparse.ArgumentParser(prog="count_modules --child")
        ap.add_argument("--child", choices=("simulator", "companion"))
        ap.add_argument("--out")
        ap.add_argument("--from", dest="t_from", type=float)
        ap.add_argument("--to", dest="t_to", type=float)
        a = ap.parse_args(argv[:sep])
        return child(a.child, a.out, a.t_from, a.t_to, argv[sep + 1:])
    ap = argparse.ArgumentParser(prog="python -m benchmarks.count_modules",
                                 description="Count the project modules one setpoint's path runs through.")
    ap.add_argument("--mode", choices=("torque", "attitude", "both"), default="both")
    ap.add_argument("--from", dest="t_from", type=float, default=0.5, help="window start, run time [s] (0.5)")
    ap.add_argument("--to", dest="t_to", type=float, default=1.0, help="window end, run time [s] (1.0)")
    ap.add_argument("--all", action="store_true", help="count the bookkeeping's modules too")
    ap.add_argument("--functions", action="store_true", help="under each module, the functions the path called")
    ap.add_argument("--json", type=Path, default=None, help="also write the findings as JSON")
    a = ap.parse_args(argv)
    if not 0.0 <= a.t_from < a.t_to:
        ap.error("--from must be >= 0 and below --to")
    results = [measure(m, a.t_from, a.t_to) for m in (("torque", "attitude") if a.mode == "both" else (a.mode,))]
    print("\n\n".join(report(r, a.all, a.functions) for r in results))
    if a.json is not None:
        a.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
