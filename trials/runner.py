"""Runs a campaign's trials: each in-process (`sitl.inprocess`, bit-identical to the
multi-process SITL), on any `concurrent.futures.Executor`: a local process pool by default,
or a Dask distributed cluster's executor (`dask.distributed.Client(address).get_executor()`),
whose workers need this project installed and nothing else: each trial carries its scenario
data and the vehicle files it names (`TrialTask.files`), so no filesystem is shared. A link
key file (`[link] key_file`) is a secret and does not travel: a scenario that names one is
read where it is. Results do not depend on the executor: a trial is a pure function of its
scenario data.

A scheduler's address is checked before anything connects (`parse_scheduler_address`), and one
that does not answer within SCHEDULER_CONNECT_TIMEOUT_S raises `SchedulerUnreachable` naming it.
"""
from __future__ import annotations

import concurrent.futures as cf
import contextlib
import multiprocessing
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

# how long `executor` waits for a Dask scheduler to answer before it gives up [s]
SCHEDULER_CONNECT_TIMEOUT_S = 30.0
SCHEDULER_ADDRESS_FORM = "tcp://HOST:PORT (or tls:// with dask's TLS settings), e.g. tcp://sched.lab:8786"


class SchedulerUnreachable(RuntimeError):
    """No Dask scheduler answered at the address within the connect timeout (refused, no
    route, a name that does not resolve, or nothing listening): a missing peer, not a bad
    argument. Carries the address, the timeout [s] and the reason when the OS gave one."""

    def __init__(self, address: str, timeout_s: float, reason: str | None) -> None:
        self.address, self.timeout_s, self.reason = address, timeout_s, reason
        why = f" ({reason})" if reason else ""
        super().__init__(f"--scheduler {address}: no Dask scheduler reached within {timeout_s:g} s{why}")


def parse_scheduler_address(text: str) -> str:
    """A Dask scheduler's address, "tcp://HOST:PORT", "tls://HOST:PORT" or "HOST:PORT" (tcp,
    dask's default scheme), as "SCHEME://HOST:PORT" (an IPv6 HOST in brackets, "tcp://[::1]:8786"):
    split as `distributed.comm.addressing.parse_address` and `parse_host_port` split it, but
    checked before anything connects. tls takes its certificates from dask's configuration
    (distributed.comm.tls.*). Raises ValueError saying what is wrong: another scheme (inproc is
    one process's own; ws and ucx are not set up here), no HOST, no PORT, or a PORT that is not
    a whole number 1-65535."""
    scheme, sep, loc = text.strip().rpartition("://")
    if not sep:
        scheme = "tcp"
    if scheme not in ("tcp", "tls"):
        raise ValueError(f"scheme {scheme!r}: am-trials reaches a scheduler over tcp:// or tls:// only")
    if loc.startswith("["):  # IPv6: [addr]:port
        host, closed, tail = loc[1:].partition("]")
        if not closed or (tail and not tail.startswith(":")):
            raise ValueError("an IPv6 HOST goes in brackets before the port: tcp://[::1]:8786")
        port, shown = tail[1:], f"[{host}]"
    else:
        host, colon, port = loc.rpartition(":")
        if not colon:
            host, port = port, ""
        elif ":" in host:
            raise ValueError("an IPv6 HOST needs brackets: tcp://[::1]:8786")
        shown = host
    if not host:
        raise ValueError("no HOST")
    if not port:
        raise ValueError("no PORT")
    if not (port.isascii() and port.isdigit()):
        raise ValueError(f"PORT {port!r} is not a whole number")
    if not 1 <= int(port) <= 65535:
        raise ValueError(f"PORT must be 1-65535, got {int(port)}")
    return f"{scheme}://{shown}:{int(port)}"


def _os_reason(exc: BaseException) -> str | None:
    """The operating system's words for why a connection failed ("Connection refused"), from
    the first exception in `exc`'s chain that carries them; None if none does (a timeout)."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.strerror:
            return exc.strerror
        exc = exc.__cause__ or exc.__context__
    return None


@dataclass(frozen=True)
class TrialTask:
    """One trial: its index, its scenario data (TOML tables) and the file it was written to
    (relative paths in the data are taken from that file's folder), the drawn values, and the
    files the data names ({path relative to the trial's folder: contents}: the vehicle TOML and
    its URDF, `bundle_files`). A worker that cannot read `path`'s folder (a Dask worker on
    another machine) flies the trial from a temporary folder holding `files`."""

    index: int
    data: dict
    path: str
    params: dict
    files: tuple[tuple[str, bytes], ...] = ()


def bundle_files(data: dict, path: Path) -> tuple[tuple[str, bytes], ...]:
    """The files scenario `data` (written at `path`) needs to load: its vehicle TOML and the URDF
    that one names, each keyed by its path relative to `path`'s folder. A vehicle outside that
    folder (a path with ..) is not bundled: the worker reads it where it is."""
    import tomllib

    folder = Path(path).resolve().parent
    rel = data.get("scenario", {}).get("vehicle")
    if not rel or Path(rel).is_absolute() or ".." in Path(rel).parts:
        return ()
    vpath = folder / rel
    out = [(Path(rel).as_posix(), vpath.read_bytes())]
    urdf = tomllib.loads(out[0][1].decode()).get("vehicle", {}).get("urdf")
    if urdf and not Path(urdf).is_absolute():
        upath = (vpath.parent / urdf).resolve()
        if upath.is_file() and upath.is_relative_to(folder):
            out.append((upath.relative_to(folder).as_posix(), upath.read_bytes()))
    return tuple(out)


@contextlib.contextmanager
def trial_folder(task: TrialTask) -> Iterator[Path]:
    """The path to load `task` from: its own file when every file it bundles is there, else the
    same name in a temporary folder that holds the bundled files (removed afterwards)."""
    import tempfile

    own = Path(task.path)
    if not task.files or all((own.parent / rel).is_file() for rel, _ in task.files):
        yield own
        return
    with tempfile.TemporaryDirectory(prefix="amtrial-") as tmp:
        for rel, blob in task.files:
            dst = Path(tmp) / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            dst.write_bytes(blob)
        yield Path(tmp) / own.name


def run_trial(task: TrialTask) -> dict:
    """Run one trial in-process; its table row: the drawn values, the verdict and the key
    figures. A trial outside the team's envelope ([mission].envelope_check, amcore.preflight)
    does not fly: its verdict is "refused", with the check's sentence as the reason, as
    `am-run` of its file refuses it. Runs in a worker process (imports inside: a Dask worker
    or a spawned pool process starts with none of this loaded)."""
    from amcore.config import scenario_from_dict
    from amcore.preflight import refusal
    from sitl.inprocess import run
    from simulator.verdict import summary_figures

    with trial_folder(task) as where:
        return _run_trial(task, scenario_from_dict(task.data, where), refusal, run, summary_figures)


def _run_trial(task: TrialTask, spec, refusal, run, summary_figures) -> dict:
    t0 = time.perf_counter()
    why = refusal(spec)
    if why is not None:
        return {**row_head(task, spec), "verdict": "refused", "failure_class": "", "reason": why,
                "wall_s": time.perf_counter() - t0}
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


def row_head(task: TrialTask, spec) -> dict:
    """The first columns of a trial's row: its index, file, control law and drawn values."""
    return {"trial": task.index, "scenario_file": task.path,
            "controller": getattr(spec.vehicle.options, "controller", "passivity"), **task.params}


def error_row(task: TrialTask, exc: BaseException) -> dict:
    """The row of a trial that raised (a bug, not a failed mission): verdict "error"."""
    return {"trial": task.index, "scenario_file": task.path, **task.params, "verdict": "error",
            "failure_class": "", "reason": f"{type(exc).__name__}: {exc}"}


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
def executor(workers: int, scheduler: str | None = None,
             connect_timeout_s: float | None = None) -> Iterator[cf.Executor]:  # fmt: skip
    """A local process pool of `workers` processes, or, given a scheduler address
    ("tcp://host:8786", `parse_scheduler_address`), that Dask cluster's executor. The scheduler
    is connected to on entry: ValueError if its address is malformed, `SchedulerUnreachable` if
    it does not answer within `connect_timeout_s` (default SCHEDULER_CONNECT_TIMEOUT_S)."""
    if scheduler is None:
        # spawn: each worker starts clean (no PyBullet client or pinocchio state inherited)
        ex = cf.ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
        try:
            yield ex
        except BaseException:
            # interrupted (KeyboardInterrupt, am-trials' SIGTERM) or failed: the queued trials are
            # dropped and the running ones stopped, not waited for (a trial is a pure function
            # of its data: nothing of it is lost that a rerun would not give again)
            workers_running = list((ex._processes or {}).values())  # the pool's own processes
            ex.shutdown(wait=False, cancel_futures=True)
            for proc in workers_running:
                proc.terminate()
            for proc in workers_running:
                proc.join(5.0)
            raise
        ex.shutdown(wait=True)
        return
    try:
        address = parse_scheduler_address(scheduler)
    except ValueError as exc:
        raise ValueError(f"scheduler address {scheduler!r}: {exc} (expected {SCHEDULER_ADDRESS_FORM})") from None
    timeout_s = SCHEDULER_CONNECT_TIMEOUT_S if connect_timeout_s is None else connect_timeout_s
    try:
        from dask.distributed import Client
    except ImportError as exc:  # pragma: no cover - a dependency of the project
        raise RuntimeError(f"--scheduler needs dask.distributed ({exc})") from None
    try:
        # dask retries a refused or unresolved connection until the timeout, then raises
        # OSError("Timed out trying to connect ..."), the cause of the last attempt chained
        client = Client(address, timeout=timeout_s)
    except OSError as exc:
        raise SchedulerUnreachable(address, timeout_s, _os_reason(exc)) from None
    except TypeError as exc:  # tls:// without dask's TLS settings (no SSL context)
        raise ValueError(f"scheduler address {address!r}: {exc}") from None
    with client:
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
            row = error_row(t, exc)
        rows.append(row)
        on_result(row)
    return sorted(rows, key=lambda r: r["trial"])
