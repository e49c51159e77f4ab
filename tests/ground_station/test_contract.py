"""The topic contract: what the translator writes for a real run's telemetry, and seq accounting."""
from __future__ import annotations

import json
import math
import struct

import numpy as np
import pytest
from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp
from hypothesis import given, strategies as st

from ground_station import contract as c
from ground_station.contract import KeyStats, Translator
from telemetry import binary, schema
from telemetry.schema import Channel, Keys
from telemetry.validate import errors

from .conftest import as_json, stamped, wire_form

KEYS = Keys()


def _message(o):
    """A protobuf Out's message, parsed with Foxglove's type of its schema name."""
    assert o.encoding == c.PROTOBUF, o.topic
    return c.PROTOBUF_TYPES[o.schema].FromString(o.data)


def _translate_all(samples, scene_rate_hz=20.0):
    tr = Translator(KEYS, scene_rate_hz=scene_rate_hz)
    outs = []
    for k, p in stamped(samples):
        outs.extend(tr.translate(k, *wire_form(p)))
    return tr, outs


def _fields(o):
    """A JSON or ros1 Out's message as a dict: a ros1 one decoded with its channel's layout."""
    if o.encoding == c.ROS1:
        return binary.json_shape(o.schema, c.ROS1_SCHEMAS[o.schema].decode(o.data))
    return json.loads(o.data)


@pytest.mark.parametrize("form", ["binary", "json"])
def test_real_run_maps_to_the_documented_topics_and_schemas(capture, form):
    tr, outs = _translate_all(capture.samples if form == "binary" else as_json(capture.samples))
    sysids = [a.sysid for a in capture.spec.ams]
    expected = {c.TF_TOPIC, c.SCENE_TOPIC, c.OBJECT_POSE_TOPIC, c.OBJECT_STATE_TOPIC, c.SIM_EVENT_TOPIC, c.EVENTS_TOPIC}
    expected |= {c.controller_topic(s) for s in sysids} | {c.contact_topic(s) for s in sysids}
    expected |= {c.truth_topic(s) for s in sysids}  # the truth as sent, the estimate beside it
    assert {o.topic for o in outs} == expected
    schema_of = {}
    for o in outs:
        assert schema_of.setdefault(o.topic, o.schema) == o.schema  # one schema per topic
        if o.encoding == c.PROTOBUF:  # Foxglove's type, a whole message of it that says the same again
            assert _message(o).SerializeToString() == o.data, o.topic
        else:
            assert errors(_fields(o), c.json_schema(o.schema)) == [], (o.topic, o.data[:200])
    derived = {d.topic.format(sysid=s): d.schema for d in c.DERIVED for s in sysids}
    assert {o.topic: o.schema for o in outs if o.encoding == c.PROTOBUF} == {
        t: n for t, n in derived.items() if not t.startswith("/am/")}  # no companion events in the capture
    hot = {c.controller_topic(s) for s in sysids} | {c.contact_topic(s) for s in sysids} | {c.OBJECT_STATE_TOPIC}
    hot |= {c.truth_topic(s) for s in sysids}
    assert {o.topic for o in outs if o.encoding == c.ROS1} == (hot if form == "binary" else set())
    if form == "binary":
        assert schema_of[c.controller_topic(sysids[0])] == "amstack/ControllerState"
    last: dict[str, int] = {}
    for o in outs:
        assert o.log_time_ns >= last.get(o.topic, 0), o.topic
        last[o.topic] = o.log_time_ns
    assert schema_of[c.TF_TOPIC] == "foxglove.FrameTransforms"
    assert schema_of[c.OBJECT_POSE_TOPIC] == "foxglove.PoseInFrame"
    assert schema_of[c.SCENE_TOPIC] == "foxglove.SceneUpdate" and schema_of[c.EVENTS_TOPIC] == "foxglove.Log"
    assert all(d.message.__module__.startswith("foxglove.") for d in c.DERIVED)  # Foxglove's own generated types
    assert tr.malformed == tr.unknown == 0 and all(s.missing == 0 for s in tr.stats.values())
    assert tr.run_start is not None and tr.run_end is not None


def _R(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


@pytest.mark.parametrize("form", ["binary", "json"])
def test_ground_truth_reaches_tf_and_object_pose_unchanged(capture, form):
    _, outs = _translate_all(capture.samples if form == "binary" else as_json(capture.samples))
    gts = capture.truths
    tf = [_message(o) for o in outs if o.topic == c.TF_TOPIC]
    obj = [_message(o) for o in outs if o.topic == c.OBJECT_POSE_TOPIC]
    n_ams = len(capture.spec.ams)
    assert len(tf) == len(gts) * n_ams and len(obj) == len(gts)
    for k, gt in enumerate(gts):  # every step: the transforms are the truth's poses
        for j, (sysid, am) in enumerate(gt.ams.items()):
            base, ee = tf[k * n_ams + j].transforms
            assert (base.parent_frame_id, ee.parent_frame_id) == ("world", "world")
            assert (base.child_frame_id, ee.child_frame_id) == (c.base_frame(sysid), c.ee_frame(sysid))
            for tr, p, R in ((base, am.p_WB, am.R_WB), (ee, am.p_WE, am.R_WE)):
                np.testing.assert_allclose([tr.translation.x, tr.translation.y, tr.translation.z], p, atol=1e-12)
                r = tr.rotation
                np.testing.assert_allclose(_R([r.w, r.x, r.y, r.z]), R, atol=1e-12)
                assert (tr.timestamp.seconds, tr.timestamp.nanos) == divmod(round(gt.time_s * 1e9), 10**9)
        pose = obj[k].pose
        assert obj[k].frame_id == "world"
        np.testing.assert_allclose([pose.position.x, pose.position.y, pose.position.z], gt.object.p_WO, atol=1e-12)
        q = pose.orientation
        np.testing.assert_allclose([q.w, q.x, q.y, q.z], gt.object.quat_WO_wxyz, atol=1e-12)


def test_scene_rate_and_content(capture):
    _, outs = _translate_all(capture.samples, scene_rate_hz=10.0)
    scenes = [(o.log_time_ns, _message(o)) for o in outs if o.topic == c.SCENE_TOPIC]
    span = capture.truths[-1].time_s - capture.truths[0].time_s
    assert abs(len(scenes) - (1 + int(span * 10.0))) <= 1
    ids = {e.id for e in scenes[-1][1].entities}
    assert ids == {"object"} | {f"am{a.sysid}" for a in capture.spec.ams}
    last_truth = capture.truths[-1]
    for e in scenes[-1][1].entities:
        assert e.frame_id == "world" and e.timestamp.ToNanoseconds() == scenes[-1][0]
        if e.id.startswith("am"):  # the arm: base, every joint origin, the end-effector
            am = last_truth.ams[int(e.id[2:])]
            pts = [[p.x, p.y, p.z] for p in e.lines[0].points]
            assert len(pts) == 2 + len(am.p_W_joints) == 2 + capture.spec.vehicle.n_joints
            np.testing.assert_allclose(pts[1:-1], np.array(am.p_W_joints), atol=0.05)  # drawn a little earlier
    _, none = _translate_all(capture.samples, scene_rate_hz=0.0)
    assert not any(o.topic == c.SCENE_TOPIC for o in none)


def _literal_tf(t: float, sysid: int, poses) -> FrameTransforms:
    """/tf as Foxglove's definition reads, built anew field by field: the reference the
    recorder's in-place filling is checked against."""
    ns = round(t * 1e9)
    return FrameTransforms(transforms=[
        FrameTransform(timestamp=Timestamp(seconds=ns // 10**9, nanos=ns % 10**9), parent_frame_id="world",
                       child_frame_id=child, translation=Vector3(x=p[0], y=p[1], z=p[2]),
                       rotation=Quaternion(x=q[1], y=q[2], z=q[3], w=q[0]))
        for child, (p, q) in zip((c.base_frame(sysid), c.ee_frame(sysid)), poses)])


def _literal_pose(t: float, p, q) -> PoseInFrame:
    ns = round(t * 1e9)
    return PoseInFrame(timestamp=Timestamp(seconds=ns // 10**9, nanos=ns % 10**9), frame_id="world",
                       pose=Pose(position=Vector3(x=p[0], y=p[1], z=p[2]),
                                 orientation=Quaternion(x=q[1], y=q[2], z=q[3], w=q[0])))


def _as_json_number(x: float) -> float:
    """What a number becomes through a JSON sample: a non-finite one is sent as null (read as NaN)."""
    return x if math.isfinite(x) else math.nan


def _bits(msg) -> bytes:
    return msg.SerializeToString()  # NaN == NaN as bytes: one quiet NaN on both sides (struct, float('nan'))


number = st.floats(width=64)  # NaN and infinities too


@given(st.lists(number, min_size=14, max_size=14), st.floats(0, 1e5), st.integers(0, 255),
       st.sampled_from(["binary", "json"]))
def test_a_truth_and_an_object_sample_become_their_foxglove_messages(v, t, sysid, form):
    """Telemetry -> message round trip: whatever the numbers, an AM truth sample's /tf holds
    its base and end-effector poses and an object sample's /sim/object/pose its pose, exactly
    (what JSON cannot carry, a non-finite number, as NaN), the same bytes as the literal,
    field-by-field construction; decoded, the numbers are the sample's."""
    am = {"t": t, "seq": 0, "sysid": sysid, "p_WB": v[0:3], "q_WB": v[3:7], "p_WE": v[7:10], "q_WE": v[10:14],
          "p_W_joints": [], "rotor_saturated_steps": 0, "joint_saturated_steps": 0, "axis_saturated_steps": [0] * 4,
          "rotor_fraction_max": 0.0, "rotor_fraction_min": 0.0, "p_WB_est": [0.0] * 3, "q_WB_est": [1.0, 0, 0, 0],
          "v_B_est": [0.0] * 3, "w_B_est": [0.0] * 3}
    obj = {"t": t, "seq": 0, "p_WO": v[0:3], "q_WO": v[3:7], "v_WO": v[7:10], "w_WO": v[11:14], "touching": []}
    seen = (lambda x: x) if form == "binary" else _as_json_number
    tr = Translator(KEYS, scene_rate_hz=0.0)
    for key, ch, p in ((KEYS.am_truth(sysid), Channel.AM_TRUTH, am), (KEYS.object, Channel.OBJECT, obj)):
        data = binary.from_dict(ch, p) if form == "binary" else schema.encode(p)[0]
        (derived, _), = [tr.translate(key, data, form == "binary")]
        assert derived.log_time_ns == round(t * 1e9) and derived.encoding == c.PROTOBUF
        got = _message(derived)
        w = [seen(x) for x in v]
        if ch is Channel.AM_TRUTH:
            assert derived.data == _bits(_literal_tf(t, sysid, ((w[0:3], w[3:7]), (w[7:10], w[10:14]))))
            numbers = [x for f in got.transforms for x in (f.translation.x, f.translation.y, f.translation.z,
                                                           f.rotation.w, f.rotation.x, f.rotation.y, f.rotation.z)]
        else:
            assert derived.data == _bits(_literal_pose(t, w[0:3], w[3:7]))
            po = got.pose
            numbers = [po.position.x, po.position.y, po.position.z, po.orientation.w, po.orientation.x,
                       po.orientation.y, po.orientation.z]
            w = w[0:7]
        assert struct.pack(f"<{len(w)}d", *w) == struct.pack(f"<{len(numbers)}d", *numbers)  # bit for bit
    assert tr.malformed == 0


def test_a_pose_of_the_wrong_length_is_malformed_not_written():
    tr = Translator(KEYS)
    short = {"t": 0.1, "seq": 0, "p_WO": [0.0, 0.0], "q_WO": [1.0, 0.0, 0.0, 0.0], "v_WO": [0.0] * 3}
    wrong = {"t": 0.1, "seq": 1, "p_WO": [0.0, 0.0, 1.0], "q_WO": [1.0, 0.0, 0.0, "a"], "v_WO": [0.0] * 3}
    assert tr.translate(KEYS.object, schema.encode(short)[0]) == []
    assert tr.translate(KEYS.object, schema.encode(wrong)[0]) == []
    assert tr.malformed == 2 and "object" in tr.last_error


@given(st.lists(st.booleans(), min_size=1, max_size=300))
def test_keystats_counts_exactly_the_gaps(delivered):
    s = KeyStats()
    seqs = [i for i, d in enumerate(delivered) if d]
    for q in seqs:
        s.see(q)
    if seqs:
        assert s.received == len(seqs) and s.missing == (seqs[-1] + 1) - len(seqs)  # the head counts too
        assert s.first_seq == seqs[0] and s.last_seq == seqs[-1] and s.reordered == 0


def test_keystats_close_counts_the_tail():
    s = KeyStats()
    for q in (0, 1, 3):
        s.see(q)
    s.close(6)  # seq 4 and 5 were issued but never arrived
    assert (s.missing, s.last_seq) == (3, 5)
    s.close(6)  # idempotent
    assert s.missing == 3
    never = KeyStats()
    never.close(4)
    assert never.missing == 4 and never.received == 0


def test_final_publisher_stats_add_tail_losses_and_are_logged():
    tr = Translator(KEYS)
    for q in range(3):
        tr.translate(KEYS.controller(4), b'{"t":%f,"seq":%d}' % (q * 1e-3, q))
    stats = schema.publisher_stats_sample(0.002, "am4", False, {KEYS.controller(4): 5}, dict.fromkeys(
        ("published", "sent", "dropped_queue_full", "dropped_no_session", "dropped_at_close", "encode_errors",
         "send_errors"), 0))
    out = tr.translate(KEYS.publisher("am4"), schema.encode(stats)[0])
    assert [o.topic for o in out] == ["/telemetry/am4"] and errors(json.loads(out[0].data), c.SCHEMAS[out[0].schema]) == []
    assert tr.stats[KEYS.controller(4)].missing == 0  # not final: samples may still be on their way
    stats.update(final=True, seq=1)
    tr.translate(KEYS.publisher("am4"), schema.encode(stats)[0])
    assert tr.stats[KEYS.controller(4)].missing == 2


def test_keystats_reorder_and_restart():
    s = KeyStats()
    for q in (0, 1, 3, 2, 4, 0, 1):
        s.see(q)
    assert (s.missing, s.reordered, s.restarts, s.last_seq) == (1, 1, 1, 1)


def test_malformed_and_unknown_payloads_are_counted_not_lost_silently():
    tr = Translator(KEYS)
    assert tr.translate(KEYS.controller(4), b"not json") == []
    assert tr.translate(KEYS.object, b'{"t":1.0,"seq":0,"p_WO":[0,0]}') == []  # too short for a pose
    assert tr.malformed == 2 and "object" in tr.last_error
    out = tr.translate("amstack/lab/thermometer", b'{"t":2.5,"seq":0,"c":21.5}')
    assert [(o.topic, o.schema, o.log_time_ns) for o in out] == [("/unknown/amstack/lab/thermometer", None, 2_500_000_000)]
    assert tr.unknown == 1
    stats = json.loads(tr.stats_out(1.0, inbox_overflow=3).data)
    assert errors(stats, c.RECORDER_STATS_SCHEMA) == [] and stats["inbox_overflow"] == 3 and stats["malformed"] == 2


def test_scene_keeps_its_rate_on_a_fixed_grid():
    """Object samples every 10 ms of simulated time (k * dt in floating point, as the simulator
    stamps them): /scene comes at exactly 20 Hz, one per 50 ms slot, without drifting."""
    tr = Translator(KEYS, scene_rate_hz=20.0)
    dt, scenes = 1e-3, []
    for seq, k in enumerate(range(0, 10_001, 10)):
        t = k * dt
        raw = schema.encode({"t": t, "seq": seq, "p_WO": [0.0, 0.0, 0.6], "q_WO": [1.0, 0.0, 0.0, 0.0],
                             "v_WO": [0.0, 0.0, 0.0]})[0]
        scenes += [t for o in tr.translate(KEYS.object, raw) if o.topic == c.SCENE_TOPIC]
    assert len(scenes) == 201  # t = 0, 0.05, ..., 10
    np.testing.assert_allclose(np.diff(scenes), 0.05, atol=1e-9)
