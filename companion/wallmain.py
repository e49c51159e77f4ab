"""The process side of `companion --clock wall` (companion.main hands over to `run_wall` once the
arguments, the scenario and the control law are ready): endpoints, signals, the summary."""
from __future__ import annotations

import json
import signal
import sys
from pathlib import Path

from amcore.config import ConfigError
from amlink import signing
from amlink.endpoint import EndpointError, parse_endpoint
from amlink.px4link import LinkOpenError
from amruntime import procstats

from .devices import DeviceError
from .devices.arm import parse_arm_endpoint
from .devices.netft import parse_ft_endpoint
from .pilot import Pilot
from .wallrun import WallRun, default_endpoints, fly


def _endpoints(a, index: int) -> dict[str, str]:
    """The defaults for place `index`, overridden by --fc/--arm/--ft/--mocap; ValueError naming a bad one."""
    eps = default_endpoints(index, getattr(a, "instance", 0))
    for key in ("fc", "arm", "ft", "mocap"):
        given = getattr(a, key)
        if given is not None:
            eps[key] = given
    try:
        parse_endpoint(eps["fc"])
    except EndpointError as exc:
        raise ValueError(f"--fc {eps['fc']!r}: {exc.why}") from None
    try:
        parse_arm_endpoint(eps["arm"])
    except (ValueError, EndpointError) as exc:
        raise ValueError(f"--arm {eps['arm']!r}: {exc}") from None
    if eps["ft"] != "none":
        parse_ft_endpoint(eps["ft"])  # ValueError naming --ft
    return eps


def run_wall(a, spec, pilot: Pilot, tele, am_tele, keys, tlog, tag: str, _stop_exc) -> int:
    say = lambda text: print(f"{tag}: {text}", file=sys.stderr, flush=True)  # noqa: E731
    index = [am.sysid for am in spec.ams].index(a.sysid)
    if spec.vehicle.flight_controller.mode != "attitude":
        say(f"error: --clock wall flies a stock autopilot (SET_ATTITUDE_TARGET); scenario '{spec.name}' is in "
            f"{spec.vehicle.flight_controller.mode} mode: use an *_attitude scenario")
        return 2
    try:
        eps = _endpoints(a, index)
    except (ValueError, ConfigError) as exc:
        say(f"error: {exc}")
        return 2
    try:  # the autopilot link's own signing (PX4's ports are unsigned unless set up)
        fc_key = signing.read_gcs_key_file(a.fc_key_file, "--fc-key-file") if getattr(a, "fc_key_file", None) is not None else None
    except signing.SigningKeyError as exc:
        say(f"error: {exc}")
        return 2
    stopping: list[str] = []

    def on_signal(signum, _frame):
        """The first SIGINT or SIGTERM ends the loop after its step; later ones are ignored (a
        supervisor's second signal, even during the interpreter's exit, does not cut the end short)."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
        if not stopping:
            stopping.append(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    # PX4's onboard port is unsigned by default (MAVLink signing is set per link); the lockstep's
    # [link] keys are for the simulator's own protocol
    run = WallRun(spec, a.sysid, eps, signing_key=fc_key, tlog=tlog, type_mask=a.type_mask, log=say)
    say(f"wall clock: autopilot {eps['fc']}, servo bus {eps['arm']}, F/T {eps['ft']}"
        + (f", motion capture {eps['mocap']}" if run.mocap is not None else ""))
    cpu = procstats.CpuMeter()
    tele.open()
    result = None
    try:
        pose = run.open(a.connect_timeout)
        if pose is not None:  # plan the approach from the measured object
            pilot = Pilot(spec, a.sysid, model=pilot.model, object_pose=pose)
        cpu.start()
        def publish(t, phase, res):  # the log is the mission's, from its t = 0 (the take-off is in outcome.json)
            if t >= 0.0:
                am_tele.step(t, phase, res)

        result = fly(run, pilot, on_step=publish, stop=lambda: bool(stopping), predict=not a.no_predict,
                     mission_start_s=a.mission_start, link_timeout_s=a.frame_timeout, log=say,
                     on_stats=lambda t, stats: am_tele.loop_stats(max(t, 0.0), stats))
    except (DeviceError, LinkOpenError, OSError) as exc:
        say(f"error: {exc}")
        _save(say, a.outcome, pilot.summary(error=str(exc)))
        return 1
    finally:
        run.close()
        tele.close()
    why = f"stopped by {stopping[0]}" if stopping and result.why == "stopped" else result.why
    summary = pilot.summary(error=None if result.code == 0 else why)
    cpu_s = cpu.seconds()
    summary["clock"] = "wall"
    summary["ended"] = why
    summary["engaged_fc_s"] = None if result.engaged_fc_us is None else result.engaged_fc_us * 1e-6
    summary["held_steps"] = result.held_steps
    summary["loop"] = result.stats
    summary["endpoints"] = eps
    summary["process"] = {"memory_mib": procstats.memory_mib(), "cpu_s": cpu_s,
                          "cpu_us_per_step": 1e6 * cpu_s / result.steps if cpu_s is not None and result.steps else None,
                          "main_thread": cpu.main_thread()}
    saved = _save(say, a.outcome, summary)
    st = result.stats
    p = st.get("period_ms", {})
    say(f"{why} after {result.steps} steps; period p50 {p.get('p50')} ms, p99 {p.get('p99')} ms, max {p.get('max')} ms; "
        f"{st.get('deadline_misses')} deadline misses, worst lateness {st.get('worst_lateness_ms')} ms")
    return result.code if saved else 1


def _save(say, path: Path | None, summary: dict) -> bool:
    if path is None:
        return True
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(summary, indent=1, default=float))
        tmp.replace(path)
    except OSError as exc:
        say(f"error: --outcome {path}: cannot write it: {exc.strerror or exc}")
        return False
    return True
