"""Runs a campaign's trials: each in-process (`simulator.inprocess`, bit-identical to the
multi-process SITL), on any `concurrent.futures.Executor`: a local process pool by default,
or a Dask distributed cluster's executor (`dask.distributed.Client(address).get_executor()`),
whose workers need this project installed. Results do not depend on the executor: a trial
is a pure function of its scenario data.
"""
from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class TrialTask:
    """One trial: its index, its scenario data (TOML tables) and the file it was written to
    (relative paths in the data are taken from that file's folder), and the drawn values."""

    index: int
    data: dict
    path: str
    params: dict


def run_trial(task: TrialTask) -> dict:
    """Run one trial in-process; its table row: the drawn values, the verdict and the key
    figures. A trial outside the team's envelope ([mission].envelope_check, amcore.preflight)
    does not fly: its verdict is "refused", with the check's sentence as the reason, as
    `am-run` of its file refuses it. Runs in a worker process (imports inside: a Dask worker
    or a spawned pool process starts with none of this loaded)."""
    from amcore.config import scenario_from_dict
    from amcore.preflight import refusal
    from simulator.inprocess import run
    from simulator.verdict import summary_figures

    spec = scenario_from_dict(task.data, Path(task.path))
    t0 = time.perf_counter()
    why = refusal(spec)
    if why is not None:
        return {"trial": task.index, "scenario_file": task.path,
                "controller": getattr(spec.vehicle.options, "controller", "passivity"), **task.params,
                "verdict": "refused", "failure_class": "", "reason": why, "wall_s": time.perf_counter() - t0}
    result = run(spec)
    wall = time.perf_counter() - t0
    v = result["verdict"]
    share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
    peaks = _peak_errors(result["companions"])
    return {"trial": task.index, "scenario_file": task.path, "controller": getattr(spec.vehicle.options, "controller", "passivity"),
            **task.params, "verdict": v["status"], "failure_class": v["failure_class"] or "",
            "reason": v["text"], **summary_figures(result, share), **peaks,
            "rejected_setpoints": result["rejected_setpoints"], "state_digest": result["state_digest"],
            "wall_s": wall}


def _peak_errors(companions: dict) -> dict:
    """Largest CoM error [m], attitude error [rad] and task x error [m] of any AM from the
    grasp on (the approach's start offsets would dominate otherwise)."""
    com = att = yx = 0.0
    for c in companions.values():
        for phase in ("grasp", "hover"):
            mx = c["phases"][phase]["max"]
            if mx:
                com, att = max(com, mx["r_c_err"]), max(att, mx["e_R"])
                yx = max(yx, mx["y_err"][0])
    return {"peak_com_err_m": com, "peak_e_R_rad": att, "peak_y_err_x_m": yx}


@contextlib.contextmanager
def executor(workers: int, scheduler: str | None = None) -> Iterator[cf.Executor]:
    """A local process pool of `workers` processes, or, given a scheduler address
    ("tcp://host:8786"), that Dask cluster's executor."""
    if scheduler is None:
        # spawn: each worker starts clean (no PyBullet client or pinocchio state inherited)
        with cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as ex:
            yield ex
        return
    try:
        from dask.distributed import Client
    except ImportError as exc:  # pragma: no cover - a dependency of the project
        raise RuntimeError(f"--scheduler needs dask.distributed ({exc})") from None
    with Client(scheduler, timeout=30) as client:
        ex = client.get_executor()
        try:
            yield ex
        finally:
            ex.shutdown(wait=False)


def run_all(tasks: list[TrialTask], ex: cf.Executor,
            on_result: Callable[[dict], None] = lambda _row: None) -> list[dict]:  # fmt: skip
    """Every task on `ex`; rows in trial order. `on_result(row)` as each finishes (progress,
    saving). A trial that raises (a bug, not a failed mission: failed missions are verdicts)
    gets a row with verdict "error" and the exception; the others run on."""
    futures = {ex.submit(run_trial, t): t for t in tasks}
    rows = []
    for f in cf.as_completed(futures):
        t = futures[f]
        try:
            row = f.result()
        except Exception as exc:  # noqa: BLE001 - recorded, and the campaign goes on
            row = {"trial": t.index, "scenario_file": t.path, **t.params, "verdict": "error",
                   "failure_class": "", "reason": f"{type(exc).__name__}: {exc}"}
        rows.append(row)
        on_result(row)
    return sorted(rows, key=lambda r: r["trial"])
