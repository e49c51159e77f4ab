"""SITL simulator process: the PyBullet world of a scenario and every AM's flight-controller
emulation, stepped in lockstep with one companion process per AM over MAVLink/UDP.

    simulator [--config configs/scenarios/two_am_comp.toml] [--bind udp:127.0.0.1:14550]

Start-up waits for every [[am]] sysid's HEARTBEAT and ARM; then each control step k it sends
every companion its sensor frame (ODOMETRY, AM_JOINT_STATE, AM_WRENCH, AM_SIM_STEP), waits for
all N setpoints answering step k (the N exchanges run concurrently) and applies them through
the flight controller (torque mode: the rotor mixer; attitude mode: the emulated autopilot)
and the joint limits (saturation is counted and logged); it steps physics every step.
The run folder gets outcome.json (the physical outcome from ground truth, see
simulator.outcome). Exit codes: 0 run complete, 2 bad configuration, 1 link failure
(a missing or silent companion, named), 130 interrupted.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path


from amcore.config import DEFAULT_SCENARIO, ConfigError, load_scenario, scenario_id
from amlink import signing
from amlink.errors import LinkError
from amlink.limits import SetpointLimits
from amlink.lockstep import SimServer
from amlink.types import ScenarioInfo

from telemetry.publisher import TelemetryPublisher
from telemetry.session import TelemetryConfigError, add_zenoh_arguments, options_from_args
from telemetry.wiring import SimulatorTelemetry

from .core import SitlCore



class _Stop(Exception):
    pass


class _BindError(Exception):
    pass


def _on_signal(signum, _frame):
    raise _Stop(signal.Signals(signum).name)


class Progress:
    """Progress to stderr as a bar (tty) or to stdout as JSON lines (for am-run)."""

    def __init__(self, mode: str, duration_s: float) -> None:
        self.mode, self.duration = mode, duration_s
        self.t_wall0 = time.perf_counter()
        self._next = 0.0

    def event(self, **kw) -> None:
        if self.mode == "jsonl":
            print(json.dumps(kw), flush=True)

    def update(self, t: float, force: bool = False) -> None:
        now = time.perf_counter()
        if now < self._next and not force:
            return
        self._next = now + 0.5
        wall = now - self.t_wall0
        rtf = t / wall if wall > 0 else 0.0
        if self.mode == "jsonl":
            self.event(event="progress", t=round(t, 3), duration=self.duration, rtf=round(rtf, 3))
        elif self.mode == "bar":
            frac = min(1.0, t / self.duration)
            bar = "#" * int(30 * frac) + "." * (30 - int(30 * frac))
            print(f"\r[{bar}] sim {t:6.2f}/{self.duration:.1f} s  {rtf:5.2f}x real time", end="", file=sys.stderr,
                  flush=True)
            if force:
                print(file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="simulator", description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--config", type=Path, default=DEFAULT_SCENARIO, help="scenario TOML")
    ap.add_argument("--bind", default="udp:127.0.0.1:14550",
                    help="MAVLink endpoint udp:HOST:PORT (0.0.0.0 to serve other hosts, port 0 = any free port)")
    ap.add_argument("--run-dir", type=Path, default=None, help="folder for outcome.json (default runs/<name>-<time>)")
    ap.add_argument("--duration", type=float, default=None, help="override [scenario].duration_s")
    ap.add_argument("--peer-timeout", type=float, default=60.0, help="seconds to wait for every companion at start")
    ap.add_argument("--step-timeout", type=float, default=5.0,
                    help="seconds a companion may stay silent before its vehicle goes to failsafe")
    ap.add_argument("--key-file", type=Path, default=None,
                    help="signing master key (64 hex digits); overrides [link].key_file of the scenario")
    ap.add_argument("--progress", choices=("bar", "jsonl", "none"), default=None,
                    help="progress display (default: bar on a terminal, else none)")
    add_zenoh_arguments(ap, role="publisher")
    a = ap.parse_args(argv)
    try:
        spec = load_scenario(a.config)
        keys, warning = signing.keys_for_run(spec, a.key_file)
    except (ConfigError, signing.SigningKeyError) as exc:
        print(f"simulator: error: {exc}", file=sys.stderr)
        return 2
    if warning:
        print(f"simulator: warning: {warning}", file=sys.stderr)
    duration = spec.duration_s if a.duration is None else a.duration
    if not duration > 0:
        print(f"simulator: error: --duration must be > 0, got {duration}", file=sys.stderr)
        return 2
    mode = a.progress or ("bar" if sys.stderr.isatty() else "none")
    run_dir = a.run_dir or Path("runs") / f"{spec.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    sysids = [am.sysid for am in spec.ams]
    info = ScenarioInfo(scenario_id=scenario_id(spec), n_am=len(sysids), name=spec.name, seed=spec.seed,
                        rate_hz=spec.rate_hz)
    progress = Progress(mode, duration)
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)

    try:
        tele = TelemetryPublisher(options_from_args(a), name="simulator")
    except (TelemetryConfigError, ValueError) as exc:
        print(f"simulator: error: telemetry: {exc}", file=sys.stderr)
        return 2
    sim_tele = SimulatorTelemetry(tele, spec)

    def log(msg: str) -> None:
        print(f"simulator: {msg}", file=sys.stderr, flush=True)
        sim_tele.fault(core.time_s, msg, level="warning")

    core = SitlCore(spec, log=log, on_truth=sim_tele.truth)
    v = spec.vehicle
    limits = SetpointLimits.for_vehicle(v.rotors.count * v.rotors.thrust_max_n, max(v.joint_torque_max_nm), v.n_joints)
    try:
        server = SimServer(a.bind, sysids=sysids, scenario=info, timeout_s=a.step_timeout, signing_keys=keys,
                           limits=limits)
    except ValueError as exc:
        print(f"simulator: error: --bind: {exc}", file=sys.stderr)
        return 2
    status, code, k = "run complete", 0, 0
    completed = False  # the run reached its end (a vehicle in failsafe makes the code 1, not the run an error)
    told = status  # what the companions hear (STATUSTEXT carries 50 bytes)
    n_steps = int(round(duration * spec.rate_hz))
    result: dict = {}
    tele.open()
    try:
        core.connect()
        try:
            host, port = server.open()
        except OSError as exc:
            raise _BindError(f"cannot listen on {a.bind}: {exc}") from None
        progress.event(event="ready", bind=f"udp:{host}:{port}", scenario=spec.name, sysids=sysids)
        print(f"simulator: '{spec.name}' listening on udp:{host}:{port}, waiting for sysids {sysids}",
              file=sys.stderr, flush=True)
        server.wait_for_peers(a.peer_timeout)
        server.wait_for_armed(a.peer_timeout)
        if not tele.await_recorder(tele.keys.sim_event, a.telemetry_wait):
            print(f"simulator: warning: telemetry: no subscriber (recorder) after {a.telemetry_wait:g} s; "
                  f"publishing anyway", file=sys.stderr, flush=True)
        progress.t_wall0 = time.perf_counter()
        sim_tele.start(core.time_s)
        for k in range(n_steps):
            if core.is_control_step(k):
                # each frame leaves as soon as it is read; each setpoint is applied as it arrives
                setpoints = server.exchange(core.iter_frames(k), partial=True, while_waiting=core.observe,
                                            on_setpoint=core.on_setpoint)
                core.actuate(k, setpoints, server.lost_peers)
            else:  # between the companions' control steps the flight controllers fly on their own
                core.hold(k, server.lost_peers)
            core.step()
            progress.update(core.time_s)
        progress.update(core.time_s, force=True)
        k = n_steps
        result = core.finish()
        if core.failsafes:
            lost = ", ".join(map(str, sorted(core.failsafes)))
            status, code = f"run complete; in failsafe at the end: sysid {lost}", 1
            told, completed = f"run complete; failsafe: sysid {lost}", True
    except _Stop as stop:
        status, code = f"interrupted by {stop}", 130
        told = status
    except _BindError as exc:
        status, code, told = str(exc), 1, str(exc)
        print(f"simulator: error: {exc}", file=sys.stderr)
    except LinkError as exc:
        status, code, told = f"link failure: {exc}", 1, str(exc)
        print(f"\nsimulator: error: {exc}", file=sys.stderr)
    finally:
        sim_tele.end(core.time_s, status, level="info" if code == 0 else "error")
        server.close(told, error=code != 0 and not completed)
        if not result:
            try:
                result = core.finish()
            except Exception:  # the world never connected
                result = {}
        core.close()
        tele.close()
    wall = time.perf_counter() - progress.t_wall0
    sim_time = k * spec.dt_s
    result = {"scenario": spec.name, "scenario_id": info.scenario_id, "status": status, "exit_code": code,
              "steps": k, "sim_time_s": sim_time, "wall_s": wall,
              "real_time_factor": (sim_time / wall) if wall > 0 else None, "link": vars(server.stats), **result}
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "outcome.json").write_text(json.dumps(result, indent=1))
    progress.event(event="done", status=status, exit_code=code, outcome=str(run_dir / "outcome.json"))
    print(f"simulator: {status}; {sim_time:.3f} s simulated in {wall:.1f} s; outcome in {run_dir / 'outcome.json'}",
          file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
