"""SITL simulator process: the PyBullet world of a scenario and every AM's flight-controller
emulation, stepped in lockstep with one companion process per AM over MAVLink/UDP.

    simulator [--config configs/scenarios/two_am_comp.toml] [--bind udp:127.0.0.1:14550]

Start-up waits for every [[am]] sysid's HEARTBEAT and ARM; then each step k it sends every
companion its sensor frame (ODOMETRY, AM_JOINT_STATE, AM_WRENCH, AM_SIM_STEP), waits for
all N setpoints answering step k (the N exchanges run concurrently), applies them through
the rotor mixer and joint limits (saturation is counted and logged) and steps physics.
The run folder gets outcome.json (the physical outcome from ground truth, see
simulator.outcome). Exit codes: 0 run complete, 2 bad configuration, 1 link failure
(a missing or silent companion, named), 130 interrupted.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import signal
import sys
import time
from pathlib import Path

import numpy as np

from amcore.config import ConfigError, load_scenario, scenario_id
from amcore.mission import am_mission
from amcore.model import build_model
from amcore.so3 import R_to_quat_wxyz
from amlink import signing
from amlink.errors import LinkError
from amlink.impair import ImpairedLink, LinkImpairment
from amlink.limits import SetpointLimits
from amlink.lockstep import SimServer
from amlink.types import ScenarioInfo, SensorFrame

from .failsafe import Failsafe
from .outcome import RunOutcome
from .world import World

DEFAULT_SCENARIO = Path(__file__).resolve().parents[1] / "configs" / "scenarios" / "two_am_comp.toml"
TRUTH_EVERY = 10  # ground-truth sample period for the outcome [steps]


class _Stop(Exception):
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
    ap = argparse.ArgumentParser(prog="simulator", description=__doc__.splitlines()[0])
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
    model = build_model(spec.vehicle)
    initial = {am.sysid: am_mission(spec, am, model).initial_state() for am in spec.ams}
    sysids = [am.sysid for am in spec.ams]
    info = ScenarioInfo(scenario_id=scenario_id(spec), n_am=len(sysids), name=spec.name, seed=spec.seed,
                        rate_hz=spec.rate_hz)
    ms = spec.mission
    outcome = RunOutcome(sysids, (ms.grasp_end_s + ms.lift_move_s + 1.0, ms.hover_end_s), slip_from_s=ms.grasp_end_s)
    progress = Progress(mode, duration)
    digest = hashlib.sha256()
    signal.signal(signal.SIGTERM, _on_signal)
    signal.signal(signal.SIGINT, _on_signal)

    world = World(spec, initial)
    v = spec.vehicle
    limits = SetpointLimits.for_vehicle(v.rotors.count * v.rotors.thrust_max_n, max(v.joint_torque_max_nm), v.n_joints)
    server = SimServer(a.bind, sysids=sysids, scenario=info, timeout_s=a.step_timeout, signing_keys=keys,
                       limits=limits)
    impairment = LinkImpairment.for_scenario(spec)
    fc_links = {s: ImpairedLink(impairment, stream=s) for s in sysids}  # what each flight controller receives
    status, code, k = "run complete", 0, 0
    events: list[dict] = []
    completed = False  # the run reached its end (a vehicle in failsafe makes the code 1, not the run an error)
    failsafes: dict[int, Failsafe] = {}
    told = status  # what the companions hear (STATUSTEXT carries 50 bytes)
    n_steps = int(round(duration * spec.rate_hz))
    try:
        world.connect()
        host, port = server.open()
        progress.event(event="ready", bind=f"udp:{host}:{port}", scenario=spec.name, sysids=sysids)
        print(f"simulator: '{spec.name}' listening on udp:{host}:{port}, waiting for sysids {sysids}",
              file=sys.stderr, flush=True)
        server.wait_for_peers(a.peer_timeout)
        server.wait_for_armed(a.peer_timeout)
        progress.t_wall0 = time.perf_counter()
        wrenches: dict[int, np.ndarray] = {}
        for k in range(n_steps):
            t = world.time_s
            frames = {}
            for s in sysids:
                st = world.state(s)
                wrenches[s] = world.wrench_ee(s)
                frames[s] = SensorFrame(step=k, time_s=t, p_WB=st.p_WB, quat_WB_wxyz=R_to_quat_wxyz(st.R_WB),
                                        v_B=st.v_B, w_B=st.w_B, q=st.q, qdot=st.qdot, wrench_E=wrenches[s])
                f = frames[s]
                digest.update(f.p_WB.tobytes() + f.quat_WB_wxyz.tobytes() + f.q.tobytes() + f.wrench_E.tobytes())
            if k % TRUTH_EVERY == 0:
                outcome.add(world.ground_truth(), wrenches)
            setpoints = server.exchange(frames, partial=True)
            lost = server.lost_peers
            for s in sysids:
                if s in lost or (s in failsafes and s not in setpoints):
                    if s not in failsafes:
                        failsafes[s] = Failsafe(model, world.state(s), t)
                        events.append({"t": t, "sysid": s, "event": "lost", "failsafe": "hold, then land"})
                        print(f"simulator: t={t:.3f} s sysid {s}: companion silent for {a.step_timeout:g} s; "
                              f"flight controller failsafe: hold, then land", file=sys.stderr, flush=True)
                    c = failsafes[s].command(t, world.state(s))
                    world.apply(s, c.thrust_n, c.tau_B_nm, c.tau_q_nm)
                    continue
                if s in failsafes:  # the companion is back (rejoined and armed): it flies again
                    del failsafes[s]
                    events.append({"t": t, "sysid": s, "event": "rejoined"})
                    print(f"simulator: t={t:.3f} s sysid {s}: companion back, failsafe ended", file=sys.stderr,
                          flush=True)
                sp = fc_links[s].step(k, setpoints.get(s))
                if sp is None:  # nothing has reached this flight controller yet: keep the last command
                    continue
                rep = world.apply(s, sp.thrust_n, sp.tau_B_nm, sp.tau_q_nm)
                if rep.saturated and outcome.saturation(s, t):
                    print(f"simulator: t={t:.3f} s sysid {s}: command saturated (thrust {sp.thrust_n:.2f} N, "
                          f"tau_B {np.round(sp.tau_B_nm, 3)}, tau_q {np.round(sp.tau_q_nm, 3)}); "
                          f"counted in outcome.json, further ones not printed", file=sys.stderr, flush=True)
            world.step()
            progress.update(world.time_s)
        outcome.add(world.ground_truth(), {s: world.wrench_ee(s) for s in sysids})
        progress.update(world.time_s, force=True)
        if failsafes:
            status, code = f"run complete; in failsafe at the end: sysid {', '.join(map(str, sorted(failsafes)))}", 1
            told = f"run complete; failsafe: sysid {', '.join(map(str, sorted(failsafes)))}"
            completed = True
    except _Stop as stop:
        status, code = f"interrupted by {stop}", 130
        told = status
    except LinkError as exc:
        status, code, told = f"link failure: {exc}", 1, str(exc)
        print(f"\nsimulator: error: {exc}", file=sys.stderr)
    finally:
        server.close(told, error=code != 0 and not completed)
        world.close()
    wall = time.perf_counter() - progress.t_wall0
    result = {"scenario": spec.name, "scenario_id": info.scenario_id, "status": status, "exit_code": code,
              "steps": k + 1 if code == 0 else k, "sim_time_s": world.time_s if world else None, "wall_s": wall,
              "real_time_factor": (world.time_s / wall) if wall > 0 else None,
              "state_digest": digest.hexdigest(), "link": vars(server.stats), "events": events,
              "failsafe_at_end": sorted(failsafes), **outcome.to_dict()}
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "outcome.json").write_text(json.dumps(result, indent=1))
    progress.event(event="done", status=status, exit_code=code, outcome=str(run_dir / "outcome.json"))
    print(f"simulator: {status}; {world.time_s:.3f} s simulated in {wall:.1f} s; outcome in {run_dir / 'outcome.json'}",
          file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
