"""Free-running trials: each trial's scenario file flown by `am-run --realtime` (the simulator
paced to the wall clock, each vehicle a PX4 SITL port, each companion on its own clock over
standard MAVLink, Dynamixel and Net F/T), one after another, and judged by the verdict in its
outcome.json, as `am-run` judges it.

A free-running trial is not a pure function of its data: its timing is the machine's. So the
row also carries what the run measured of time: the real-time factor flown, the physics loop's
deadline misses, and each companion's period (p99, worst), deadline misses and latency from
sample to setpoint (p99), the worst AM's. Trials fly one at a time: each wants the machine's
cores for its processes (docs/freerun.md, "Where it stands").

What a row says, from `am-run`'s exit code (`exit_code`) and outcome.json: the verdict in
outcome.json when the mission failed, whatever the code (a companion that handed its vehicle
back to PX4 exits 1 and the verdict names the failover); any other verdict when the code is 0
or 4. Verdict "error", with the last lines of the trial's output as the reason: no verdict (the
world never came up, code 2 for a check the campaign did not make), another verdict with a
process that failed (a success; a run cut short because a process did not start), or a trial
past its time limit. A campaign with an error
row exits 1, as one whose trial raised.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from .runner import error_row, row_head

# am-run --realtime's boot-time start of the mission [s] (its --mission-start default)
MISSION_START_S = 10.0
# a trial's wall-time limit: this many times its simulated time at --speed, plus start-up [s]
TIMEOUT_FACTOR, TIMEOUT_EXTRA_S = 3.0, 180.0


def command(path: str, run_dir: Path, speed: float, instance: int) -> list[str]:
    """The `am-run` command line of one free-running trial (no telemetry, no GCS ports: a
    campaign's trials report through their outcome.json)."""
    return [sys.executable, "-m", "sitl.launch", path, "--realtime", "--speed", repr(speed),
            "--instance", str(instance), "--run-dir", str(run_dir), "--no-progress", "--no-telemetry",
            "--gcs", "none"]


def run_trial(task, speed: float, instance: int, runs: Path) -> dict:
    """Fly one trial free-running (module doc); its table row."""
    from amcore.config import scenario_from_dict
    from amcore.preflight import refusal

    spec = scenario_from_dict(task.data, Path(task.path))
    head = row_head(task, spec)
    t0 = time.perf_counter()
    why = refusal(spec)
    if why is not None:
        return {**head, "verdict": "refused", "failure_class": "", "reason": why, "wall_s": time.perf_counter() - t0}
    run_dir = runs / f"trial-{task.index:04d}"
    timeout = TIMEOUT_FACTOR * (MISSION_START_S + spec.duration_s) / speed + TIMEOUT_EXTRA_S
    out = run_dir.parent / f"trial-{task.index:04d}.log"
    run_dir.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w") as logf:
        proc = subprocess.Popen(command(task.path, run_dir, speed, instance), stdout=logf, stderr=subprocess.STDOUT,
                                start_new_session=True)  # a stop of the campaign stops the trial's processes
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _stop(proc)
            rc = None
        except BaseException:  # interrupted: the trial's stack goes down with the campaign
            _stop(proc)
            raise
    row = judged(head, rc, run_dir, out, spec, timeout)
    row["wall_s"] = time.perf_counter() - t0
    return row


def judged(head: dict, rc: int | None, run_dir: Path, log: Path, spec, timeout_s: float) -> dict:
    """A flown trial's row from `am-run`'s exit code `rc` (None: past its time limit) and its run
    folder (module doc: which verdict a row gets)."""
    from simulator.verdict import summary_figures

    outcome = run_dir / "outcome.json"
    o = json.loads(outcome.read_text()) if outcome.is_file() else {}
    v = o.get("verdict")
    # a failed flight is a verdict, whatever the processes did (a companion that handed its vehicle
    # back exits 1); no verdict, or any other verdict with a process that failed (a success, or a
    # run that ended before its mission did because the stack did not start), is an error of the stack
    if v is None or rc is None or (rc not in (0, 4) and v["status"] != "failed"):
        lines = log.read_text(errors="replace").strip().splitlines() if log.is_file() else []
        what = f"timed out after {timeout_s:.0f} s" if rc is None else f"am-run exited {rc}"
        return {**head, "verdict": "error", "failure_class": "", "reason": f"{what}: {' / '.join(lines[-3:])} "
                f"(log {log})", "exit_code": rc}
    share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
    return {**head, "verdict": v["status"], "failure_class": v["failure_class"] or "", "reason": v["text"],
            **summary_figures(o, share), **timing_figures(o, run_dir, [am.sysid for am in spec.ams]),
            "exit_code": rc, "run_dir": str(run_dir)}


def timing_figures(outcome: dict, run_dir: Path, sysids: list[int]) -> dict:
    """What a free-running run measured of time, for its row: the real-time factor flown, the
    share of physics steps that missed their deadline, and the worst companion's period (p99,
    max), deadline misses and sample-to-setpoint latency (p99) [ms]."""
    t = outcome.get("timing") or {}
    steps = t.get("steps") or 0
    row = {"real_time_factor": outcome.get("real_time_factor"),
           "physics_miss_share": t.get("deadline_misses", 0) / steps if steps else None}
    loops = []
    for s in sysids:
        p = run_dir / f"am{s}.json"
        loop = json.loads(p.read_text()).get("loop") if p.is_file() else None
        if loop:
            loops.append(loop)

    row.update({
        "companion_period_p99_ms": _largest(lp.get("period_ms", {}).get("p99") for lp in loops),
        "companion_period_max_ms": _largest(lp.get("period_ms", {}).get("max") for lp in loops),
        "companion_deadline_misses": _largest(lp.get("deadline_misses") for lp in loops),
        "sample_to_setpoint_p99_ms": _largest(lp.get("sample_to_setpoint_ms", {}).get("p99") for lp in loops),
    })
    return row


def _largest(values):
    """The largest of `values` that is not None; None if there is none."""
    vals = [v for v in values if v is not None]
    return max(vals) if vals else None


def timing_summary(rows: list[dict]) -> dict:
    """The campaign's timing over its flown trials: the median and the lowest real-time factor
    flown, the largest physics miss share, and the worst companion figures."""
    flown = [r for r in rows if r.get("real_time_factor") is not None]
    if not flown:
        return {}
    rtf = sorted(r["real_time_factor"] for r in flown)

    def worst(k):
        return _largest(r.get(k) for r in flown)

    return {"real_time_factor_median": rtf[len(rtf) // 2], "real_time_factor_min": rtf[0],
            "physics_miss_share_max": worst("physics_miss_share"),
            "companion_period_p99_ms_max": worst("companion_period_p99_ms"),
            "companion_deadline_misses_max": worst("companion_deadline_misses"),
            "sample_to_setpoint_p99_ms_max": worst("sample_to_setpoint_p99_ms")}


def run_serial(tasks, speed: float, instance: int, runs: Path, on_result=lambda _row: None) -> list[dict]:
    """Every task, one after another, in trial order (module doc); `on_result(row)` as each ends.
    A trial whose flight raised gets an "error" row, and the others fly on."""
    rows = []
    for t in tasks:
        try:
            row = run_trial(t, speed, instance, runs)
        except Exception as exc:  # noqa: BLE001 - recorded, and the campaign goes on
            row = error_row(t, exc)
        rows.append(row)
        on_result(row)
    return rows


def _stop(proc: subprocess.Popen) -> None:
    """End a trial's am-run as its own interrupt does (SIGINT to its session: it stops its
    stack and writes its outcome), then harder if it does not within its grace."""
    for sig, wait_s in ((signal.SIGINT, 30.0), (signal.SIGTERM, 10.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            return
        try:
            proc.wait(timeout=wait_s)
            return
        except subprocess.TimeoutExpired:
            continue
