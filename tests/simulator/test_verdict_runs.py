"""Every failure class of the mission verdict, on short crafted runs of the real physics
and controllers (two_am_short, in-process): what the verdict names is what happened."""
from __future__ import annotations

import copy
from pathlib import Path

import pytest

from amcore.config import read_scenario, scenario_from_dict
from sitl.inprocess import run

SHORT = Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_short.toml"


def _run(changes: dict, duration=None, lost_from=None):
    data = copy.deepcopy(read_scenario(SHORT))
    for table, values in changes.items():
        if table == "am4":
            data["am"][0].update(values)
        else:
            data.setdefault(table, {}).update(values)
    lost = (lambda t: {5} if t >= lost_from else set()) if lost_from is not None else (lambda _t: set())
    return run(scenario_from_dict(data, SHORT), duration, lost=lost)


def test_the_nominal_short_grasp_is_a_success():
    r = _run({})
    assert r["verdict"]["status"] == "success", r["verdict"]["text"]
    assert r["object"]["hover_min_lift_m"] > 0.2


TRUST = {"flight_controller": {"failsafe_after_rejected": 10**9}}

# (variation, duration [s] or None for the whole 8 s, companion 5 lost from [s], expected class, words)
CRAFTED = [
    ({"object": {"pad_friction": 0.1}}, None, None, "never lifted", "object never lifted to 20 cm"),
    ({}, None, 6.0, "dropped", "dropped at t = 6."),
    ({"am4": {"misalignment_deg": 0.1}}, None, None, "slipped", "> 2 mm"),
    # these two keep flying on the last valid command whatever is refused (K huge): what a
    # flight controller without the K-in-a-row failsafe would do
    ({"am4": {"start_offset_m": [0.0, 0.0, -0.7]}, **TRUST}, 0.5, None, "base contact", "base of am4 touched ground"),
    # a base beyond the 3 m limit (placed there: where an overloaded team ends up is chaotic, it
    # depends on the last bits of the arithmetic, and mostly ends on the table first)
    ({"am4": {"start_offset_m": [0.0, 0.0, 3.2]}, **TRUST}, 0.5, None, "diverged",
     "from the object's rest position > 3 m"),
    ({}, 1.0, 0.3, "failsafe", "sysid 5 in failsafe at the end"),
    ({"sensors": {"latency_s": 0.008}}, 2.0, None, "rejected setpoints", "rejected as implausible"),
    ({"am4": {"start_heading_deg": 20.0}}, 1.0, None, "saturated", "am4's actuators saturated"),
]


@pytest.mark.parametrize("changes,duration,lost_from,kind,words", CRAFTED, ids=[c[3] for c in CRAFTED])
def test_each_failure_class_on_a_crafted_run(changes, duration, lost_from, kind, words):
    v = _run(changes, duration, lost_from)["verdict"]
    assert v["status"] == "failed" and v["failure_class"] == kind, v["text"]
    first = v["failures"][0]
    assert words in first["reason"], first["reason"]
