"""The wire contract: keys parse back, builders hold to their own schemas, encoding is strict JSON."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from amcore.so3 import quat_wxyz_to_R
from telemetry import schema
from telemetry.schema import Channel, Keys
from telemetry.validate import errors


def test_every_key_parses_back_to_its_channel_and_sysid():
    for prefix in ("amstack", "lab/run7"):
        k = Keys(prefix)
        cases = {k.controller(4): (Channel.CONTROLLER, 4), k.am_event(12): (Channel.AM_EVENT, 12),
                 k.am_truth(5): (Channel.AM_TRUTH, 5), k.contact(0): (Channel.CONTACT, 0),
                 k.object: (Channel.OBJECT, None), k.sim_event: (Channel.SIM_EVENT, None),
                 k.publisher("am4"): (Channel.PUBLISHER, None)}
        for key, (ch, sysid) in cases.items():
            m = k.parse(key)
            assert m is not None and (m.channel, m.sysid) == (ch, sysid), key
        assert k.parse(k.publisher("sim-1")).name == "sim-1"
    k = Keys()
    assert k.batch_name(k.batch("simulator")) == "simulator" and k.parse(k.batch("simulator")) is None
    assert k.batch_name(k.publisher("am4")) is None and k.batch_name("other/batch/am4") is None
    for foreign in ("other/am/4/controller", "amstack/am/x/controller", "amstack/am/4/controllers",
                    "amstack/sim/am/4", "amstack/sim/objects", "amstack", "amstack/am/-1/event",
                    "amstack/telemetry", "amstack/telemetry/a/b"):
        assert k.parse(foreign) is None, foreign


@pytest.mark.parametrize("bad", ["", "a/", "/a", "a/**", "a b", "a/*/b"])
def test_prefix_rejects_wildcards_and_empty_chunks(bad):
    with pytest.raises(ValueError):
        Keys(bad)


def _payloads(step_result, ground_truth, spec):
    k = Keys()
    d, c = step_result.diagnostics, step_result.command
    out = [(Channel.CONTROLLER, schema.controller_sample(0.7, "grasp", d, c, seq=3, sysid=4))]
    for key, p in schema.ground_truth_samples(ground_truth, k):
        out.append((k.parse(key).channel, p))
    out += [(Channel.SIM_EVENT, schema.run_start_event(0.0, spec)),
            (Channel.SIM_EVENT, schema.run_end_event(20.0, "completed")),
            (Channel.SIM_EVENT, schema.phase_event(5.0, "grasp", "simulator")),
            (Channel.AM_EVENT, schema.fault_event(3.0, "thrust saturated", "am4", level="warning")),
            (Channel.PUBLISHER, schema.publisher_stats_sample(1.0, "am4", True, {"amstack/am/4/controller": 7},
                                                              dict(published=7, sent=7, dropped_queue_full=0,
                                                                   dropped_no_session=0, dropped_at_close=0,
                                                                   encode_errors=0, send_errors=0)))]
    return out


def test_builders_validate_against_their_own_schemas(step_result, ground_truth, spec):
    payloads = _payloads(step_result, ground_truth, spec)
    assert {ch for ch, _ in payloads} == set(Channel)
    for ch, p in payloads:
        assert errors(p, schema.SCHEMAS[ch]) == [], (ch, p)
        data, replaced = schema.encode(p)
        assert not replaced
        # survives the wire: strict JSON, same content, t and seq first
        back = json.loads(data)
        assert back == json.loads(json.dumps(p))
        assert list(back)[:2] == ["t", "seq"]
        assert schema.peek_header(data) == (p["t"], p["seq"])


def test_controller_sample_carries_the_diagnostics(step_result):
    d, c = step_result.diagnostics, step_result.command
    p = schema.controller_sample(0.7, "grasp", d, c, sysid=4)
    np.testing.assert_allclose(p["r_c_err"], d.r_c_err)
    np.testing.assert_allclose(quat_wxyz_to_R(np.array(p["q_WB"])), d.R_WB, atol=1e-12)
    np.testing.assert_allclose(quat_wxyz_to_R(np.array(p["q_WB_d"])), d.R_d, atol=1e-12)
    np.testing.assert_allclose(p["f_W"], d.F_rc)
    np.testing.assert_allclose(p["tau_q_nm"], c.tau_q_nm)
    assert p["thrust_n"] == c.thrust_n and p["sigma_min_J3"] == d.sigma_min_J3
    assert np.linalg.norm(p["r_c_err"]) > 0 and np.linalg.norm(p["wrench_E"]) > 0


def test_contact_sample_is_the_ground_truth(ground_truth):
    for sysid, am in ground_truth.ams.items():
        p = schema.contact_sample(ground_truth.time_s, sysid, am)
        assert p["normal_force_n"] == am.pad_object_contact.normal_force_n > 0
        np.testing.assert_allclose(p["tangential_force_W"], am.pad_object_contact.tangential_force_W)
        assert p["n_points"] == am.pad_object_contact.n_points


def test_validator_rejects_broken_payloads(step_result):
    good = schema.controller_sample(0.7, "grasp", step_result.diagnostics, step_result.command, sysid=4)
    s = schema.CONTROLLER_SCHEMA
    broken = [
        {k: v for k, v in good.items() if k != "e_R"},  # missing
        {**good, "r_c": good["r_c"][:2]},  # wrong length
        {**good, "q_WB": good["q_WB"] + [0.0]},
        {**good, "seq": 1.5},  # not an integer
        {**good, "seq": True},
        {**good, "phase": "landing"},  # not a phase
        {**good, "thrust_n": "12"},
        {**good, "t": -1.0},
        {**good, "y": [1.0, math.nan, 0.0]},  # not finite
    ]
    for b in broken:
        assert errors(b, s), b


def test_nonfinite_numbers_go_out_as_null():
    data, replaced = schema.encode({"t": 1.0, "seq": 0, "x": [1.0, math.nan, math.inf], "y": {"z": -math.inf}})
    assert replaced
    assert json.loads(data) == {"t": 1.0, "seq": 0, "x": [1.0, None, None], "y": {"z": None}}


def test_peek_header_refuses_other_shapes():
    for data in (b'{"seq":1,"t":0.5}', b'{"t":"0.5","seq":1}', b'[1,2]', b'', b'{"t":0.5,"seq":-1}'):
        assert schema.peek_header(data) is None, data
    assert schema.peek_header(b'{"t":1e-05,"seq":7}') == (1e-05, 7)


def test_event_builders_reject_unknown_kinds_levels_and_phases():
    with pytest.raises(ValueError):
        schema.event(0.0, "explosion", "x", "simulator")
    with pytest.raises(ValueError):
        schema.event(0.0, "info", "x", "simulator", level="loud")
    with pytest.raises(ValueError):
        schema.phase_event(0.0, "landing", "simulator")


def test_run_start_describes_the_scenario(spec):
    p = schema.run_start_event(0.0, spec)
    d = p["data"]
    assert d["phase_ends_s"] == [spec.mission.approach_end_s, spec.mission.grasp_end_s, spec.mission.hover_end_s]
    assert d["sysids"] == [a.sysid for a in spec.ams]
    assert d["object"]["position_m"] == list(spec.object.position_m)
