"""telemetry.binary: the .msg layouts describe the JSON payloads' fields; every sample starts
with the t/seq header; the validator checks binary samples through their JSON view. (The
builders are checked against the literal path in test_capture.py.)"""
from __future__ import annotations

import math

import numpy as np
import pytest

from telemetry import binary, capture, schema
from telemetry.capture import finished
from telemetry.schema import Channel
from telemetry.validate import binary_errors

from .test_capture import _diag


def test_every_message_has_the_json_payload_s_fields_in_order():
    """The .msg layouts and the JSON Schemas describe the same samples: same names, same order,
    fixed lengths where JSON fixes them, number types for numbers."""
    kinds = {"number": {"float64"}, "integer": {"uint32", "uint64"}, "boolean": {"bool"}, "string": {"string"}}
    for ch, msg in binary.MESSAGES.items():
        props = schema.SCHEMAS[ch]["properties"]
        assert [f.name for f in msg.fields] == list(props), ch
        assert binary.JSON_TITLE[msg.name] == schema.SCHEMAS[ch]["title"] == msg.name.replace("/", ".")
        for f in msg.fields:
            p = props[f.name]
            if p["type"] != "array":
                assert f.count is None and f.type in kinds[p["type"]], (ch, f)
                continue
            item = p["items"].get("type")
            if item == "array":  # p_W_joints: 3-vectors, flattened
                assert f.type == "float64" and f.count == -1
                continue
            assert f.type in kinds[item], (ch, f)
            assert f.count == p.get("maxItems", -1) and p.get("minItems", -1) == f.count, (ch, f)
    assert binary.MESSAGES.keys() == {Channel.CONTROLLER, Channel.AM_TRUTH, Channel.CONTACT, Channel.OBJECT}
    for msg in binary.MESSAGES.values():  # the header the publisher stamps and the recorder reads
        assert [(f.name, f.type) for f in msg.fields[:2]] == [("t", "float64"), ("seq", "uint64")]


def test_with_seq_sets_only_the_seq():
    data = finished(capture.controller(0.5, "grasp", *_diag(np.random.default_rng(1), 3, 3), sysid=4))
    stamped = binary.with_seq(data, 2**40 + 3)
    assert binary.header(stamped) == (0.5, 2**40 + 3) and len(stamped) == len(data)
    assert binary.to_dict(Channel.CONTROLLER, stamped) == {**binary.to_dict(Channel.CONTROLLER, data), "seq": 2**40 + 3}
    with pytest.raises(ValueError):
        binary.header(data[:15])


def test_the_validator_checks_binary_samples_through_their_json_view(step_result):
    data = finished(capture.controller(0.7, "grasp", step_result.diagnostics, step_result.command, sysid=4))
    assert binary_errors(Channel.CONTROLLER, data) == []
    assert binary_errors(Channel.CONTROLLER, data[:-1])  # not a whole message
    assert binary_errors(Channel.OBJECT, data)  # not of that channel's layout
    wrong_phase = finished(capture.controller(0.7, "landing", step_result.diagnostics, step_result.command, sysid=4))
    assert any("landing" in e for e in binary_errors(Channel.CONTROLLER, wrong_phase))
    nan = binary.from_dict(Channel.CONTROLLER, {**binary.to_dict(Channel.CONTROLLER, data), "damping": math.nan})
    assert any("non-finite" in e for e in binary_errors(Channel.CONTROLLER, nan))
