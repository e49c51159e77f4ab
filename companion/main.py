"""Companion process of one AM: runs the paper's controller against a flight controller
(here the SITL simulator) over MAVLink, in lockstep.

    companion --sysid 4 [--sim udpout:127.0.0.1:14550] [--config configs/scenarios/two_am_comp_attitude.toml]

--sim takes mavutil's endpoint forms: udpout:HOST:PORT, udpin:HOST:PORT, tcp:HOST:PORT,
tcpin:HOST:PORT or a serial device DEVICE[:BAUD] (a flight controller on /dev/ttyUSB0).
The older --sim udp:HOST:PORT still means "send to" (mavutil's udp: listens): it warns.

It loads its own [[am]] entry of the scenario, computes its own references (approach,
grasp, lift, hover, timed on simulation time) and never sees another AM's state. It
checks that the simulator runs the same scenario (AM_SCENARIO.scenario_id), arms, answers
every sensor frame with a setpoint (torque mode: AM_TORQUE_SETPOINT; attitude mode:
SET_ATTITUDE_TARGET and AM_JOINT_TORQUE_SETPOINT, docs/flight_controller.md), and exits 0
when the simulator ends the run or on SIGINT/SIGTERM. Exit codes: 2 bad configuration or
arguments (an --outcome or --tlog that cannot be written is found before flying), 3 scenario
mismatch, 1 link failure (an --sim endpoint that cannot be opened, a simulator that does not
answer, a lost link) or an outcome that could not be written at the end.
"""
from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path

from amcore import cliargs
from amcore.config import DEFAULT_SCENARIO, ConfigError, load_scenario, scenario_id
from amcore.mission import ObjectPose
from amlink import signing
from amlink.client import EndpointOpenError
from amlink.codec import mav
from amlink.endpoint import COMPANION_SIM, COMPANION_SIM_FORMS, EndpointError, as_destination, parse_endpoint
from amlink.errors import LinkError, SimulatorUnreachableError
from amlink.lockstep import CompanionClient
from amlink.tlog import TlogError, TlogWriter
from amruntime import jitcache, procstats
from telemetry.publisher import TelemetryPublisher
from telemetry.session import TelemetryConfigError, add_zenoh_arguments, options_from_args
from telemetry.wiring import CompanionTelemetry

from .pilot import Pilot

# attitude mode: what the arm law reads every control step, requested at the control rate
# (SET_MESSAGE_INTERVAL) as PX4 streams them slower by default (docs/flight_controller.md, "Rates")
STREAMS_AT_CONTROL_RATE = (mav.MAVLINK_MSG_ID_ODOMETRY, mav.MAVLINK_MSG_ID_ATTITUDE_TARGET,
                           mav.MAVLINK_MSG_ID_AM_JOINT_STATE)



class _Stop(Exception):
    pass


def _on_signal(signum, _frame):
    """The first SIGINT or SIGTERM stops the companion; later ones are ignored, so that its
    end (the link closed, the outcome written) is not cut short by a second Ctrl-C."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    raise _Stop(signal.Signals(signum).name)


def main(argv: list[str] | None = None) -> int:
    ap = cliargs.ArgumentParser(prog="companion", description=" ".join(__doc__.split("\n\n")[0].split()),
                                epilog=cliargs.exit_codes(0, 1, 2, 3, c0="the run ended (the simulator ended it, or "
                                                          "SIGINT or SIGTERM stopped the companion)"))
    ap.add_argument("--sysid", type=cliargs.number(2, 255, integer=True), required=True, help="this AM's MAVLink system id (its [[am]] entry)")
    ap.add_argument("--sim", default=COMPANION_SIM, metavar="ENDPOINT",
                    help=f"the flight controller (simulator) endpoint (default {COMPANION_SIM}); mavutil's forms: "
                         f"udpout:, udpin:, tcp:, tcpin:HOST:PORT or a serial DEVICE[:BAUD]; udp:HOST:PORT is "
                         f"read as udpout: (as before) with a warning")
    ap.add_argument("--config", type=Path, default=DEFAULT_SCENARIO, help="scenario TOML")
    ap.add_argument("--connect-timeout", type=cliargs.seconds, default=30.0, help="seconds to wait for the simulator")
    ap.add_argument("--frame-timeout", type=cliargs.seconds, default=10.0, help="seconds without a sensor frame = link lost")
    ap.add_argument("--key-file", type=Path, default=None,
                    help="signing master key (64 hex digits); overrides [link].key_file of the scenario")
    ap.add_argument("--outcome", type=cliargs.output_file, default=None, help="write a per-phase error summary (JSON) here")
    ap.add_argument("--telemetry-every", type=cliargs.count, default=1, help="publish the controller state every N steps")
    ap.add_argument("--tlog", type=cliargs.output_file, default=None,
                    help="write every MAVLink frame of the link to this .tlog (stock tools read it)")
    ap.add_argument("--clock", choices=("lockstep", "wall"), default="lockstep",
                    help="lockstep: the simulator's step-numbered lockstep (reproducible; default). wall: a PX4 "
                         "(the free-running simulator's, or a real one) in OFFBOARD over standard MAVLink on the "
                         "wall clock, the arm over Dynamixel Protocol 2.0 and the wrist F/T over Net F/T RDT "
                         "(docs/freerun.md)")
    ap.add_argument("--fc", default=None, metavar="ENDPOINT",
                    help="--clock wall: the autopilot (default udpin:0.0.0.0:14540+i, PX4 SITL's onboard port of this "
                         "AM's place i in [[am]]); mavutil's forms, e.g. /dev/ttyACM0:921600")
    ap.add_argument("--fc-key-file", type=Path, default=None, metavar="FILE",
                    help="--clock wall: the autopilot link's signing passphrase (SHA-256 of it, as MAVProxy's and "
                         "simulator --onboard-key-file); default unsigned, as PX4's ports")
    ap.add_argument("--arm", default=None, metavar="ENDPOINT",
                    help="--clock wall: the servo bus, a serial DEVICE[:BAUD] (/dev/ttyUSB0:4000000) or tcp:HOST:PORT "
                         "(default tcp:127.0.0.1:7200+i, the simulator's)")
    ap.add_argument("--ft", default=None, metavar="ENDPOINT",
                    help="--clock wall: the Net F/T sensor, udp:HOST:PORT (default udp:127.0.0.1:49152+i); 'none': "
                         "no wrist sensor (a zero wrench)")
    ap.add_argument("--mocap", default=None, metavar="ENDPOINT",
                    help="--clock wall: the object's pose stream, when the scenario plans from it (default "
                         "udp:127.0.0.1:7400)")
    ap.add_argument("--instance", type=cliargs.number(0, 1000, integer=True), default=0, metavar="N",
                    help="--clock wall: the simulator's vehicles are PX4 SITL instances N+i (simulator --instance N); "
                         "shifts every default endpoint by N")
    ap.add_argument("--mission-start", type=cliargs.seconds, default=None, metavar="S",
                    help="--clock wall: the autopilot's boot time [s] at which the mission's t = 0 comes (a team on "
                         "one clock starts together); default: 3 s of take-off after OFFBOARD is engaged")
    ap.add_argument("--type-mask", type=cliargs.number(0, 255, integer=True), default=None,
                    help="--clock wall: SET_ATTITUDE_TARGET.type_mask (default 0: attitude, body rates and thrust; "
                         "7 ignores the rates, as MAVSDK's set_attitude)")
    ap.add_argument("--no-predict", action="store_true",
                    help="--clock wall: use each sample as it is, without carrying it over its age")
    add_zenoh_arguments(ap, role="publisher")
    a = ap.parse_args(argv)
    tag = f"companion[{a.sysid}]"
    try:
        sim = parse_endpoint(a.sim)
        if sim.alias == "udp":  # read as udpout: a destination
            sim = as_destination(sim, a.sim)
    except EndpointError as exc:
        print(f"{tag}: error: --sim: endpoint {exc.text!r}: {exc.why}\n{COMPANION_SIM_FORMS}", file=sys.stderr)
        return 2
    if sim.alias == "udp":
        print(f"{tag}: warning: --sim {a.sim} is read as udpout:{a.sim.split(':', 1)[1]} (send to the simulator), "
              f"as it always was here; in mavutil's convention udp: means udpin: (listen). Write udpout: "
              f"(or udpin: to wait for a flight controller that sends to this port)", file=sys.stderr)
    try:
        spec = load_scenario(a.config)
        spec.am(a.sysid)  # ConfigError if this sysid is not in the scenario
        keys, warning = signing.keys_for_run(spec, a.key_file)
    except (ConfigError, signing.SigningKeyError) as exc:
        print(f"{tag}: error: {exc}", file=sys.stderr)
        return 2
    if warning and a.clock == "lockstep":  # ([link]'s keys are the lockstep's protocol's)
        print(f"{tag}: warning: {warning}", file=sys.stderr)
    pilot = Pilot(spec, a.sysid)
    try:
        tele = TelemetryPublisher(options_from_args(a), name=f"am{a.sysid}")
        am_tele = CompanionTelemetry(tele, a.sysid, every=max(1, a.telemetry_every))
    except (TelemetryConfigError, ValueError) as exc:
        print(f"{tag}: error: telemetry: {exc}", file=sys.stderr)
        return 2
    my_id = scenario_id(spec)

    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)
    tlog = TlogWriter(a.tlog) if a.tlog is not None else None
    try:
        client = CompanionClient(a.sysid, sim, signing_key=None if keys is None else keys[a.sysid], tlog=tlog)
    except ValueError as exc:
        print(f"{tag}: error: --sim: {exc}", file=sys.stderr)
        return 2
    # the output files, before flying: a folder that cannot take them would lose the run's record
    try:
        _check_writable(a.outcome)
    except OSError as exc:
        print(f"{tag}: error: --outcome {a.outcome}: cannot write there: {exc.strerror or exc}", file=sys.stderr)
        return 2
    if tlog is not None:
        try:
            tlog.open()
        except TlogError as exc:
            print(f"{tag}: error: --tlog {a.tlog}: cannot write there: {exc.strerror}", file=sys.stderr)
            return 2
    # every argument checked: compile the law (the first run on this machine) or load it
    try:
        jit = jitcache.warm(pilot.warm_up)
    except _Stop as stop:
        print(f"{tag}: stopped ({stop}) while preparing the control law", file=sys.stderr)
        if tlog is not None:
            tlog.close()
        return 1
    if jit.compiled:
        print(f"{tag}: compiled the control law in {jit.seconds:.1f} s (once per machine: cached in "
              f"{jitcache.cache_dir()})", file=sys.stderr, flush=True)
    if a.clock == "wall":
        from .wallmain import run_wall  # the wall-clock companion's wiring
        try:
            return run_wall(a, spec, pilot, tele, am_tele, keys, tlog, tag, _Stop)
        finally:
            if tlog is not None:
                tlog.close()
    why = "simulator ended the run"
    cpu = procstats.CpuMeter()
    tele.open()  # never blocks: publishes are queued, dropped and counted while nobody listens
    try:
        if not tele.await_recorder(tele.keys.controller(a.sysid), a.telemetry_wait):
            print(f"{tag}: warning: telemetry: no subscriber (recorder) after {a.telemetry_wait:g} s; "
                  f"publishing anyway", file=sys.stderr)
        info = client.connect(timeout_s=a.connect_timeout)
        if info.scenario_id != my_id or info.name != spec.name:
            same = " (same name, different content: the files differ between hosts or were edited)" \
                if info.name == spec.name else ""
            print(f"{tag}: error: the simulator runs scenario '{info.name}' (id {info.scenario_id}), this companion "
                  f"was started with '{spec.name}' (id {my_id}, {a.config}){same}; start both with the same "
                  f"scenario and vehicle files", file=sys.stderr)
            return 3
        if spec.mission.object_pose == "mocap":  # plan the approach from the simulator's measured object
            if client.object_pose is None:
                print(f"{tag}: error: the scenario plans from the measured object ([mission].object_pose = "
                      f"\"mocap\") and the simulator sent none (AM_OBJECT_POSE)", file=sys.stderr)
                return 3
            pilot = Pilot(spec, a.sysid, model=pilot.model, object_pose=ObjectPose(*client.object_pose))
        client.arm(timeout_s=5.0)
        if spec.vehicle.flight_controller.mode == "attitude":  # PX4's onboard defaults are slower (10-30 Hz)
            for msgid in STREAMS_AT_CONTROL_RATE:
                client.set_message_interval(msgid, 1e6 / spec.control_rate_hz, timeout_s=5.0)
        print(f"{tag}: connected to {a.sim}, scenario '{info.name}', armed", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        cpu.start()
        waited = []

        def simulator_waits(text: str) -> None:  # the simulator is still gathering the other companions
            if not waited or waited[-1].split(" more ", 1)[-1] != text.split(" more ", 1)[-1]:
                print(f"{tag}: the simulator is {text}", file=sys.stderr, flush=True)
            waited.append(text)

        while True:
            frame = client.recv_frame(timeout_s=a.frame_timeout, on_waiting=simulator_waits)
            if frame is None:
                break
            sp, att, res = pilot.command(frame)
            client.send_setpoint(sp, att)  # the simulator waits for this; bookkeeping comes after
            pilot.record(frame.time_s, res)
            am_tele.step(frame.time_s, pilot.mission.phase(frame.time_s), res)
        wall = time.perf_counter() - t0
    except _Stop as stop:
        why = f"stopped by {stop}"
        wall = None
    except EndpointOpenError as exc:  # nothing was sent: no hint about the simulator or its keys
        print(f"{tag}: error: --sim: {exc}", file=sys.stderr)
        _save(tag, a.outcome, pilot.summary(error=str(exc)))
        return 1
    except LinkError as exc:
        hint = ""
        if isinstance(exc, SimulatorUnreachableError) and exc.listening:
            hint = (f" (is the simulator started with --bind udpout: or tcp: toward this host and port"
                    f"{', and the same signing key' if keys is not None else ''}?)")
        elif isinstance(exc, SimulatorUnreachableError) and keys is not None:
            hint = " (is it running, and does it use the same signing key? unsigned or wrongly signed packets are dropped)"
        print(f"{tag}: error: {exc}{hint}", file=sys.stderr)
        _save(tag, a.outcome, pilot.summary(error=str(exc)))
        return 1
    finally:
        client.close()
        tele.close()
        if tlog is not None:
            tlog.close()
    failure = [text for sev, text in client.status_texts if sev <= 3]  # MAV_SEVERITY_ERROR or worse
    if failure:
        print(f"{tag}: error: the simulator ended the run: {failure[-1]}", file=sys.stderr)
        _save(tag, a.outcome, pilot.summary(error=failure[-1]))
        return 1
    summary = pilot.summary()
    cpu_s = cpu.seconds()
    summary["process"] = {"memory_mib": procstats.memory_mib(), "cpu_s": cpu_s,
                          "cpu_us_per_step": 1e6 * cpu_s / pilot.steps if cpu_s is not None and pilot.steps else None,
                          "main_thread": cpu.main_thread()}
    saved = _save(tag, a.outcome, summary)
    steps = pilot.steps
    rate = f", {steps / wall:.0f} steps/s" if wall else ""
    print(f"{tag}: {why} after {steps} steps{rate}", file=sys.stderr)
    return 0 if saved else 1


def _check_writable(path: Path | None) -> None:
    """The outcome file's folder exists (it is created) and takes the file; OSError if not."""
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    probe = path.with_suffix(".tmp")  # the file _write writes first
    probe.touch()
    probe.unlink()


def _write(path: Path, summary: dict) -> None:
    """The outcome as JSON, replaced at once (a reader never sees half of it); OSError if it cannot be."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(summary, indent=1))
    tmp.replace(path)


def _save(tag: str, path: Path | None, summary: dict) -> bool:
    """Write the outcome if asked for; False, saying why, if it could not be written."""
    if path is None:
        return True
    try:
        _write(path, summary)
    except OSError as exc:  # the folder went away or filled up during the run
        print(f"{tag}: error: --outcome {path}: cannot write it: {exc.strerror or exc}", file=sys.stderr)
        return False
    return True


if __name__ == "__main__":
    sys.exit(main())
