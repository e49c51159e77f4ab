"""SITL simulator process: the PyBullet world of a scenario and every AM's flight-controller
emulation, stepped in lockstep with one companion process per AM over MAVLink (UDP, TCP or serial).

    simulator [--config configs/scenarios/two_am_comp_attitude.toml] [--bind udpin:127.0.0.1:14550]
              [--gcs udpout:127.0.0.1:14551]

Start-up waits for every [[am]] sysid's HEARTBEAT and ARM; then each control step k it sends
every companion its sensor frame (ODOMETRY, AM_JOINT_STATE, AM_WRENCH, AM_SIM_STEP), waits for
all N setpoints answering step k (the N exchanges run concurrently) and applies them through
the flight controller (torque mode: the rotor mixer; attitude mode: the emulated autopilot)
and the joint limits (saturation is counted and logged); it steps physics every step.
A setpoint rejected as implausible is answered at once: the flight controller holds its last
valid command and counts it, and K rejections in a row send that vehicle to failsafe for the
rest of the run (--failsafe-after-rejected; simulator.core).
It also plays each vehicle's flight-controller GCS port (--gcs, simulator.gcs_link), as
PX4 SITL does. The run folder gets outcome.json (the physical outcome from ground truth, see
simulator.outcome, and the mission verdict, simulator.verdict) and gcs.tlog. Exit codes: 0
run complete and its mission a success (or not failed so far, when --duration cut the
mission short), 4 the mission failed (the verdict names the criterion and when), 2 bad
configuration (the loader's, or a URDF PyBullet cannot load), 1 link failure (a missing or
silent companion, named), 130 interrupted. With --progress jsonl its events (ready,
progress, done) are JSON lines on stdout, or on the inherited descriptor --events-fd names
(am-run's: nothing but the events is written there).

    simulator --realtime [--speed F] [--onboard ENDPOINT]... [--duration S]

runs it free-running instead (simulator.freerun): physics paced to the wall clock (F times real
time), each vehicle played as PX4 SITL on its onboard MAVLink port (vehicle i: bind
127.0.0.1:14580+i, send to 127.0.0.1:14540+i, or --onboard per vehicle), flown by any PX4
offboard program; the arm by its own bus. It prints the ports at the start and the deadline
misses and worst lateness at the end; outcome.json says the same and more. Without --duration it
ends when the mission clock (first OFFBOARD engage + amcore.mission.TAKEOFF_S) reaches
[scenario].duration_s. Exit codes as above; 1 also when no vehicle engaged OFFBOARD.
"""
from __future__ import annotations

import json
import os
import signal
import sys
import time
from pathlib import Path

from amcore import cliargs, preflight
from amcore.config import DEFAULT_SCENARIO, ConfigError, check_duration, load_scenario, scenario_id
from amlink import signing
from amlink.endpoint import DEFAULT_GCS, SIM_BIND, EndpointError, parse_endpoint
from amlink.errors import LinkError
from amlink.lockstep import SimServer
from amlink.protocol import STATUSTEXT_MAX
from amlink.types import ScenarioInfo, SetpointLimits
from amruntime import jitcache, procstats

from telemetry import schema
from telemetry.publisher import TelemetryPublisher
from telemetry.session import TelemetryConfigError, add_zenoh_arguments, options_from_args
from telemetry.wiring import SimulatorTelemetry

from .core import SitlCore, kernel_group
from .freerun import FreeRun, endpoints_for
from .px4.port import PortError
from .gcs import GcsSession, snapshot_every
from .gcs_link import GcsLink
from .lockstep import Lockstep, ServerTransport
from .bullet import pb
from .progress import SimBar
from .verdict import MISSION_FAILED



class _Stop(BaseException):
    """SIGINT or SIGTERM: a BaseException, as KeyboardInterrupt, so that no `except Exception` of a
    handler that keeps the run alive (a port's, for a message that trips a bug) swallows it."""


class _BindError(Exception):
    pass


class _Refused(Exception):
    """The physics engine refuses what the loader let through (the vehicle's URDF): a
    configuration error, exit 2."""


def _on_signal(signum, _frame):
    """The first SIGINT or SIGTERM ends the run; later ones are ignored, so that the run's end
    (the outcome, the companions told, the log's last samples) is not cut short by a second
    Ctrl-C or by am-run passing an interrupt on that the terminal delivered too."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    raise _Stop(signal.Signals(signum).name)


_EVENTS = {"stream": None}  # where --progress jsonl's events go: --events-fd, else stdout


def emit_event(**kw) -> None:
    """One event, a JSON line, on the events channel (--events-fd N: that descriptor, which am-run
    reads; nothing a library prints on stdout or stderr reaches it; else stdout)."""
    stream = _EVENTS["stream"] or sys.stdout
    stream.write(json.dumps(kw) + "\n")
    stream.flush()


def open_events(fd: int | None) -> None:
    """Send the events to descriptor `fd` (None: stdout)."""
    if fd is not None:
        _EVENTS["stream"] = os.fdopen(fd, "w", buffering=1, closefd=False)


class Progress:
    """Progress to stderr as a bar (`simulator.progress`) or as JSON-line events (for am-run,
    `emit_event`)."""

    def __init__(self, mode: str, duration_s: float) -> None:
        self.mode, self.duration = mode, duration_s
        self.t_wall0 = time.perf_counter()
        self._next = 0.0
        self._bar = SimBar(duration_s, disabled=mode != "bar")

    def event(self, **kw) -> None:
        if self.mode == "jsonl":
            emit_event(**kw)

    def update(self, t: float, force: bool = False) -> None:
        now = time.perf_counter()
        if now < self._next and not force:
            return
        self._next = now + 0.5
        wall = now - self.t_wall0
        rtf = t / wall if wall > 0 else 0.0
        if self.mode == "jsonl":
            self.event(event="progress", t=round(t, 3), duration=self.duration, rtf=round(rtf, 3))
        else:
            self._bar.show(t, rtf)
            if force:
                self._bar.close()


def main(argv: list[str] | None = None) -> int:
    ap = cliargs.ArgumentParser(prog="simulator", description=" ".join(__doc__.split("\n\n")[0].split()),
                                epilog=cliargs.exit_codes(0, 1, 2, 4, 130, c1="a link failure (a missing or silent "
                                                          "companion, named; free-running: no vehicle engaged OFFBOARD)"))
    ap.add_argument("--config", type=Path, default=DEFAULT_SCENARIO, help="scenario TOML")
    ap.add_argument("--bind", action="append", metavar="ENDPOINT",
                    help=f"where the companions reach their flight controllers, repeatable (default "
                         f"{SIM_BIND}; HOST 0.0.0.0 serves other hosts, port 0 = any free port); "
                         "mavutil's forms: udpin:/udp:, udpout:, tcpin:, tcp:HOST:PORT, serial DEVICE[:BAUD]")
    ap.add_argument("--gcs", default=None, metavar="ENDPOINT",
                    help=f"the flight controllers' GCS link (default {DEFAULT_GCS}; mavutil's forms; 'none': "
                         f"no GCS endpoint, gcs.tlog is written all the same); free-running: each vehicle's GCS "
                         f"instance, PX4 SITL's by default (bind 127.0.0.1:18570+i, send to 127.0.0.1:14550), "
                         f"udpout:HOST:PORT or none")
    ap.add_argument("--onboard-key-file", type=Path, default=None, metavar="FILE",
                    help="free-running: the onboard ports' signing passphrase (SHA-256 of it, as MAVProxy's 'signing "
                         "key'): only frames signed with it are read (companion --fc-key-file); default unsigned, as "
                         "PX4's")
    ap.add_argument("--gcs-unsigned", action="store_true",
                    help="free-running: the GCS instances' signing off, for tools without MAVLink signing "
                         "(MAVSDK): any program that reaches the port can command the vehicles")
    ap.add_argument("--gcs-key-file", type=Path, default=None,
                    help="GCS signing passphrase file (key = SHA-256 of the passphrase, as MAVProxy's 'signing "
                         "key'); with signing on, GCS commands are executed only if signed with it")
    ap.add_argument("--run-dir", type=cliargs.output_dir, default=None, help="folder for outcome.json (default runs/<name>-<time>)")
    ap.add_argument("--duration", type=cliargs.seconds, default=None, help="override [scenario].duration_s")
    ap.add_argument("--peer-timeout", type=cliargs.seconds, default=60.0, help="seconds to wait for every companion at start")
    ap.add_argument("--step-timeout", type=cliargs.seconds, default=5.0,
                    help="seconds a companion may stay silent before its vehicle goes to failsafe")
    ap.add_argument("--failsafe-after-rejected", type=cliargs.count, default=None, metavar="K",
                    help="a vehicle goes to failsafe after K of its setpoints in a row are rejected as implausible "
                         "(each one is answered at once: the flight controller holds the last valid command); "
                         "default: the scenario's [flight_controller].failsafe_after_rejected")
    ap.add_argument("--key-file", type=Path, default=None,
                    help="signing master key (64 hex digits); overrides [link].key_file of the scenario")
    ap.add_argument("--progress", choices=("bar", "jsonl", "none"), default=None,
                    help="progress display (default: bar on a terminal, else none)")
    ap.add_argument("--events-fd", type=cliargs.number(3, 65535, integer=True), default=None, metavar="FD",
                    help="with --progress jsonl: write the events (ready, progress, done) to this inherited file "
                         "descriptor instead of stdout, so that nothing else printed can mix with them (am-run)")
    ap.add_argument("--realtime", action="store_true",
                    help="free-running: physics paced to the wall clock, each vehicle played as PX4 SITL on its "
                         "onboard MAVLink port (simulator.freerun); any PX4 offboard program flies it")
    ap.add_argument("--speed", type=cliargs.number(0.0, lo_open=True), default=None, metavar="F",
                    help="free-running real-time factor (implies --realtime; default 1.0)")
    ap.add_argument("--mission-start", type=cliargs.seconds, default=None, metavar="S",
                    help="free-running: the autopilots' boot time [s] of the mission's t = 0, as the companions are "
                         "told (companion --mission-start); default: the first OFFBOARD engage + 3 s of take-off")
    ap.add_argument("--instance", type=cliargs.number(0, 1000, integer=True), default=0, metavar="N",
                    help="free-running: vehicle i is PX4 SITL instance N+i (as px4 -i): its ports are shifted by N, "
                         "so that two runs share a machine (companion --instance N)")
    ap.add_argument("--onboard", action="append", metavar="ENDPOINT",
                    help="free-running: vehicle i's onboard port, repeatable, one per [[am]] in order (default PX4 "
                         "SITL's: bind 127.0.0.1:14580+i, send to 127.0.0.1:14540+i); udpout:HOST:PORT or "
                         "udpin:HOST:PORT")
    add_zenoh_arguments(ap, role="publisher")
    a = ap.parse_args(argv)
    try:
        open_events(a.events_fd)
    except OSError as exc:
        return cliargs.fail("simulator", f"--events-fd {a.events_fd}: {exc.strerror or exc}")
    if a.speed is not None:
        a.realtime = True
    if a.onboard and not a.realtime:
        return cliargs.fail("simulator", "--onboard needs --realtime (the lockstep's companions use --bind)")
    try:
        binds = [parse_endpoint(b) for b in (a.bind or [SIM_BIND])]
    except EndpointError as exc:
        print(f"simulator: error: --bind: {exc}", file=sys.stderr)
        return 2
    try:
        if a.gcs is None and not a.realtime:
            a.gcs = DEFAULT_GCS
        gcs_endpoint = None if a.gcs is None or a.gcs.strip().lower() == "none" else parse_endpoint(a.gcs)
    except EndpointError as exc:
        print(f"simulator: error: --gcs: {exc} (or none)", file=sys.stderr)
        return 2
    try:
        spec = load_scenario(a.config)
        preflight.check(spec)  # [mission].envelope_check: nothing flies outside the team's envelope
        keys, warning = signing.keys_for_run(spec, a.key_file)
        gcs_key = signing.read_gcs_key_file(a.gcs_key_file) if a.gcs_key_file is not None else None
        onboard_key = signing.read_gcs_key_file(a.onboard_key_file, "--onboard-key-file") if a.onboard_key_file is not None else None
    except (ConfigError, signing.SigningKeyError) as exc:
        print(f"simulator: error: {exc}", file=sys.stderr)
        return 2
    if a.onboard_key_file is not None and not a.realtime:
        return cliargs.fail("simulator", "--onboard-key-file is for --realtime (the lockstep's link is keyed by "
                                         "--key-file)")
    if a.gcs_unsigned and not a.realtime:
        return cliargs.fail("simulator", "--gcs-unsigned is for --realtime (the lockstep's GCS link is unsigned "
                                         "when the scenario's [link] signing is off)")
    if a.realtime:  # the onboard ports are unsigned (as PX4 SITL's); the GCS instances as --gcs-key-file says
        if a.duration is not None:
            try:
                check_duration(spec, a.duration, "--duration")
            except ConfigError as exc:
                return cliargs.fail("simulator", str(exc))
        return _main_freerun(a, spec, gcs_key, onboard_key)
    if warning:
        print(f"simulator: warning: {warning}", file=sys.stderr)
    if keys is not None and gcs_key is None and gcs_endpoint is not None:
        print("simulator: warning: no --gcs-key-file: the GCS link sends telemetry but executes no command "
              "(am-run writes a GCS key to the run folder)", file=sys.stderr)
    duration = spec.duration_s if a.duration is None else a.duration
    try:
        check_duration(spec, duration, "--duration")
    except ConfigError as exc:
        return cliargs.fail("simulator", str(exc))
    try:  # a missing telemetry key, like a bad configuration, stops it before anything is written
        tele_opts = options_from_args(a)
    except (TelemetryConfigError, ValueError) as exc:
        print(f"simulator: error: telemetry: {exc}", file=sys.stderr)
        return 2
    mode = a.progress or ("bar" if sys.stderr.isatty() else "none")
    run_dir = a.run_dir or Path("runs") / f"{spec.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    try:  # before the run: a run folder that cannot be written must not lose the outcome afterwards
        run_dir.mkdir(parents=True, exist_ok=True)
        (run_dir / ".write-check").touch()
        (run_dir / ".write-check").unlink()
    except OSError as exc:
        return cliargs.fail("simulator", f"--run-dir {run_dir}: cannot write there: {exc.strerror or exc}")
    sysids = [am.sysid for am in spec.ams]
    info = ScenarioInfo(scenario_id=scenario_id(spec), n_am=len(sysids), name=spec.name, seed=spec.seed,
                        rate_hz=spec.rate_hz)
    progress = Progress(mode, duration)
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)

    try:
        tele = TelemetryPublisher(tele_opts, name="simulator")
    except (TelemetryConfigError, ValueError) as exc:
        print(f"simulator: error: telemetry: {exc}", file=sys.stderr)
        return 2
    sim_tele = SimulatorTelemetry(tele, spec)

    def log(msg: str) -> None:
        print(f"simulator: {msg}", file=sys.stderr, flush=True)
        sim_tele.fault(core.time_s, msg, level="warning")

    core = SitlCore(spec, log=log, on_truth=sim_tele.truth, failsafe_after_rejected=a.failsafe_after_rejected)
    v = spec.vehicle
    limits = SetpointLimits.for_vehicle(v.rotors.thrust_max_total_n, max(v.joint_torque_max_nm), v.n_joints)
    gcs_link = GcsLink(gcs_endpoint, sysids, key=gcs_key, accept_unsigned=keys is None, tlog=run_dir / "gcs.tlog")
    pose = core.object_pose  # [mission].object_pose = "mocap": the measured object, sent in the handshake
    server = SimServer(binds, sysids=sysids, scenario=info, timeout_s=a.step_timeout, signing_keys=keys,
                       limits=limits, on_heartbeat=gcs_link.forward_heartbeat,
                       object_pose=None if pose is None else (pose.p_W_m, pose.yaw_rad))
    gcs = GcsSession(core, gcs_link, server.armed, snapshot_every(spec.rate_hz))
    # every step: the GCS link's snapshot, STATUSTEXTs and GCS commands (while the companions compute)
    lockstep = Lockstep(core, ServerTransport(server), meanwhile=gcs.tick,
                        after_step=lambda _k: progress.update(core.time_s))
    status, code = "run complete", 0
    completed = False  # the run reached its end (a vehicle in failsafe makes the code 1, not the run an error)
    told = status  # what the companions hear (STATUSTEXT carries 50 bytes)
    n_steps = int(round(duration * spec.rate_hz))
    result: dict = {}
    cpu = procstats.CpuMeter()
    tele.open()
    try:
        # the autopilot's, allocation's and devices' kernels: compiled on a machine's first run, under their
        # own lock (amruntime.jitcache), so that a simulator and an am-run or a campaign starting together
        # compile them once, side by side with the control law; else loaded from the cache
        jit = jitcache.warm_groups([kernel_group(spec)])
        if jit.compiled:
            print(f"simulator: compiled the simulator's kernels in {jit.seconds:.1f} s (once per machine: cached "
                  f"in {jitcache.cache_dir()})", file=sys.stderr, flush=True)
        try:
            core.connect()
        except pb.error as exc:  # PyBullet's own refusal of a file: the user's to fix
            raise _Refused(f"{spec.vehicle.urdf}: PyBullet cannot load the scenario's bodies: {exc}") from None
        try:
            server.open()
        except OSError as exc:
            raise _BindError(f"cannot listen on {', '.join(a.bind or map(str, binds))}: {exc}") from None
        try:
            gcs.open()
        except OSError as exc:
            raise _BindError(f"cannot open --gcs {gcs_endpoint}: {exc}") from None
        gcs_endpoint = gcs_link.bound_endpoint  # a listening GCS endpoint's port 0 resolved
        bound = [str(e) for e in server.bound_endpoints]
        first = server.bound_endpoints[0]
        # "bind" as before (udp:HOST:PORT); "connect" is what a companion passes as --sim to reach it
        progress.event(event="ready", bind=f"udp:{first.host}:{first.port}" if first.kind == "udpin" else bound[0],
                       connect=f"udpout:{first.host}:{first.port}" if first.kind == "udpin" else None,
                       endpoints=bound, gcs=str(gcs_endpoint) if gcs_endpoint else None, scenario=spec.name,
                       sysids=sysids)
        print(f"simulator: '{spec.name}' on {', '.join(bound)}, waiting for sysids {sysids}; GCS link "
              f"{gcs_endpoint or 'none'}", file=sys.stderr, flush=True)
        said = _Throttled(lambda text: print(f"simulator: {text}", file=sys.stderr, flush=True))
        server.wait_for_peers(a.peer_timeout, on_waiting=said)
        server.wait_for_armed(a.peer_timeout, on_waiting=said)
        if not tele.await_recorder(tele.keys.sim_event, a.telemetry_wait):
            print(f"simulator: warning: telemetry: no subscriber (recorder) after {a.telemetry_wait:g} s; "
                  f"publishing anyway", file=sys.stderr, flush=True)
        progress.t_wall0 = time.perf_counter()
        cpu.start()
        sim_tele.start(core.time_s)

        lockstep.run(n_steps)  # simulator.lockstep: frames out, answers in, holds between control steps
        progress.update(core.time_s, force=True)
        result = core.finish()
        verdict = result["verdict"]
        completed = True
        if not verdict["success"]:
            status = f"run complete; {verdict['text']}"
        if verdict["status"] == "failed":
            code = MISSION_FAILED
            told = _told(verdict["failures"][0])
    except _Stop as stop:
        status, code = f"interrupted by {stop}", 130
        told = status
    except _BindError as exc:
        status, code, told = str(exc), 1, str(exc)
        print(f"simulator: error: {exc}", file=sys.stderr)
    except _Refused as exc:
        status, code, told = str(exc), 2, str(exc)
        print(f"simulator: error: {exc}", file=sys.stderr)
    except LinkError as exc:
        status, code, told = f"link failure: {exc}", 1, str(exc)
        print(f"\nsimulator: error: {exc}", file=sys.stderr)
    finally:
        sim_tele.end(core.time_s, status, level="info" if code == 0 else "error")
        if gcs_link.is_open:
            gcs.verdict(told, ok=code == 0)  # the one place the run's end goes to the GCS
        server.close(told, error=code != 0 and not completed)
        gcs_link.close()
        if not result:
            try:
                result = core.finish()
            except Exception:  # the world never connected
                result = {}
        core.close()
        tele.close()
    wall = time.perf_counter() - progress.t_wall0
    k = lockstep.k
    sim_time = k * spec.dt_s
    cpu_s, main_thread = cpu.seconds(), cpu.main_thread()
    result = {"scenario": spec.name, "scenario_id": info.scenario_id, "status": status, "exit_code": code,
              "steps": k, "sim_time_s": sim_time, "wall_s": wall,
              "real_time_factor": (sim_time / wall) if wall > 0 else None, "link": vars(server.stats),
              "process": {"memory_mib": procstats.memory_mib(), "cpu_s": cpu_s,
                          "cpu_us_per_step": 1e6 * cpu_s / k if cpu_s is not None and k else None,
                          "main_thread": main_thread},
              "gcs": {"endpoint": str(gcs_endpoint) if gcs_endpoint else None, **vars(gcs_link.stats),
                      "error": gcs_link.error, "link": vars(gcs_link.link_stats)}, **result}
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "outcome.json").write_text(json.dumps(result, indent=1))
    progress.event(event="done", status=status, exit_code=code, outcome=str(run_dir / "outcome.json"))
    verdict_text = result.get("verdict", {}).get("text", "")  # "mission success", as am-run says it
    said = f"{status}; {verdict_text}" if completed and verdict_text and verdict_text not in status else status
    print(f"simulator: {said}; {sim_time:.3f} s simulated in {wall:.1f} s; outcome in {run_dir / 'outcome.json'}",
          file=sys.stderr)
    return code


def _main_freerun(a, spec, gcs_key: bytes | None, onboard_key: bytes | None = None) -> int:
    """--realtime: the free-running simulator (simulator.freerun), wired: its ports, the run,
    outcome.json. Exit codes as the lockstep's; 1 also when no vehicle engaged OFFBOARD."""
    try:  # a missing telemetry key, like a bad configuration, stops it before anything is written
        tele = TelemetryPublisher(options_from_args(a), name="simulator")
    except (TelemetryConfigError, ValueError) as exc:
        return cliargs.fail("simulator", f"telemetry: {exc}")
    sim_tele = SimulatorTelemetry(tele, spec)

    def log(msg: str) -> None:
        print(f"simulator: {msg}", file=sys.stderr, flush=True)
        # (the log's clock is the mission's, from 0: what comes before it is stamped 0)
        sim_tele.fault(max(run.mission_time_s(), 0.0) if run is not None else 0.0, msg, level="warning")

    def timing(t: float, stats: dict) -> None:  # the physics loop's measurements, into the log
        if tele.enabled:
            tele.publish(tele.keys.sim_event, schema.loop_timing_event(max(t, 0.0), stats, "simulator"))

    run = None
    try:
        onboard = a.onboard or ([f"udpout:127.0.0.1:{14540 + a.instance + i}" for i in range(len(spec.ams))]
                                if a.instance else None)
        endpoints = endpoints_for(spec, onboard)
        gcs = _freerun_gcs(a, spec, gcs_key)
        arms, wrists, mocap = freerun_devices(spec, a.instance)
        run = FreeRun(spec, endpoints, speed=a.speed or 1.0, arms=arms, wrist_sensors=wrists, mocap=mocap,
                      mission_t0_s=a.mission_start, gcs=gcs, gcs_key=gcs_key, gcs_signed=not a.gcs_unsigned,
                      instance=a.instance, onboard_key=onboard_key, on_truth=sim_tele.truth, on_timing=timing,
                      log=log)
    except (PortError, ValueError) as exc:
        return cliargs.fail("simulator", str(exc))
    run_dir = a.run_dir or Path("runs") / f"{spec.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return cliargs.fail("simulator", f"--run-dir {run_dir}: cannot write there: {exc.strerror or exc}")
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)
    status, code, result = "run complete", 0, {}
    try:
        jit = jitcache.warm_groups([kernel_group(spec)])
        if jit.compiled:
            print(f"simulator: compiled the simulator's kernels in {jit.seconds:.1f} s", file=sys.stderr, flush=True)
        run.open()
        ports = "; ".join(f"sysid {p.sysid}: {p.describe()}" for p in run.ports)
        print(f"simulator: '{spec.name}' free-running at {run.speed:g}x real time; PX4 onboard ports: {ports}",
              file=sys.stderr, flush=True)
        if run.gcs_ports:
            signed = ("signed" if gcs_key is not None else "signing on, no --gcs-key-file: telemetry only") \
                if not a.gcs_unsigned else "UNSIGNED"
            ports = "; ".join(f"sysid {p.sysid}: {p.describe()}" for p in run.gcs_ports)
            print(f"simulator: GCS ports ({signed}): {ports}", file=sys.stderr, flush=True)
        buses = "; ".join(f"sysid {s}: servo bus tcp:{arm.address[0]}:{arm.address[1]}, F/T udp:{ft.address[0]}:"
                          f"{ft.address[1]}" for s, arm, ft in zip(run.sysids, arms, wrists))
        print(f"simulator: devices: {buses}" + (f"; motion capture udp:{mocap.address[0]}:{mocap.address[1]}"
                                                 if mocap is not None else ""), file=sys.stderr, flush=True)
        tele.open()
        progress_ready(a, spec, run, arms, wrists, mocap)
        if not tele.await_recorder(tele.keys.sim_event, a.telemetry_wait):
            print(f"simulator: warning: telemetry: no subscriber (recorder) after {a.telemetry_wait:g} s; "
                  f"publishing anyway", file=sys.stderr, flush=True)
        sim_tele.start(0.0)
        result = run.run(a.duration)
        if a.progress == "jsonl":  # before the ports close: am-run ends the companions as the run ends
            emit_event(event="end", status=result["status"])
        status = result["status"]
        if status.startswith("no vehicle"):
            code = 1
        elif result["verdict"]["status"] == "failed":
            code = MISSION_FAILED
    except _Stop as stop:
        status, code = f"interrupted by {stop}", 130
    except OSError as exc:
        status, code = str(exc), 1
        print(f"simulator: error: {exc}", file=sys.stderr)
    except Exception as exc:  # a bug: the outcome so far is still written, with the error
        import traceback
        traceback.print_exc()
        status, code = f"internal error: {type(exc).__name__}: {exc}", 1
    finally:
        if not result and run.core is not None:
            result = run.result()
        t_end = run.mission_time_s()
        run.close()
        sim_tele.end(max(t_end, 0.0), status, level="info" if code == 0 else "error")
        tele.close()
    result = {"scenario": spec.name, "scenario_id": scenario_id(spec), **result, "status": status, "exit_code": code}
    (run_dir / "outcome.json").write_text(json.dumps(result, indent=1))
    timing = result.get("timing", {})
    verdict = result.get("verdict", {}).get("text", "")
    print(f"simulator: {status}; {verdict}; {result.get('sim_time_s', 0.0):.3f} s simulated in "
          f"{result.get('wall_s') or 0.0:.1f} s; {timing.get('deadline_misses', 0)} deadline misses of "
          f"{timing.get('steps', 0)} steps, worst lateness {1e3 * timing.get('worst_lateness_s', 0.0):.2f} ms; "
          f"outcome in {run_dir / 'outcome.json'}", file=sys.stderr)
    return code


def _freerun_gcs(a, spec, gcs_key: bytes | None):
    """Each vehicle's GCS endpoint from --gcs (None: no GCS instances); PortError if unusable.
    Warns of an unsigned GCS link, as the lockstep warns of a keyless one."""
    from .px4.port import gcs_endpoint
    if a.gcs is not None and a.gcs.strip().lower() == "none":
        return None
    eps = [gcs_endpoint(i, a.gcs) for i in range(len(spec.ams))]
    if a.gcs_unsigned:
        print("simulator: warning: --gcs-unsigned: the GCS ports take unsigned commands; any program that reaches "
              "them can arm, switch modes and land the vehicles", file=sys.stderr)
    elif gcs_key is None:
        print("simulator: warning: no --gcs-key-file: the GCS ports send telemetry but read nothing (signing on); "
              "give --gcs-key-file, or --gcs-unsigned for tools without signing", file=sys.stderr)
    return eps


def freerun_devices(spec, instance: int = 0):
    """Each vehicle's arm as a Dynamixel bus (simulator.servo_bus, TCP 7200+i) and wrist sensor
    as a Net F/T (simulator.netft, UDP 49152+i), and the object's motion-capture stream
    (simulator.mocap_stream, UDP 7400) when the scenario plans from it."""
    from amlink.mocap_protocol import MOCAP_PORT

    from . import netft, servo_bus
    from .freerun import start_joints
    from .mocap_stream import MocapStream
    v, d = spec.vehicle, spec.devices
    q0 = start_joints(spec)
    noise = {"effort": d.effort, "noise_scale": d.scale} if d.enabled else {"noise_scale": 0.0}
    arms = [servo_bus.ServoBus(v.n_joints, q0_rad=q0[am.sysid], torque_max_nm=v.joint_torque_max_nm, seed=spec.seed,
                               sysid=am.sysid, endpoint=servo_bus.default_endpoint(instance + i), **noise)
            for i, am in enumerate(spec.ams)]
    wrists = [netft.NetFtServer(rate_hz=spec.rate_hz, endpoint=netft.default_endpoint(instance + i))  # a record per physics step
              for i in range(len(spec.ams))]
    mocap = (MocapStream(endpoint=f"udpin:127.0.0.1:{MOCAP_PORT + instance}") if spec.mission.object_pose == "mocap"
             else None)
    return arms, wrists, mocap


def progress_ready(a, spec, run, arms, wrists, mocap) -> None:
    """The ready event (--progress jsonl, for am-run): every endpoint a companion reaches."""
    if a.progress != "jsonl":
        return
    emit_event(event="ready", realtime=True, speed=run.speed, scenario=spec.name, sysids=run.sysids,
               onboard=[p.describe() for p in run.ports], gcs=[p.describe() for p in run.gcs_ports],
               arms=[f"tcp:{x.address[0]}:{x.address[1]}" for x in arms],
               ft=[f"udp:{x.address[0]}:{x.address[1]}" for x in wrists],
               mocap=None if mocap is None else f"udp:{mocap.address[0]}:{mocap.address[1]}")


def _told(first: dict) -> str:
    """The run's last STATUSTEXT for a failed mission (one STATUSTEXT: 50 bytes): its class, or
    for a GCS command what it did ("mission failed: aborted by the GCS at t = 7.02 s")."""
    if first["class"] != "commanded":
        return f"mission failed: {first['class']}"
    reason = first["reason"]
    for text in (f"mission failed: {reason}", f"mission failed: {reason.replace(' by the GCS', ' (GCS)')}"):
        if len(text.encode()) <= STATUSTEXT_MAX:
            return text
    return "mission failed: ended by a GCS command"


class _Throttled:
    """Prints a waiting notice when whom or what it waits for changes, else every `every_s`."""

    def __init__(self, say, every_s: float = 10.0) -> None:
        self.say, self.every_s = say, every_s
        self._last, self._t = "", -float("inf")

    def __call__(self, text: str) -> None:
        who = text.split(" more ", 1)[-1]  # "waiting 58 s more for ARM from sysid 5" -> what and whom
        now = time.monotonic()
        if who != self._last or now - self._t >= self.every_s:
            self.say(text)
            self._last, self._t = who, now


if __name__ == "__main__":
    sys.exit(main())
