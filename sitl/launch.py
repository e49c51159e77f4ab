"""Run a whole scenario: the simulator and one companion process per AM, wired over
MAVLink/UDP on loopback, with a progress bar and a run folder holding the outcome.

    am-run [configs/scenarios/two_am_comp_attitude.toml] [--run-dir runs/NAME] [--duration S]
           [--gcs udpout:127.0.0.1:14551] [--gcs-key-file FILE] [--tlog-companions] [--list]

The run folder gets manifest.json (the scenario, the command line, the version and commit,
the host and the start time), scenario.toml with vehicle/ (the scenario as flown: `am-run
RUN/scenario.toml` flies it again), outcome.json (simulator ground truth), am<sysid>.json (each
companion's controller errors per phase), run.mcap (the telemetry log) and plots/ (its review),
gcs.tlog (the flight controllers' GCS link, for stock MAVLink tools), every process's log, and
keys/ (mode 0700): link.key, gcs.key (the GCS signing passphrase, new every run unless
--gcs-key-file gives one to keep) and telemetry*.key (the recorder keeps only what the run's
simulator and companions sealed, telemetry.auth). Exit code:
0 when every process ended cleanly and the mission succeeded (simulator.verdict), 4 when
the mission failed, 2 bad configuration (found by am-run, or by the simulator: then its own
message is printed), 1 when a process failed, 130 when am-run was
interrupted (SIGINT, as Ctrl-C sends it, or SIGTERM). An interrupt reaches the simulator
whether the terminal sent it to every process or it went to am-run alone: the simulator
ends the run as it does on its own interrupt (its outcome.json says so, the companions are
told and the recorder finishes the log), and am-run waits for every process to end.
"""
from __future__ import annotations

import datetime
import json
import multiprocessing
import os
import select
import shutil
import socket
import signal
import subprocess
import sys
import time
from pathlib import Path

from amcore import cliargs, preflight
from amcore.config import DEFAULT_SCENARIO, ConfigError, check_duration, load_scenario
from amlink.endpoint import DEFAULT_GCS, EndpointError, parse_endpoint
from amlink.signing import SigningKeyError, read_gcs_key_file
from telemetry.keyfiles import write_run_keys, write_secret
from simulator import runfolder
from simulator.progress import SimBar
from simulator.verdict import MISSION_FAILED, criteria_rows, format_criteria

INTERRUPTED = 130  # exit code, as every process of the stack exits when interrupted
REALTIME_TELEMETRY_HZ = 50.0  # --realtime: each companion publishes its controller's state at this rate
# --realtime: the real-time factor two AMs hold on this project's two-core machines (docs/freerun.md),
# and the autopilots' boot time of the mission's start: the companions' start-up (~2-4 s), the offboard
# handshake (>= 1 s of setpoints, TIMESYNC, the engage's HEARTBEAT) and TAKEOFF_S come before it
REALTIME_SPEED = 0.5
MISSION_START_S = 10.0


class _Interrupted(Exception):
    """am-run got SIGINT or SIGTERM while the run was under way; the argument is the signal's name."""


class _Signals:
    """SIGINT and SIGTERM while the run is under way raise _Interrupted; once its shutdown has
    begun they are only noted (`late`), so that the shutdown and the summary run to their end."""

    def __init__(self) -> None:
        self.armed, self.late = False, None
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._on_signal)

    def _on_signal(self, signum, _frame) -> None:
        name = signal.Signals(signum).name
        if self.armed:
            self.armed = False
            raise _Interrupted(name)
        self.late = self.late or name


# how long an interrupted am-run lets the simulator end by itself before passing the signal on:
# a terminal's Ctrl-C reaches every process of the group at once, and the simulator stops
# within a lockstep step; a signal sent to am-run alone never reaches it
INTERRUPT_PASS_ON_S = 2.0


def _pass_on(procs: dict[str, subprocess.Popen], name: str) -> None:
    """End the run after am-run was interrupted: the simulator gets the same signal unless it
    ends by itself within INTERRUPT_PASS_ON_S (it then tells the companions and the recorder,
    as at any end of a run); before the simulator runs, every process started gets it."""
    signum = signal.Signals[name]
    sim = procs.get("simulator")
    targets = [sim] if sim is not None else list(procs.values())
    for p in targets:
        try:
            p.wait(timeout=INTERRUPT_PASS_ON_S if p is sim else 0.0)
        except subprocess.TimeoutExpired:
            p.send_signal(signum)


def _shipped(scenario: Path) -> Path:
    """A scenario named without a path (`am-run two_am_short`) is the shipped one of that name
    when no such file is here; any other path is taken as it is."""
    named = runfolder.SCENARIOS_DIR / f"{scenario.name}.toml"
    if not scenario.exists() and scenario.parent == Path(".") and scenario.suffix == "" and named.is_file():
        return named
    return scenario


def _command(name: str) -> list[str]:
    """The console script next to this interpreter, else `python -m <package>`."""
    exe = shutil.which(name, path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", name]


def _warm_kernels(spec, scenario: Path) -> None:
    """Compile the control law (amcore.law) before any companion starts, so that they load
    it from the cache instead of compiling side by side (amruntime.jitcache). On a machine
    that has not compiled it yet (the first run), also the simulator's kernels, before the
    simulator starts: a child process compiles them under their own lock while this one
    compiles the law, on the other core (`jitcache.warm_groups`); should the child fail, this
    process compiles them after the law."""
    from amruntime import jitcache
    from companion.pilot import Pilot

    groups = [jitcache.law_group(Pilot(spec, spec.ams[0].sysid).warm_up)]
    child = None
    if not jitcache.looks_cached():
        from simulator.core import kernel_group
        print("am-run: compiling the control law and the simulator's kernels (once per machine; later runs "
              "load them from the cache)", file=sys.stderr, flush=True)
        groups.append(kernel_group(spec))
        child = multiprocessing.get_context("spawn").Process(target=_warm_simulator_kernels, args=(str(scenario),),
                                                              daemon=True)
        child.start()
    report = jitcache.warm_groups(groups)
    if child is not None:
        child.join()
        if child.exitcode != 0:
            print(f"am-run: warning: compiling the simulator's kernels in a second process failed (exit "
                  f"{child.exitcode}); this process warmed them instead", file=sys.stderr, flush=True)
    if report.compiled:
        print(f"am-run: compiled the kernels in {report.seconds:.1f} s", file=sys.stderr, flush=True)


def _warm_simulator_kernels(scenario: str) -> None:
    """The simulator's kernels compiled (or loaded) under their lock: `_warm_kernels`'s child."""
    from amruntime import jitcache
    from simulator.core import kernel_group
    jitcache.warm_groups([kernel_group(load_scenario(scenario))])


def main(argv: list[str] | None = None) -> int:
    ap = cliargs.ArgumentParser(prog="am-run", description=" ".join(__doc__.split("\n\n")[0].split()),
                                epilog=cliargs.exit_codes(0, 1, 2, 4, 130, c1="a process failed or did not start"))
    ap.add_argument("--list", action="store_true", help="list the shipped scenarios and exit")
    ap.add_argument("scenario", nargs="?", type=Path, default=DEFAULT_SCENARIO,
                    help="scenario TOML, or the name of a shipped one (am-run --list)")
    ap.add_argument("--run-dir", type=cliargs.output_dir, default=None, help="run folder (default runs/<name>-<time>)")
    ap.add_argument("--duration", type=cliargs.seconds, default=None, help="override the scenario's duration [s]")
    ap.add_argument("--no-progress", action="store_true", help="no progress display (there is one on a terminal only)")
    ap.add_argument("--no-telemetry", action="store_true", help="no Zenoh telemetry, no MCAP log, no review")
    ap.add_argument("--startup-timeout", type=cliargs.seconds, default=120.0, help="seconds for all processes to connect")
    ap.add_argument("--gcs", default=None, metavar="ENDPOINT",
                    help=f"the simulator's GCS link (default {DEFAULT_GCS}; mavutil's forms; 'none' for none); "
                         f"free-running: PX4 SITL's GCS instances (from 18570+i to 127.0.0.1:14550), or "
                         f"udpout:HOST:PORT, or none")
    ap.add_argument("--gcs-unsigned", action="store_true",
                    help="free-running: the GCS instances' signing off, for tools without MAVLink signing (MAVSDK)")
    ap.add_argument("--gcs-key-file", type=Path, default=None, metavar="FILE",
                    help="the GCS signing passphrase (one line; keep it mode 0600), the same for every run, so a "
                         "GCS set up once keeps working; default: a new random one per run, keys/gcs.key in the run folder")
    ap.add_argument("--realtime", action="store_true",
                    help="free-running: the simulator paced to the wall clock, each vehicle a PX4 SITL on its onboard "
                         "port, each companion on its own clock (--clock wall) over standard MAVLink, Dynamixel "
                         "and Net F/T (docs/freerun.md)")
    ap.add_argument("--speed", type=cliargs.number(0.0, lo_open=True), default=None, metavar="F",
                    help=f"free-running real-time factor (implies --realtime; default {REALTIME_SPEED:g}: what two "
                         f"AMs hold on two cores, docs/freerun.md)")
    ap.add_argument("--mission-start", type=cliargs.seconds, default=None, metavar="S",
                    help=f"free-running: the autopilots' boot time [s] at which every companion's mission starts "
                         f"(default {MISSION_START_S:g} s: start-up, handshake and take-off before it)")
    ap.add_argument("--instance", type=cliargs.number(0, 1000, integer=True), default=0, metavar="N",
                    help="free-running: the vehicles are PX4 SITL instances N, N+1, ... (their ports shifted by N), "
                         "so that two runs share a machine")
    ap.add_argument("--tlog-companions", action="store_true",
                    help="each companion also writes its link to companion-<sysid>.tlog (1 kHz: large)")
    a = ap.parse_args(argv)
    if a.list:
        try:
            print(runfolder.format_scenarios(runfolder.list_scenarios()))
        except ConfigError as exc:
            return cliargs.fail("am-run", str(exc))
        print(f"(the default: {DEFAULT_SCENARIO.stem}; run one with: am-run NAME, its file is {DEFAULT_SCENARIO.parent}/NAME.toml)")
        return 0
    a.scenario = _shipped(a.scenario)
    if a.speed is not None or a.mission_start is not None:
        a.realtime = True
    if a.gcs_unsigned and not a.realtime:
        return cliargs.fail("am-run", "--gcs-unsigned is for --realtime (the lockstep's GCS link follows the "
                                      "scenario's [link] signing)")
    gcs_given = a.gcs is not None
    a.gcs = a.gcs if gcs_given else DEFAULT_GCS
    try:
        if a.gcs.strip().lower() != "none":
            parse_endpoint(a.gcs)
    except EndpointError as exc:
        print(f"am-run: error: --gcs: {exc} (or none)", file=sys.stderr)
        return 2
    try:
        spec = load_scenario(a.scenario)
        if a.duration is not None:
            check_duration(spec, a.duration, "--duration")
        check_memory(spec)
        preflight.check(spec)  # [mission].envelope_check: refuse what the team cannot hold, before anything starts
        if a.gcs_key_file is not None:
            if not spec.link.signing:
                raise ConfigError(f"--gcs-key-file {a.gcs_key_file}: the scenario turns signing off ([link] signing "
                                  f"= false), so the GCS link is unsigned and takes no key")
            read_gcs_key_file(a.gcs_key_file)  # readable, and a passphrase MAVProxy takes
            if a.gcs_key_file.stat().st_mode & 0o077:
                print(f"am-run: warning: --gcs-key-file {a.gcs_key_file}: others may read it (chmod 600 it)",
                      file=sys.stderr)
    except (ConfigError, SigningKeyError) as exc:
        return cliargs.fail("am-run", str(exc))
    started = datetime.datetime.now(datetime.timezone.utc)
    run_dir = (a.run_dir or Path("runs") / f"{spec.name}-{time.strftime('%Y%m%d-%H%M%S')}").resolve()
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        try:
            runfolder.write_scenario_as_flown(run_dir, a.scenario, a.duration)
        except ConfigError as exc:  # the run itself is sound (its scenario loaded): say so and fly it
            print(f"am-run: warning: the scenario as flown could not be copied into the run folder: {exc}",
                  file=sys.stderr)
        runfolder.write_manifest(run_dir, a.scenario, spec.name, sys.argv if argv is None else argv, started,
                                 {"duration_s": spec.duration_s if a.duration is None else a.duration,
                                  "realtime": a.realtime, "gcs": a.gcs})
    except OSError as exc:
        return cliargs.fail("am-run", f"--run-dir {run_dir}: {exc.strerror or exc}")
    try:
        _warm_kernels(spec, a.scenario)  # every argument checked: compile the law once, before any companion
    except KeyboardInterrupt:
        print("am-run: interrupted while compiling the kernels; nothing was started", file=sys.stderr)
        return INTERRUPTED
    signals = _Signals()
    cfg = str(Path(a.scenario).resolve())
    key_args = _fresh_key(spec, run_dir)
    speed = a.speed or REALTIME_SPEED
    start = MISSION_START_S if a.mission_start is None else a.mission_start
    if a.realtime:  # PX4 SITL's onboard ports are unsigned, as PX4's; its GCS instances signed unless told
        sim_cmd = _command("simulator") + ["--config", cfg, "--realtime", "--speed", str(speed), "--mission-start",
                                           str(start), "--run-dir", str(run_dir), "--progress", "jsonl",
                                           "--instance", str(a.instance)]
        sim_cmd += (["--gcs", a.gcs] if gcs_given else []) + (
            ["--gcs-unsigned"] if a.gcs_unsigned else _gcs_key(spec, run_dir, a.gcs_key_file))
    else:
        sim_cmd = _command("simulator") + key_args + _gcs_key(spec, run_dir, a.gcs_key_file) + [
            "--config", cfg, "--bind", "udpin:127.0.0.1:0", "--gcs", a.gcs, "--run-dir", str(run_dir),
            "--progress", "jsonl", "--peer-timeout", str(a.startup_timeout)]
    if a.duration is not None:  # free-running: the mission's duration, from the mission's start
        sim_cmd += ["--duration", str(a.duration + start if a.realtime else a.duration)]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    tele_args = ["--no-telemetry"] if a.no_telemetry else []
    tele_keys = {} if a.no_telemetry else _telemetry_keys(spec, run_dir)
    mcap = run_dir / "run.mcap"
    procs: dict[str, subprocess.Popen] = {}
    logs = []
    interrupted = None
    refused = False
    # a bar on a terminal only, as the simulator's own default: redirected output gets the summary lines
    bar = SimBar(spec.duration_s if a.duration is None else a.duration, disabled=a.no_progress or not sys.stderr.isatty())
    if a.realtime:
        print(f"am-run: scenario '{spec.name}' with {len(spec.ams)} AMs, free-running at {speed:g}x real time, the "
              f"mission from autopilot time {start:g} s; run folder {run_dir}", file=sys.stderr)
    else:
        print(f"am-run: scenario '{spec.name}' with {len(spec.ams)} AMs; run folder {run_dir}; GCS link {a.gcs}",
              file=sys.stderr)
    try:
        signals.armed = True
        if not a.no_telemetry:
            # the logger listens on a free loopback port; every publisher connects to it
            endpoint = f"tcp/127.0.0.1:{_free_tcp_port()}"
            tele_args = ["--zenoh-connect", endpoint, "--telemetry-wait", "5"]  # the log starts with the run
            rlog = open(run_dir / "recorder.log", "w")
            logs.append(rlog)
            procs["recorder"] = subprocess.Popen(
                _command("ground-station") + ["record", "--out", str(mcap), "--zenoh-listen", endpoint,
                                              "--telemetry-key-file", tele_keys["recorder"]],
                stdout=rlog, stderr=subprocess.STDOUT, env=env, preexec_fn=_lower_priority)
            _wait_listening(endpoint, procs["recorder"], time.monotonic() + a.startup_timeout)
        log = open(run_dir / "simulator.log", "w")
        logs.append(log)
        sim_tele = tele_args + (["--telemetry-key-file", tele_keys["simulator"]] if tele_keys else [])
        # its events come on their own pipe: whatever a library prints on stdout or stderr goes to the log
        ev_read, ev_write = os.pipe()
        try:
            sim = procs["simulator"] = subprocess.Popen(sim_cmd + sim_tele + ["--events-fd", str(ev_write)],
                                                        stdout=log, stderr=subprocess.STDOUT, env=env,
                                                        pass_fds=(ev_write,))
        finally:
            os.close(ev_write)
        events = os.fdopen(ev_read, "r")
        logs.append(events)
        bind = None
        deadline = time.monotonic() + a.startup_timeout
        while bind is None:
            ev = _next_event(events, deadline)
            if ev is None:
                code = _exit_code(sim, time.monotonic() + 5.0)
                if code == REFUSED:
                    raise _Refused(_simulator_errors(run_dir / "simulator.log"))
                raise RuntimeError(f"the simulator did not start (exit {code}); see {run_dir / 'simulator.log'}")
            if ev.get("event") == "ready" and a.realtime:
                bind = ev
                if ev.get("gcs"):
                    print(f"am-run: GCS ports ({'unsigned' if a.gcs_unsigned else 'signed'}): {'; '.join(ev['gcs'])}",
                          file=sys.stderr)
            elif ev.get("event") == "ready":
                bind = ev["connect"]
                if ev.get("gcs") and parse_endpoint(a.gcs).port == 0:  # the port a GCS connects to
                    print(f"am-run: the GCS link listens on {ev['gcs']}", file=sys.stderr)
        for i, am in enumerate(spec.ams):
            clog = open(run_dir / f"companion-{am.sysid}.log", "w")
            logs.append(clog)
            tlog = ["--tlog", str(run_dir / f"companion-{am.sysid}.tlog")] if a.tlog_companions else []
            if a.realtime:  # each companion reaches its own vehicle's ports, as on a real AM
                link = ["--clock", "wall", "--arm", bind["arms"][i], "--ft", bind["ft"][i], "--mission-start",
                        str(start), "--frame-timeout", "3", "--instance", str(a.instance)] + (
                    ["--mocap", bind["mocap"]] if bind.get("mocap") else [])
                if not a.no_telemetry:  # the controller's state at REALTIME_TELEMETRY_HZ: CPU the loop needs
                    link += ["--telemetry-every", str(max(1, round(1.0 / (spec.control_dt_s * REALTIME_TELEMETRY_HZ))))]
            else:
                link = key_args + ["--sim", bind]
            procs[f"companion {am.sysid}"] = subprocess.Popen(
                _command("companion") + link + ["--sysid", str(am.sysid), "--config", cfg,
                                         "--outcome", str(run_dir / f"am{am.sysid}.json"),
                                         "--connect-timeout", str(a.startup_timeout)] + tlog + tele_args
                + (["--telemetry-key-file", tele_keys[f"am{am.sysid}"]] if tele_keys else []),
                stdout=clog, stderr=subprocess.STDOUT, env=env)
        failed = _follow(sim, events, procs, bar, started=a.realtime)
        if a.realtime:  # the run is over when the simulator ends it: its vehicles are gone, not silent
            for name, p in procs.items():
                if name.startswith("companion") and p.poll() is None:
                    p.send_signal(signal.SIGTERM)
    except _Interrupted as stop:
        interrupted = str(stop)
        failed = []
        bar.close()
        print(f"am-run: interrupted by {interrupted}; ending the run", file=sys.stderr)
        _pass_on(procs, interrupted)
    except _Refused as exc:  # its configuration: the simulator's own words, and the config error's exit code
        print(f"am-run: the simulator refused the scenario:\n{exc}", file=sys.stderr)
        refused = True
        failed = ["start-up"]
    except RuntimeError as exc:
        print(f"am-run: error: {exc}", file=sys.stderr)
        failed = ["start-up"]
    finally:
        signals.armed = False
        bar.close()
        _stop_all(procs)
        for f in logs:
            f.close()
    mission_failed = "simulator" in procs and procs["simulator"].returncode == MISSION_FAILED
    for name, p in procs.items():
        if p.returncode != 0 and name not in failed and not (name == "simulator" and mission_failed):
            failed.append(name)
    _print_summary(run_dir, spec, procs)
    interrupted = interrupted or signals.late
    if interrupted:  # the processes' non-zero exits are the interrupt's; the log stays to review
        if not a.no_telemetry and mcap.is_file():
            print(f"log: {mcap} (ground-station review {mcap})", file=sys.stderr)
        print(f"am-run: interrupted by {interrupted} (logs in {run_dir})", file=sys.stderr)
        return INTERRUPTED
    if not a.no_telemetry and mcap.is_file():
        r = subprocess.run(_command("ground-station") + ["review", str(mcap), "--plots", str(run_dir / "plots")],
                           capture_output=True, text=True, env=env)
        print(r.stdout + r.stderr, file=sys.stderr)
        print(f"log: {mcap}\nplots: {run_dir / 'plots'}", file=sys.stderr)
    if signals.late:  # during the review
        print(f"am-run: interrupted by {signals.late} (logs in {run_dir})", file=sys.stderr)
        return INTERRUPTED
    if refused:
        return REFUSED
    if failed:
        print(f"am-run: FAILED: {', '.join(failed)} (logs in {run_dir})", file=sys.stderr)
        return 1
    if mission_failed:
        print(f"am-run: the mission FAILED (verdict in {run_dir / 'outcome.json'})", file=sys.stderr)
        return MISSION_FAILED
    return 0


# resident memory of the processes am-run starts [MiB]: a companion (pinocchio, numpy, zenoh)
# measured at 191 MiB; the simulator's and recorder's figures are allowances, not measurements
COMPANION_MIB = 191
SIMULATOR_MIB = 250
SIMULATOR_PER_AM_MIB = 2


def memory_needed_mib(n_am: int) -> int:
    """About how much memory a run of `n_am` AMs takes [MiB]: one companion process per AM,
    the simulator and the recorder."""
    return n_am * (COMPANION_MIB + SIMULATOR_PER_AM_MIB) + SIMULATOR_MIB + COMPANION_MIB


def available_mib() -> float | None:
    """MemAvailable of /proc/meminfo [MiB] (None where there is none)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_memory(spec, available: float | None = None) -> None:
    """ConfigError (before anything starts) if the run's processes would not fit in the memory
    the machine has available: it would swap, or thrash without swap, instead of running."""
    have = available_mib() if available is None else available
    need = memory_needed_mib(len(spec.ams))
    if have is not None and need > have:
        raise ConfigError(f"{spec.path}: [[am]]: {len(spec.ams)} AMs need about {need / 1024:.1f} GiB "
                          f"({COMPANION_MIB} MiB per companion process, plus the simulator and the recorder); "
                          f"this machine has {have / 1024:.1f} GiB available")


def _fresh_key(spec, run_dir: Path) -> list[str]:
    """A random signing master key for this run (mode 0600 in the run folder), unless the
    scenario names its own keys or turns signing off."""
    if not spec.link.signing or spec.link.key_file or any(am.signing_key_hex for am in spec.ams):
        return []
    return ["--key-file", str(_secret_file(runfolder.keys_dir(run_dir) / "link.key", os.urandom(32).hex()))]


def _telemetry_keys(spec, run_dir: Path) -> dict[str, str]:
    """A random telemetry master key for this run for the recorder, and each publisher's own
    key derived from it (telemetry.auth), each in a 0600 file of the run folder: the recorder
    keeps only what the run's simulator and companions sealed."""
    return {name: str(path) for name, path in write_run_keys(runfolder.keys_dir(run_dir), [am.sysid for am in spec.ams]).items()}


def _gcs_key(spec, run_dir: Path, given: Path | None = None) -> list[str]:
    """The GCS signing passphrase: `given` (am-run --gcs-key-file), else a random one for this
    run (mode 0600 in the run folder, MAVProxy's 'signing key' takes it as is); none when the
    scenario turns signing off."""
    if not spec.link.signing:
        return []
    if given is not None:
        return ["--gcs-key-file", str(Path(given).resolve())]
    return ["--gcs-key-file", str(_secret_file(runfolder.keys_dir(run_dir) / "gcs.key", os.urandom(16).hex()))]


_secret_file = write_secret


def _free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(endpoint: str, proc: subprocess.Popen, deadline: float) -> None:
    host, port = endpoint.split("/")[1].rsplit(":", 1)
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"the ground-station recorder exited with {proc.returncode}")
        try:
            with socket.create_connection((host, int(port)), timeout=0.2):
                return
        except OSError:
            time.sleep(0.05)
    raise RuntimeError(f"the ground-station recorder is not listening on {endpoint}")


def _readable(stream, deadline: float) -> bool:
    return bool(select.select([stream], [], [], max(0.0, deadline - time.monotonic()))[0])


REFUSED = 2  # the simulator's exit code for a configuration it refuses, and am-run's then


class _Refused(Exception):
    """The simulator exited REFUSED before it was ready; the message is its error lines."""


def _next_event(events, deadline: float) -> dict | None:
    """The next event line from the simulator's events pipe before `deadline`; None at its end
    or on time-out. A line that is not a JSON object is skipped (only the simulator writes here)."""
    while _readable(events, deadline):
        line = events.readline()
        if not line:
            return None
        try:
            ev = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(ev, dict):
            return ev
    return None


def _exit_code(proc: subprocess.Popen, deadline: float) -> int | None:
    try:
        return proc.wait(max(0.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        return None


def _simulator_errors(log_path: Path) -> str:
    """The simulator's own error lines in its log (all of its last lines if none is marked)."""
    try:
        lines = log_path.read_text(errors="replace").splitlines()
    except OSError:
        return f"(no log at {log_path})"
    mark = "simulator: error"  # a library's unterminated output may precede it on its line
    errors = [ln[ln.index(mark):] for ln in lines if mark in ln]
    return "\n".join(errors or lines[-5:])


def _follow(sim: subprocess.Popen, events, procs: dict[str, subprocess.Popen], bar: SimBar,
            started: bool = False) -> list[str]:
    """Show progress until the simulator exits. A process that fails before the run starts
    stops everything (the simulator would only wait for it); once the run is under way, a
    companion that dies is reported and its vehicle flies on under the flight controller's
    failsafe, as on a real vehicle, until the simulator ends the run; a dead logger never
    stops a run."""
    reported, failed = set(), []  # (free-running: under way from the start; the simulator waits for nobody)
    while True:
        if _readable(events, time.monotonic() + 0.2):
            line = events.readline()
            if not line:
                sim.wait()
                return failed
            try:
                ev = json.loads(line)
            except json.JSONDecodeError:
                continue
            if ev.get("event") == "progress":
                started = True
                bar.show(ev["t"], ev["rtf"])
            elif ev.get("event") == "end":  # free-running: the run is over, its vehicles are about to go
                for name, p in procs.items():
                    if name.startswith("companion") and p.poll() is None:
                        p.send_signal(signal.SIGTERM)
        for name, p in procs.items():
            code = p.poll()
            if code in (None, 0) or p is sim or name in reported:
                continue
            if not started and name != "recorder":
                return [name]
            reported.add(name)
            failed.append(name)
            what = "the run goes on without its log" if name == "recorder" else "its vehicle is in failsafe"
            print(f"\nam-run: {name} exited with code {code}; {what} (see {name.replace(' ', '-')}.log)",
                  file=sys.stderr)


def _lower_priority() -> None:
    """In the recorder's child process: nice 10, so that on a machine with fewer cores than
    processes the logger takes the time the lockstep leaves idle (its inbox buffers) rather
    than the simulator's and companions'."""
    try:
        os.nice(10)
    except (AttributeError, OSError):
        pass


def _stop_all(procs: dict[str, subprocess.Popen], grace_s: float = 10.0) -> None:
    deadline = time.monotonic() + grace_s
    # companions end on the simulator's SHUTDOWN; give them the grace period before signalling
    for p in procs.values():
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGTERM)
    for p in procs.values():
        try:
            p.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _print_summary(run_dir: Path, spec, procs) -> None:
    path = run_dir / "outcome.json"
    if not path.is_file():
        return
    o = json.loads(path.read_text())
    if "object" not in o:  # the world never came up (a refused configuration): nothing flew
        return
    obj = o["object"]
    rtf = o.get("real_time_factor") or 0.0
    print(f"\n{spec.name}: {o['status']}; {o['sim_time_s']:.2f} s simulated, {rtf:.2f}x real time", file=sys.stderr)
    timing = o.get("timing")
    if timing:  # free-running
        print(f"pacing: {timing['deadline_misses']} of {timing['steps']} physics steps missed their deadline, worst "
              f"lateness {1e3 * timing['worst_lateness_s']:.1f} ms, {1e3 * timing['mean_step_compute_s']:.2f} ms of "
              f"compute per step of {1e3 * timing['period_s']:.2f} ms", file=sys.stderr)
    if "verdict" in o:
        print(f"verdict: {o['verdict']['text']}", file=sys.stderr)
    print("success criteria ([success] of the scenario):\n"
          + format_criteria(criteria_rows(o, spec.success)), file=sys.stderr)
    hl = obj.get("hover_min_lift_m")
    print(f"object: final lift {obj['final_lift_m'] * 100:.1f} cm"
          + (f", hover-window min {hl * 100:.1f} cm" if hl is not None else "")
          + (f", touching {obj['touching_in_hover']}" if obj["touching_in_hover"] else ""), file=sys.stderr)
    share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
    print(f"{'sysid':>5} {'|r~c| t=5s':>11} {'|eR| t=5s':>10} {'|r~c| end':>10} {'|eR| end':>9} {'F/T up':>8} "
          f"{'share':>7} {'normal':>7} {'slip':>7} {'sat':>6}", file=sys.stderr)
    for am in spec.ams:
        g = o["ams"][str(am.sysid)]
        c = {}
        cp = run_dir / f"am{am.sysid}.json"
        if cp.is_file():
            c = json.loads(cp.read_text())
        a5, end = c.get("at", {}).get("approach_end", {}), c.get("at", {}).get("end", {})
        up = -g["hover_mean_ft_force_W_n"][2]

        def mm(x):
            return f"{x * 1e3:.2f}mm" if x is not None else "-"

        def rad(x):
            return f"{x:.4f}" if x is not None else "-"
        print(f"{am.sysid:>5} {mm(a5.get('r_c_err')):>11} {rad(a5.get('e_R')):>10} {mm(end.get('r_c_err')):>10} "
              f"{rad(end.get('e_R')):>9} {up:7.2f}N {share:6.2f}N {g['hover_mean_normal_force_n']:6.2f}N "
              f"{g['slip_max_m'] * 1e3:5.2f}mm {g['saturated_steps']:>6}", file=sys.stderr)
    for am in spec.ams:  # free-running: each companion's loop as it measured itself
        cp = run_dir / f"am{am.sysid}.json"
        loop = json.loads(cp.read_text()).get("loop") if cp.is_file() else None
        if loop:
            p, lat = loop.get("period_ms", {}), loop.get("sample_to_setpoint_ms", {})
            print(f"companion {am.sysid}: period p50 {p.get('p50')} / p99 {p.get('p99')} / max {p.get('max')} ms "
                  f"(target {loop.get('period_target_ms')} ms), {loop.get('deadline_misses')} deadline misses, "
                  f"sample to setpoint p50 {lat.get('p50')} / p99 {lat.get('p99')} ms", file=sys.stderr)
    print(f"(F/T up: mean vertical force the wrist sensor measures in the hover window "
          f"{o['hover_window_s'][0]:g}-{o['hover_window_s'][1]:g} s; share: m_obj g / N; slip: pad "
          f"relative to the object since t = {o['slip_from_s']:g} s)", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
