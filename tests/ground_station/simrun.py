"""A short in-process run (World + controller, no processes) that feeds telemetry.

Test helper: the paper's two-AM scenario with its mission compressed (the AMs start
5 mm from the box, squeeze it from 0.2 s, lift from 0.8 s) so that a run of about a
second has all three phases and pad-object contact. Whether the grasp holds does not
matter here: these tests check that telemetry reports what the simulator did.
"""
from __future__ import annotations

import dataclasses
from typing import Callable

from amcore.control import ControllerMemory, ControllerParams, step
from amcore.mission import am_mission
from simulator.world import World
from telemetry import capture, schema
from telemetry.wiring import CompanionTelemetry, SimulatorTelemetry

SHORT_MISSION = dict(approach_end_s=0.2, grasp_end_s=0.8, hover_end_s=2.0, approach_move_s=0.1,
                     grasp_move_s=0.6, lift_move_s=0.5, standoff_m=0.005, start_height_m=0.0,
                     pre_gap_m=0.005, squeeze_m=0.03, lift_m=0.03)


def short_spec(spec, duration_s: float = 2.0):
    mission = dataclasses.replace(spec.mission, **SHORT_MISSION)
    return dataclasses.replace(spec, mission=mission, duration_s=duration_s)


class _Sink:
    """A publisher that hands each sample to fn(key, payload), binary ones finished (as the
    sender thread puts them on the wire)."""

    def __init__(self, fn, keys):
        self.fn, self.keys = fn, keys

    def publish(self, key, payload):
        self.fn(key, capture.finished(payload) if type(payload) is tuple else payload)


def run(spec, model, duration_s: float, sink: Callable[[str, dict | bytes], object], keys: schema.Keys,
        truth_every: int = 1, on_truth: Callable | None = None, on_step: Callable | None = None,
        encoding: str = "binary") -> int:
    """Fly `duration_s` of the scenario, publishing through telemetry.wiring as the mains
    do; sink(key, payload) receives every sample (hot ones binary unless encoding="json");
    on_truth(GroundTruth) and on_step(sysid, t, phase, StepResult) see what was published.
    Returns the number of steps."""
    from amcore.model import create_data

    out = _Sink(sink, keys)
    missions = {a.sysid: am_mission(spec, a, model) for a in spec.ams}
    params = {s: ControllerParams.from_vehicle(spec.vehicle, m.frame) for s, m in missions.items()}
    ams = {s: CompanionTelemetry(out, s, encoding=encoding) for s in missions}
    sim = SimulatorTelemetry(out, spec, truth_every=truth_every, encoding=encoding)
    data = create_data(model)
    memory = {s: ControllerMemory() for s in missions}
    n_steps = int(round(duration_s / spec.dt_s))
    with World(spec, {s: m.initial_state() for s, m in missions.items()}) as world:
        sim.start()
        for _ in range(n_steps):
            t = world.time_s
            for s, m in missions.items():
                res = step(model, data, params[s], world.state(s), m.reference(t), world.wrench_ee(s), memory[s], t)
                memory[s] = res.memory
                world.apply(s, res.command.thrust_n, res.command.tau_B_nm, res.command.tau_q_nm)
                ams[s].step(t, m.phase(t), res)
                if on_step is not None:
                    on_step(s, t, m.phase(t), res)
            if sim.due(world.step_index):
                gt = world.ground_truth()
                if on_truth is not None:
                    on_truth(gt)
                sim.truth(gt)
            world.step()
        sim.end(world.time_s)
    return n_steps
