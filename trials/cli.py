"""am-trials: a trial campaign of randomized variations of one scenario, each judged by its
mission verdict, on a local process pool or a Dask distributed cluster.

    am-trials SCENARIO --trials N --seed S --out DIR [--workers K] [--scheduler ADDRESS]
              [--randomize FILE] [--controller NAME ...] [--set TABLE.KEY=VALUE ...] [--screening]
              [--realtime [--speed F] [--instance N]]

What varies: --randomize FILE's [randomize] table, else the scenario's own, else
configs/randomize/default.toml (see trials/randomize.py). Trial i of seed S is the same
trial on any executor and in any campaign size. DIR gets trials.csv (a row per trial: every
drawn value, the verdict, its failure class and reason, the key figures, the state digest),
summary.json (success rate, Wilson 95 % interval, counts per failure class), plots/ and
scenarios/trial-NNNN.toml: each trial as a scenario file that `am-run` replays through the
real processes, with its MCAP log. Several --controller options run the same trials with
each law (DIR/<controller>/...) and write DIR/comparison.md. --set changes the base
scenario before the draws (a value in TOML syntax; `am.KEY` sets it on every [[am]]), e.g.
`--set mission.squeeze_sizing=true --set pad.shape='"crowned"'`: a campaign with and without
an option on the same trials; `--set devices.estimator.gyro_cutoff_hz=0` sets a key of a sub-table.
--screening flies every trial in the screening world (`screening_overrides`: fewer solver
sweeps and, in attitude mode, half the physics rate in two substeps): faster, its verdicts
measured against the scenario's own world in docs/trials.md; confirm the ones that matter
without it.
--realtime flies each trial free-running instead, through the processes `am-run --realtime`
starts (trials/freerun.py): one at a time, paced to the wall clock at --speed, its run folder in
DIR/runs/trial-NNNN and its timing (the real-time factor flown, deadline misses, the companions'
periods and latency) in its row; such a trial is not bit-reproducible, its draws are.
Every --controller is checked against the scenario, and the --scheduler address parsed and
connected to, before anything is drawn or written to DIR.
Exit codes: 0 the campaign ran (whatever its success rate), 2 bad arguments or
configuration (a malformed --scheduler address, a --controller the scenario cannot fly), 1 a
trial raised (a bug: failed missions are verdicts, not errors) or the --scheduler did not
answer (a missing peer; nothing is written then), 130 interrupted (SIGINT or SIGTERM).
"""
from __future__ import annotations

import argparse
import contextlib
import copy
import os
import shutil
import signal
import sys
import json
import threading
import time
from pathlib import Path

from amcore import cliargs
from amcore.config import (CONFIGS_DIR, CONTROLLERS, ConfigError, _read_toml, load_scenario, read_scenario,
                           scenario_from_dict)
from amcore.toml_write import dumps

from . import report
from .randomize import RandomizeSpec, draw_trial, load_randomize, randomize_from_table, relocate
from .runner import (SCHEDULER_ADDRESS_FORM, SchedulerUnreachable, TrialTask, bundle_files, executor,
                     parse_scheduler_address, run_all)

DEFAULT_RANDOMIZE = CONFIGS_DIR / "randomize" / "default.toml"
# --screening's PyBullet solver sweeps a step ([scenario].solver_iterations; the default is 50)
SCREENING_SWEEPS = 25


def screening_overrides(spec) -> list[str]:
    """--screening: the --set arguments of the screening world for a scenario (docs/trials.md,
    "Screening campaigns"). PyBullet's solver sweeps at most SCREENING_SWEEPS times a step. Where
    the companions' rate divides half the physics rate (attitude mode's 250 Hz at 1 kHz), the
    world also steps at half its rate in two substeps of PyBullet, so that contacts and joints
    still integrate at the scenario's rate, and the emulated autopilot's loops run at most at the
    new rate; an actuation delay keeps its length in time (half the steps; an odd number of steps
    keeps the rate). Torque mode's companions run at the physics rate, so there the rate stays.
    What the simulator times in seconds ([link] delays, [sensors].latency_s) is rounded to the
    new step, as at any rate."""
    out = [f"scenario.solver_iterations={SCREENING_SWEEPS}"]
    half, c = spec.rate_hz / 2.0, spec.control_rate_hz
    fc = spec.vehicle.flight_controller
    if (spec.physics_substeps == 1 and c is not None and c < spec.rate_hz and (half / c).is_integer()
            and fc.actuation_delay_steps % 2 == 0):
        out += [f"scenario.rate_hz={half!r}", f"flight_controller.rate_hz={min(fc.rate_hz, half)!r}",
                "scenario.physics_substeps=2"]
        if fc.actuation_delay_steps:
            out.append(f"flight_controller.actuation_delay_steps={fc.actuation_delay_steps // 2}")
    return out


def screening_for(scenario: Path, overrides: list[str] = ()) -> list[str]:
    """`screening_overrides` of a scenario file with `overrides` (--set) applied; they go before
    those, which may change what they set. ConfigError as `apply_overrides` and the scenario's."""
    return screening_overrides(scenario_from_dict(apply_overrides(read_scenario(scenario), list(overrides)), scenario))


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {v}")
    return v


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not 0 <= v < 2**32:
        raise argparse.ArgumentTypeError(f"must be in 0..2**32-1, got {v}")
    return v


def _scheduler(text: str) -> str:
    try:
        return parse_scheduler_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}; expected {SCHEDULER_ADDRESS_FORM}") from None


def parse_args(argv):
    ap = cliargs.ArgumentParser(prog="am-trials", description=" ".join(__doc__.split("\n\n")[0].split()),
                                 epilog="Exit codes: 0 the campaign ran (whatever its success rate); 1 a trial "
                                        "raised, a free-running trial's processes failed, or the --scheduler did not "
                                        "answer; 2 bad arguments or configuration; 130 interrupted (SIGINT or "
                                        "SIGTERM).")
    ap.add_argument("scenario", type=Path, help="base scenario TOML")
    ap.add_argument("--trials", type=_positive_int, required=True, help="number of trials")
    ap.add_argument("--seed", type=_seed, required=True, help="campaign seed (0..2**32-1)")
    ap.add_argument("--out", type=Path, required=True, help="output folder (created; must not hold trials.csv)")
    ap.add_argument("--workers", type=_positive_int, default=None,
                    help="local worker processes (default: the machine's cores)")
    ap.add_argument("--scheduler", type=_scheduler, default=None,
                    help="Dask scheduler address (tcp://HOST:8786): run there")
    ap.add_argument("--randomize", type=Path, default=None, help="TOML file with a [randomize] table")
    ap.add_argument("--controller", action="append", default=None,
                    help="control law for every trial ([options].controller); repeat to compare laws")
    ap.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE", dest="overrides",
                    help="change the base scenario before the draws (VALUE in TOML syntax; am.KEY: every [[am]])")
    ap.add_argument("--screening", action="store_true",
                    help="fly the trials in the screening world (fewer solver sweeps; in attitude mode half the "
                         "physics rate in two substeps): faster; --set applies after it")
    ap.add_argument("--realtime", action="store_true",
                    help="fly each trial free-running, as `am-run --realtime` does (each vehicle a PX4 SITL, each "
                         "companion on its own clock), one at a time; its timing in the row (trials/freerun.py)")
    ap.add_argument("--speed", type=cliargs.number(0.0, 10.0, lo_open=True), default=None, metavar="F",
                    help="free-running real-time factor (implies --realtime; default: am-run's, 0.5)")
    ap.add_argument("--instance", type=cliargs.number(0, 200, integer=True), default=0, metavar="N",
                    help="free-running: the vehicles are PX4 SITL instances N, N+1, ... (am-run --instance)")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar (there is one on a terminal only)")
    ap.add_argument("--no-plots", action="store_true", help="no plots")
    return ap.parse_args(argv)


def apply_overrides(base: dict, overrides: list[str]) -> dict:
    """The scenario data with each TABLE.KEY=VALUE of `--set` applied (VALUE parsed as TOML;
    `am.KEY` on every [[am]] entry). Raises ConfigError naming the malformed one."""
    import tomllib

    data = copy.deepcopy(base)
    for text in overrides:
        name, eq, value = text.partition("=")
        table, dot, key = name.strip().partition(".")
        *subs, key = key.split(".")  # TABLE.SUB.KEY: a key of a sub-table ([devices.estimator])
        if not (eq and dot and table and key) or not all(subs) or (subs and table == "am"):
            raise ConfigError(f"--set {text!r}: expected TABLE.KEY=VALUE, e.g. mission.squeeze_sizing=true")
        try:
            v = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"--set {text!r}: VALUE is not a TOML value ({exc}; strings need quotes: "
                              f"pad.shape='\"crowned\"')") from None
        if table == "am":
            for entry in data.get("am", []):
                entry[key] = v
        else:
            t = data.setdefault(table, {})
            for sub in subs:
                if not isinstance(t, dict):
                    break
                t = t.setdefault(sub, {})
            if not isinstance(t, dict):
                raise ConfigError(f"--set {text!r}: [{'.'.join([table, *subs])}] is not a table")
            t[key] = v
    return data


def _randomization(a, base: dict, scenario: Path) -> tuple[RandomizeSpec, str]:
    if a.randomize is not None:
        return load_randomize(a.randomize), str(a.randomize)
    if "randomize" in base:
        return randomize_from_table(base["randomize"], str(scenario)), f"{scenario} [randomize]"
    return load_randomize(DEFAULT_RANDOMIZE), str(DEFAULT_RANDOMIZE)


def with_controller(data: dict, controller: str | None) -> dict:
    """Scenario data with [options].controller set to `controller` (None: the scenario's own);
    `data` is left as it was."""
    if controller is None:
        return data
    return {**data, "options": {**data.get("options", {}), "controller": controller}}


def check_controllers(base: dict, scenario: Path, controllers: list[str]) -> None:
    """Every --controller, before anything is drawn or flown: each named once, a known law
    (amcore.config.CONTROLLERS), and one the scenario can fly (what the scenario's loader checks
    of [options].controller, e.g. that the baseline flies [flight_controller].mode = 'torque'
    only). `base` is the scenario data, already valid. Raises ConfigError naming the first bad one."""
    twice = sorted({c for c in controllers if controllers.count(c) > 1})
    if twice:
        raise ConfigError(f"--controller {twice[0]!r} given twice: each law once")
    for c in controllers:
        if c not in CONTROLLERS:
            raise ConfigError(f"--controller {c!r}: unknown controller (known: {', '.join(CONTROLLERS)})")
        try:
            scenario_from_dict(with_controller(base, c), scenario)
        except ConfigError as exc:
            raise ConfigError(f"--controller {c!r}: {scenario.name} cannot fly it: {exc}") from None


def snapshot_vehicle(base: dict, scenario: Path, folder: Path) -> dict:
    """The base scenario data with its vehicle (TOML and URDF) copied into `folder`/vehicle/:
    a campaign's trials then read their own copy, so that editing the project's vehicle
    files during a campaign, or long after it, changes none of its trials or replays."""
    data = copy.deepcopy(base)
    sc = data.get("scenario", {})
    if "vehicle" not in sc:
        return data
    vpath = (scenario.parent / sc["vehicle"]).resolve()
    vdata = _read_toml(vpath)
    urdf = (vpath.parent / vdata.get("vehicle", {}).get("urdf", "")).resolve()
    dst = folder / "vehicle"
    dst.mkdir(parents=True, exist_ok=True)
    shutil.copy2(vpath, dst / vpath.name)
    if urdf.is_file():
        shutil.copy2(urdf, dst / urdf.name)
    sc["vehicle"] = str((dst / vpath.name).resolve())
    return data


def build_tasks(base: dict, scenario: Path, rand: RandomizeSpec, seed: int, n: int, out: Path,
                controller: str | None) -> list[TrialTask]:
    """Draw every trial, write it as out/scenarios/trial-NNNN.toml (with the vehicle files
    copied beside, `snapshot_vehicle`) and check that it loads."""
    folder = out / "scenarios"
    folder.mkdir(parents=True, exist_ok=True)
    base = snapshot_vehicle(base, scenario, folder)
    tasks = []
    for i in range(n):
        data, params = draw_trial(base, rand, seed, i)
        data = with_controller(data, controller)
        path = (folder / f"trial-{i:04d}.toml").resolve()
        data = relocate(data, scenario, folder)
        path.write_text(f"# trial {i} of am-trials {scenario.name} --seed {seed}\n" + dumps(data))
        scenario_from_dict(data, path)  # a draw that makes an invalid scenario stops here, named
        tasks.append(TrialTask(i, data, str(path), params, bundle_files(data, path)))
    return tasks


def _interrupted_by_sigterm(signum, _frame):
    raise KeyboardInterrupt  # a supervisor's stop ends the campaign as a Ctrl-C does: exit 130


def main(argv: list[str] | None = None) -> int:
    if threading.current_thread() is not threading.main_thread():  # signals go to the main thread only
        return _main(argv)
    previous = signal.signal(signal.SIGTERM, _interrupted_by_sigterm)
    try:
        return _main(argv)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _main(argv: list[str] | None) -> int:
    a = parse_args(argv)
    scenario = a.scenario.resolve()
    if a.speed is not None:
        a.realtime = True
    if a.realtime:  # one trial at a time on this machine's cores, in the scenario's own world
        for flag, given in (("--scheduler", a.scheduler is not None), ("--workers", a.workers not in (None, 1)),
                            ("--screening", a.screening)):
            if given:
                return cliargs.fail("am-trials", f"{flag} is not for --realtime: free-running trials fly one at a "
                                                 f"time, paced to this machine's wall clock, in the scenario's world")
    elif a.instance:
        return cliargs.fail("am-trials", "--instance is for --realtime (the in-process trials open no ports)")
    try:
        load_scenario(scenario)
        if a.screening:  # before the user's --set, which may change what it set
            screening = screening_for(scenario, a.overrides)
            a.overrides = [*screening, *a.overrides]
            print(f"am-trials: screening world: --set {' --set '.join(screening)}", file=sys.stderr)
        base = apply_overrides(read_scenario(scenario), a.overrides)
        if a.overrides:  # an override the scenario cannot take stops here, named
            try:
                scenario_from_dict(base, scenario)
            except ConfigError as exc:
                raise ConfigError(f"--set {' --set '.join(a.overrides)}: the scenario cannot take it: {exc}") from None
        if a.realtime and scenario_from_dict(base, scenario).vehicle.flight_controller.mode != "attitude":
            raise ConfigError(f"{scenario.name}: --realtime flies PX4's attitude setpoints: it needs "
                              f"[flight_controller].mode = \"attitude\" (an *_attitude.toml scenario)")
        rand, rand_source = _randomization(a, base, scenario)
        controllers = a.controller or [None]
        if a.controller:
            check_controllers(base, scenario, a.controller)
    except ConfigError as exc:
        return cliargs.fail("am-trials", str(exc))
    if a.out.exists() and not a.out.is_dir():
        return cliargs.fail("am-trials", f"--out {a.out}: exists and is not a folder")
    outs = {c: a.out / c if len(controllers) > 1 else a.out for c in controllers}
    for out in outs.values():
        if (out / "trials.csv").exists():
            return cliargs.fail("am-trials", f"{out / 'trials.csv'} exists: choose another --out")
    workers = a.workers or os.cpu_count() or 1
    where = f"Dask at {a.scheduler}" if a.scheduler else f"{workers} local worker(s)"
    if a.realtime:
        from sitl.launch import REALTIME_SPEED

        a.speed = a.speed or REALTIME_SPEED
        where = f"free-running at {a.speed:g}x real time, one trial at a time (PX4 SITL instances {a.instance}+)"
    summaries = []
    try:
        with contextlib.ExitStack() as stack:
            # a scheduler is connected to once, before anything is written; a local pool starts
            # and stops with each campaign, inside the wall time the campaign measures
            try:
                dask = stack.enter_context(executor(workers, a.scheduler)) if a.scheduler else None
            except ValueError as exc:  # tls:// without dask's TLS settings
                return cliargs.fail("am-trials", f"--scheduler: {exc}")
            for controller, out in outs.items():
                try:
                    tasks = build_tasks(base, scenario, rand, a.seed, a.trials, out, controller)
                except ConfigError as exc:
                    return cliargs.fail("am-trials", f"a drawn trial is not a valid scenario: {exc}")
                except OSError as exc:
                    return cliargs.fail("am-trials", f"--out {a.out}: {exc}")
                pool = contextlib.nullcontext(dask) if dask is not None else executor(workers)
                summaries.append(_campaign(a, tasks, out, controller, pool, where, rand_source))
    except KeyboardInterrupt:
        print("\nam-trials: interrupted", file=sys.stderr)
        return 130
    except SchedulerUnreachable as exc:
        print(f"am-trials: error: {exc}; nothing was written to {a.out}", file=sys.stderr)
        return 1
    except RuntimeError as exc:
        print(f"am-trials: error: {exc}", file=sys.stderr)
        return 1
    if len(summaries) > 1:
        table = report.comparison_table(summaries)
        (a.out / "comparison.md").write_text(table)
        print(table, file=sys.stderr)
    return 0


def _campaign(a, tasks: list[TrialTask], out: Path, controller: str | None,
              pool: contextlib.AbstractContextManager, where: str, rand_source: str) -> dict:  # fmt: skip
    """Run `tasks` on the executor that `pool` gives (entered and left here: a local pool's start
    and stop count in the campaign's wall time) and write out/'s table, summary and plots."""
    from tqdm import tqdm

    name = controller or "the scenario's controller"
    print(f"am-trials: {len(tasks)} trials of {a.scenario.name} ({name}), seed {a.seed}, on {where}; "
          f"variation from {rand_source}", file=sys.stderr)
    bar = tqdm(total=len(tasks), unit="trial", disable=a.no_progress or not sys.stderr.isatty(), file=sys.stderr,
               dynamic_ncols=True)  # a bar on a terminal only: redirected output gets the summary lines
    counts = {"ok": 0}

    def on_result(row):
        counts["ok"] += row["verdict"] == "success"
        bar.update(1)
        bar.set_postfix_str(f"{counts['ok']}/{bar.n} succeeded")

    t0 = time.perf_counter()
    with open(out / "trials.partial.jsonl", "w") as partial:  # every row as it comes: nothing lost
        def keep(row):
            partial.write(json.dumps(row) + "\n")
            partial.flush()
            on_result(row)

        if a.realtime:
            from . import freerun

            rows = freerun.run_serial(tasks, a.speed, a.instance, out / "runs", keep)
        else:
            with pool as ex:
                rows = run_all(tasks, ex, keep)
    wall = time.perf_counter() - t0
    bar.close()
    errors = [r for r in rows if r["verdict"] == "error"]
    if errors:
        raise RuntimeError(f"{len(errors)} trial(s) raised (rows so far in {out / 'trials.partial.jsonl'}); first: "
                           f"trial {errors[0]['trial']}: {errors[0]['reason']}")
    (out / "trials.partial.jsonl").unlink()
    report.add_derived(rows)
    report.write_csv(rows, out / "trials.csv")
    params = [k for k in rows[0] if k in tasks[0].params and k != "seed"]
    params += [k for k in ("max_abs_misalignment_deg", "max_start_offset_m") if k in rows[0]]
    flown = [r for r in rows if r["verdict"] != "refused"]
    summary = report.summarize(rows, scenario=str(a.scenario), overrides=a.overrides,
                               controller=rows[0]["controller"], seed=a.seed, randomize=rand_source,
                               executor=where, wall_s=wall, trials_per_minute=60.0 * len(rows) / wall,
                               # a refused trial costs the pre-flight check alone: the rate of flights is apart
                               flown_per_minute=60.0 * len(flown) / wall)
    if a.realtime:
        from . import freerun

        summary["timing"] = freerun.timing_summary(rows)
    report.write_summary(summary, out / "summary.json")
    if not a.no_plots:  # success against the draws of the trials that flew (refused ones did not)
        report.plot_parameters(flown, params, out / "plots", f"{a.scenario.stem}, {summary['controller']}, "
                                                              f"seed {a.seed}, {len(flown)} trials flown of {len(rows)}")
    per_min = f"{summary['trials_per_minute']:.1f} trials/min"
    if summary["refused"]:
        per_min += f" ({summary['flown_per_minute']:.1f} flown/min)"
    print(f"am-trials: {report.summary_line(summary)}; {per_min}; in {out}", file=sys.stderr)
    tm = summary.get("timing")
    if tm:
        def ms(v):
            return "-" if v is None else f"{v:.1f} ms"
        print(f"am-trials: free-running timing: real-time factor flown median {tm['real_time_factor_median']:.2f}x "
              f"(lowest {tm['real_time_factor_min']:.2f}x); physics steps late at most "
              f"{100 * (tm['physics_miss_share_max'] or 0):.0f} %; companion period p99 at most "
              f"{ms(tm['companion_period_p99_ms_max'])}, deadline misses at most {tm['companion_deadline_misses_max']}, "
              f"sample to setpoint p99 at most {ms(tm['sample_to_setpoint_p99_ms_max'])}", file=sys.stderr)
    return summary


if __name__ == "__main__":
    sys.exit(main())
