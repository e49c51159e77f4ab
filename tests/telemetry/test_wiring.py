"""The mains' helpers publish what the contract asks, when it asks."""
from __future__ import annotations

import dataclasses

import pytest

from simulator.world import World
from telemetry import schema
from telemetry.schema import Channel, Keys
from telemetry.validate import errors
from telemetry.wiring import CompanionTelemetry, SimulatorTelemetry, phase_at
from tests.simulator.sim_testing import far_apart


class Collect:
    def __init__(self):
        self.keys = Keys("lab")
        self.items = []

    def publish(self, key, payload):
        self.items.append((key, payload))
        return True


def test_phase_at_boundaries():
    ends = (5.0, 10.0, 20.0)
    assert [phase_at(t, ends) for t in (0.0, 4.999, 5.0, 9.999, 10.0, 25.0)] == \
        ["approach", "approach", "grasp", "grasp", "hover", "hover"]


def test_simulator_publishes_start_truth_phases_and_end(spec, model):
    short = dataclasses.replace(spec, mission=dataclasses.replace(spec.mission, approach_end_s=0.004,
                                                                  grasp_end_s=0.008))
    c = Collect()
    st = SimulatorTelemetry(c, short, truth_every=3)
    with World(short, far_apart(short)) as w:
        st.start()
        for _ in range(12):
            if st.due(w.step_index):
                st.truth(w.ground_truth())
            w.step()
        st.end(w.time_s)
    k = c.keys
    events = [p for key, p in c.items if key == k.sim_event]
    assert [e["kind"] for e in events] == ["run_start", "phase", "phase", "phase", "run_end"]
    assert [e["data"]["phase"] for e in events if e["kind"] == "phase"] == ["approach", "grasp", "hover"]
    objs = [p["t"] for key, p in c.items if key == k.object]
    assert objs == pytest.approx([0.0, 0.003, 0.006, 0.009])  # every 3rd step of 1 ms
    for key, p in c.items:
        assert key.startswith("lab/")
        assert errors(p, schema.SCHEMAS[k.parse(key).channel]) == [], key
    assert {k.parse(key).channel for key, _ in c.items} == {Channel.SIM_EVENT, Channel.AM_TRUTH, Channel.CONTACT,
                                                           Channel.OBJECT}


def test_companion_decimates_and_reports_faults(step_result):
    c = Collect()
    ct = CompanionTelemetry(c, 7, every=4)
    for i in range(10):
        ct.step(i * 1e-3, "approach", step_result)
    ct.fault(0.01, "lost lockstep")
    ctrl = [p for key, p in c.items if key == "lab/am/7/controller"]
    assert [p["t"] for p in ctrl] == pytest.approx([0.0, 0.004, 0.008]) and all(p["sysid"] == 7 for p in ctrl)
    (key, ev), = [(key, p) for key, p in c.items if key == "lab/am/7/event"]
    assert ev["kind"] == "fault" and ev["source"] == "am7" and errors(ev, schema.EVENT_SCHEMA) == []
