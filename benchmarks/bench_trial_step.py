"""Where a campaign trial's physics step goes: CPU time per step of `sitl.inprocess.run`
for one trial of `am-trials` (default randomization, seed 1, trial 0), whole and by part.

    python -m benchmarks.bench_trial_step [--scenario configs/scenarios/two_am_comp.toml] [--duration 20]

First the trial runs as it is (after a short warm-up run that loads the compiled kernels):
CPU time of this thread per physics step. Then it runs again with each part below wrapped
in a timer (the thread's CPU time around the call, less the wrapped parts it calls): us per
physics step for all AMs together. The wrappers cost ~0.5 us per call, so the parts sum to
more than the unwrapped step; "other" is what no part holds (the run loop, the link's
zero-order hold, the flight controllers' bookkeeping, the digest's inputs). A part that a
mode calls less than once in 100 steps is not printed: torque mode's setpoint_from_result,
attitude mode's offboard step, autopilot, rotors and joint-effort sensor. For
`benchmarks.ab`: a name wrapped that a tree compared does not have is skipped.

With --in-situ, a third run times the two largest pure calls of a controller step where the
run makes them and then again at once on the same arguments (the second result dropped, the
digest checked unchanged): the compiled law (`law.control_law`) and pinocchio's terms
(`control.pinocchio_terms`). A call made at once again finds its code and data in the
caches the first call filled; in the run they were cold, evicted by the physics, the
simulator's per-AM work and the other controller in between. The two figures bound what a
hot micro-benchmark (`bench_controller.py`) says about a run: its calls are the repeated
kind.
"""
from __future__ import annotations

import argparse
import functools
import importlib
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from amcore.config import read_scenario, scenario_from_dict
from trials.cli import DEFAULT_RANDOMIZE, build_tasks
from trials.randomize import load_randomize

ROOT = Path(__file__).resolve().parents[1]

# (label, module, attribute path): the parts, in the order of a control step (torque mode's and attitude
# mode's); a label on two rows times one function under both of its bindings
PARTS = (
    ("sense (World.sensor_values)", "simulator.world", "World.sensor_values"),
    ("devices and estimator (DeviceSuite.step)", "simulator.devices", "DeviceSuite.step"),
    ("frame (sensor_frame_from_wire, in core)", "simulator.core", "sensor_frame_from_wire"),
    ("as_on_the_wire", "sitl.inprocess", "as_on_the_wire"),
    ("state_from_frame", "companion.pilot", "state_from_frame"),
    ("mission reference", "amcore.mission", "AmMission.reference"),
    ("control.step without the law", "amcore.control", "step"),
    ("control.step without the law", "amcore.offboard", "step"),  # attitude mode's binding of it
    ("the compiled law (law.control_law)", "amcore.law", "control_law"),
    ("offboard_step, the rest (tau_b^, the arm's torques)", "companion.pilot", "offboard_step"),
    ("setpoint_from_result", "companion.pilot", "setpoint_from_result"),
    ("attitude_setpoint_from_result, the rest", "companion.pilot", "attitude_setpoint_from_result"),
    ("Pilot.command, the rest", "companion.pilot", "Pilot.command"),
    ("record (companion.outcome)", "companion.pilot", "Pilot.record"),
    ("setpoint_as_on_the_wire", "sitl.inprocess", "setpoint_as_on_the_wire"),
    ("setpoint limits", "amlink.types", "SetpointLimits.violation"),
    ("the emulated autopilot (FlightController.step)", "simulator.flight_controller", "FlightController.step"),
    ("apply (allocation, joint limits)", "simulator.world", "World.apply"),
    ("apply rotors (allocation, rotor lag, joint limits)", "simulator.world", "World.apply_rotors"),
    ("joint effort sensor", "simulator.devices", "JointEffortSensor.advance"),
    ("link (ImpairedLink.step)", "amlink.impair", "ImpairedLink.step"),
    ("ground truth and digest (observe)", "simulator.core", "SitlCore.observe"),
    ("PyBullet step (World.step)", "simulator.world", "World.step"),
)


def _trial_spec(scenario: Path, tmp: Path):
    tasks = build_tasks(read_scenario(scenario), scenario.resolve(), load_randomize(DEFAULT_RANDOMIZE), 1, 1, tmp, None)
    return scenario_from_dict(tasks[0].data, Path(tasks[0].path))


def _wrap_parts(excl: dict, calls: dict) -> None:
    clock = time.thread_time_ns
    inner = [0]  # wrapped time spent in the current call's wrapped callees

    def wrap(label, owner, name):
        f = getattr(owner, name)

        @functools.wraps(f)
        def timed(*a, **k):
            outer, inner[0] = inner[0], 0
            t0 = clock()
            try:
                return f(*a, **k)
            finally:
                dt = clock() - t0
                excl[label] += dt - inner[0]
                calls[label] += 1
                inner[0] = outer + dt
        setattr(owner, name, timed)

    for label, module, path in PARTS:
        owner = importlib.import_module(module)
        *outer, name = path.split(".")
        for o in outer:
            owner = getattr(owner, o, None)
        if owner is not None and hasattr(owner, name):
            wrap(label, owner, name)


# (label, module, attribute): the pure calls --in-situ times twice, in the order of a control step
REPEATED = (
    ("pinocchio's terms (control.pinocchio_terms)", "amcore.control", "pinocchio_terms"),
    ("the compiled law (law.control_law)", "amcore.law", "control_law"),
)


def _wrap_repeated(first: dict, again: dict, calls: dict) -> None:
    """Each of REPEATED timed where the run calls it and again at once (wall clock, ns)."""
    clock = time.perf_counter_ns
    for label, module, name in REPEATED:
        owner = importlib.import_module(module)
        f = getattr(owner, name, None)
        if f is None:
            continue

        def twice(*a, _f=f, _label=label):
            t0 = clock()
            out = _f(*a)
            t1 = clock()
            _f(*a)
            first[_label] += t1 - t0
            again[_label] += clock() - t1
            calls[_label] += 1
            return out
        setattr(owner, name, twice)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", type=Path, default=ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    ap.add_argument("--duration", type=float, default=None, help="simulated seconds (default: the trial's)")
    ap.add_argument("--in-situ", action="store_true",
                    help="a third run: the law and pinocchio's terms in the run against called again at once")
    a = ap.parse_args()
    import sitl.inprocess as ip

    with tempfile.TemporaryDirectory() as tmp:
        spec = _trial_spec(a.scenario, Path(tmp))
        ip.run(spec, 0.2)  # the kernels loaded, the caches warm
        c0 = time.thread_time()
        r = ip.run(spec, a.duration)
        cpu = time.thread_time() - c0
        n = r["steps"]
        print(f"{spec.name}: {n} steps, {len(spec.ams)} AMs, digest {r['state_digest'][:16]}, verdict {r['verdict']['status']}")
        print(f"CPU per physics step: {1e6 * cpu / n:.1f} us (real-time factor {r['real_time_factor']:.2f})")
        excl, calls = defaultdict(int), defaultdict(int)
        _wrap_parts(excl, calls)
        c0 = time.thread_time_ns()
        r2 = ip.run(spec, a.duration)
        total = time.thread_time_ns() - c0
        excl, calls = dict(excl), dict(calls)  # this run's (the parts' timers stay on in the next)
        first, again, repeated = defaultdict(int), defaultdict(int), defaultdict(int)
        if a.in_situ:
            _wrap_repeated(first, again, repeated)
            r3 = ip.run(spec, a.duration)
            assert r3["state_digest"] == r["state_digest"]
    assert r2["state_digest"] == r["state_digest"]
    print(f"wrapped run: {1e-3 * total / n:.1f} us per step")
    print(f"{'part':44s} {'us/step':>8s} {'calls/step':>11s}")
    for label in dict.fromkeys(label for label, _, _ in PARTS):
        if calls.get(label, 0) >= n / 100:  # (a few calls at start-up are no part of the step: warm_up_kernels)
            print(f"{label:44s} {1e-3 * excl[label] / n:8.1f} {calls[label] / n:11.2f}")
    print(f"{'other':44s} {1e-3 * (total - sum(excl.values())) / n:8.1f}")
    if repeated:
        print(f"{'in situ, wall clock per call':44s} {'in the run':>10s} {'again at once':>14s} {'ratio':>6s}")
        for label, _, _ in REPEATED:
            k = repeated[label]
            if k:
                print(f"{label:44s} {1e-3 * first[label] / k:10.1f} {1e-3 * again[label] / k:14.1f} "
                      f"{first[label] / again[label]:6.2f}")


if __name__ == "__main__":
    main()
