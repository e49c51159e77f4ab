"""The mains' helpers publish what the contract asks, when it asks."""
from __future__ import annotations

import dataclasses

import pytest

from simulator.world import World
from telemetry import binary, capture, schema
from telemetry.schema import Channel, Keys
from telemetry.validate import binary_errors, errors
from telemetry.wiring import CompanionTelemetry, SimulatorTelemetry, phase_at
from tests.simulator.sim_testing import far_apart


class Collect:
    """A publisher that keeps what it is given; `items` has binary samples as their JSON dicts."""

    def __init__(self):
        self.keys = Keys("lab")
        self.given = []  # as published: dicts, bytes, (finish, pre-sample) pairs
        self.raw = []  # binary ones finished (what the sender puts on the wire)

    def publish(self, key, payload):
        self.given.append((key, payload))
        self.raw.append((key, capture.finished(payload) if type(payload) is tuple else payload))
        return True

    @property
    def items(self):
        return [(k, binary.to_dict(self.keys.parse(k).channel, p) if isinstance(p, bytes) else p) for k, p in self.raw]


def test_phase_at_boundaries():
    ends = (5.0, 10.0, 20.0)
    assert [phase_at(t, ends) for t in (0.0, 4.999, 5.0, 9.999, 10.0, 25.0)] == \
        ["approach", "approach", "grasp", "grasp", "hover", "hover"]


def _simulate(spec, encoding):
    short = dataclasses.replace(spec, mission=dataclasses.replace(spec.mission, approach_end_s=0.004,
                                                                  grasp_end_s=0.008))
    c = Collect()
    st = SimulatorTelemetry(c, short, truth_every=3, encoding=encoding)
    with World(short, far_apart(short)) as w:
        st.start()
        for _ in range(12):
            if st.due(w.step_index):
                st.truth(w.ground_truth())
            w.step()
        st.end(w.time_s)
    return c


def test_simulator_publishes_start_truth_phases_and_end(spec, model):
    c = _simulate(spec, "binary")
    k = c.keys
    hot = {Channel.AM_TRUTH, Channel.CONTACT, Channel.OBJECT}
    assert all(isinstance(p, bytes) == (k.parse(key).channel in hot) for key, p in c.raw)  # events stay JSON
    events = [p for key, p in c.items if key == k.sim_event]
    assert [e["kind"] for e in events] == ["run_start", "phase", "phase", "phase", "run_end"]
    assert [e["data"]["phase"] for e in events if e["kind"] == "phase"] == ["approach", "grasp", "hover"]
    objs = [p["t"] for key, p in c.items if key == k.object]
    assert objs == pytest.approx([0.0, 0.003, 0.006, 0.009])  # every 3rd step of 1 ms
    for key, p in c.raw:
        assert key.startswith("lab/")
        ch = k.parse(key).channel
        assert (binary_errors(ch, p) if isinstance(p, bytes) else errors(p, schema.SCHEMAS[ch])) == [], key
    assert {k.parse(key).channel for key, _ in c.items} == {Channel.SIM_EVENT, Channel.AM_TRUTH, Channel.CONTACT,
                                                           Channel.OBJECT}


def test_the_json_encoding_publishes_the_same_samples_as_json(spec):
    got = {enc: _simulate(spec, enc) for enc in ("binary", "json")}
    assert all(isinstance(p, dict) for _, p in got["json"].raw)
    assert got["json"].items == got["binary"].items


@pytest.mark.parametrize("encoding", ["binary", "json"])
def test_companion_decimates_and_reports_faults(step_result, encoding):
    c = Collect()
    ct = CompanionTelemetry(c, 7, every=4, encoding=encoding)
    for i in range(10):
        ct.step(i * 1e-3, "approach", step_result)
    ct.fault(0.01, "lost lockstep")
    assert [isinstance(p, bytes) for _, p in c.raw] == [encoding == "binary"] * 3 + [False]
    ctrl = [p for key, p in c.items if key == "lab/am/7/controller"]
    assert [p["t"] for p in ctrl] == pytest.approx([0.0, 0.004, 0.008]) and all(p["sysid"] == 7 for p in ctrl)
    assert all(errors(p, schema.CONTROLLER_SCHEMA) == [] for p in ctrl)
    (key, ev), = [(key, p) for key, p in c.items if key == "lab/am/7/event"]
    assert ev["kind"] == "fault" and ev["source"] == "am7" and errors(ev, schema.EVENT_SCHEMA) == []


def test_an_unknown_encoding_is_refused(spec):
    with pytest.raises(ValueError, match="protobuf"):
        CompanionTelemetry(Collect(), 4, encoding="protobuf")
    with pytest.raises(ValueError, match="protobuf"):
        SimulatorTelemetry(Collect(), spec, encoding="protobuf")


def test_nothing_is_built_for_a_disabled_publisher(step_result, spec):
    class Off(Collect):
        enabled = False

    c = Off()
    CompanionTelemetry(c, 7).step(0.0, "approach", step_result)
    sim = SimulatorTelemetry(c, spec)
    with World(spec, far_apart(spec)) as w:
        sim.truth(w.ground_truth())
    assert [c.keys.parse(k).channel for k, _ in c.given] == [Channel.SIM_EVENT]  # the phase event only
