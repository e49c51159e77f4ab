"""The topic contract: what the translator writes for a real run's telemetry, and seq accounting."""
from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, strategies as st

from ground_station import contract as c
from ground_station.contract import KeyStats, Translator
from telemetry import binary, schema
from telemetry.schema import Keys
from telemetry.validate import errors

from .conftest import as_json, stamped, wire_form

KEYS = Keys()


def _translate_all(samples, scene_rate_hz=20.0):
    tr = Translator(KEYS, scene_rate_hz=scene_rate_hz)
    outs = []
    for k, p in stamped(samples):
        outs.extend(tr.translate(k, *wire_form(p)))
    return tr, outs


def _fields(o):
    """An Out's message as a dict: a ros1 one decoded with its channel's layout."""
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
        assert errors(_fields(o), c.json_schema(o.schema)) == [], (o.topic, o.data[:200])
    hot = {c.controller_topic(s) for s in sysids} | {c.contact_topic(s) for s in sysids} | {c.OBJECT_STATE_TOPIC}
    hot |= {c.truth_topic(s) for s in sysids}
    assert {o.topic for o in outs if o.encoding == c.ROS1} == (hot if form == "binary" else set())
    if form == "binary":
        assert schema_of[c.controller_topic(sysids[0])] == "amstack/ControllerState"
    last: dict[str, int] = {}
    for o in outs:
        assert o.log_time_ns >= last.get(o.topic, 0), o.topic
        last[o.topic] = o.log_time_ns
    assert schema_of[c.TF_TOPIC] == "foxglove.FrameTransforms" and schema_of[c.OBJECT_POSE_TOPIC] == "foxglove.PoseInFrame"
    assert schema_of[c.SCENE_TOPIC] == "foxglove.SceneUpdate" and schema_of[c.EVENTS_TOPIC] == "foxglove.Log"
    assert tr.malformed == tr.unknown == 0 and all(s.missing == 0 for s in tr.stats.values())
    assert tr.run_start is not None and tr.run_end is not None


@pytest.mark.parametrize("form", ["binary", "json"])
def test_ground_truth_reaches_tf_and_object_pose_unchanged(capture, form):
    _, outs = _translate_all(capture.samples if form == "binary" else as_json(capture.samples))
    gts = capture.truths
    tf = [json.loads(o.data) for o in outs if o.topic == c.TF_TOPIC]
    obj = [json.loads(o.data) for o in outs if o.topic == c.OBJECT_POSE_TOPIC]
    n_ams = len(capture.spec.ams)
    assert len(tf) == len(gts) * n_ams and len(obj) == len(gts)
    for k in (0, len(gts) // 2, len(gts) - 1):
        gt = gts[k]
        for j, (sysid, am) in enumerate(gt.ams.items()):
            base, ee = tf[k * n_ams + j]["transforms"]
            assert (base["child_frame_id"], ee["child_frame_id"]) == (c.base_frame(sysid), c.ee_frame(sysid))
            np.testing.assert_allclose([ee["translation"][a] for a in "xyz"], am.p_WE, atol=1e-12)
            assert base["timestamp"] == {"sec": int(gt.time_s), "nsec": round(gt.time_s * 1e9) % 10**9}
        np.testing.assert_allclose([obj[k]["pose"]["position"][a] for a in "xyz"], gt.object.p_WO, atol=1e-12)
        q = obj[k]["pose"]["orientation"]
        np.testing.assert_allclose([q["w"], q["x"], q["y"], q["z"]], gt.object.quat_WO_wxyz, atol=1e-12)


def test_scene_rate_and_content(capture):
    _, outs = _translate_all(capture.samples, scene_rate_hz=10.0)
    scenes = [(o.log_time_ns, json.loads(o.data)) for o in outs if o.topic == c.SCENE_TOPIC]
    span = capture.truths[-1].time_s - capture.truths[0].time_s
    assert abs(len(scenes) - (1 + int(span * 10.0))) <= 1
    ids = {e["id"] for e in scenes[-1][1]["entities"]}
    assert ids == {"object"} | {f"am{a.sysid}" for a in capture.spec.ams}
    last_truth = capture.truths[-1]
    for e in scenes[-1][1]["entities"]:
        if e["id"].startswith("am"):  # the arm: base, every joint origin, the end-effector
            am = last_truth.ams[int(e["id"][2:])]
            pts = [[p["x"], p["y"], p["z"]] for p in e["lines"][0]["points"]]
            assert len(pts) == 2 + len(am.p_W_joints) == 2 + capture.spec.vehicle.n_joints
            np.testing.assert_allclose(pts[1:-1], np.array(am.p_W_joints), atol=0.05)  # drawn a little earlier
    _, none = _translate_all(capture.samples, scene_rate_hz=0.0)
    assert not any(o.topic == c.SCENE_TOPIC for o in none)


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@given(st.lists(finite, min_size=14, max_size=14), st.floats(0, 1e5), st.integers(0, 255))
def test_spliced_poses_equal_the_general_path(v, t, sysid):
    """The recorder's fast path (splicing the payload's number text into the Foxglove
    message) says exactly what decoding and re-encoding would."""
    from ground_station import foxglove as fg

    am = {"p_WB": v[0:3], "q_WB": v[3:7], "p_WE": v[7:10], "q_WE": v[10:14]}
    raw = schema.encode({"t": t, "seq": 0, "sysid": sysid, **am})[0]
    slow = {"transforms": [fg.frame_transform(t, "world", c.base_frame(sysid), am["p_WB"], am["q_WB"]),
                           fg.frame_transform(t, "world", c.ee_frame(sysid), am["p_WE"], am["q_WE"])]}
    assert json.loads(c._tf_spliced(t, sysid, raw)) == slow
    raw = schema.encode({"t": t, "seq": 0, "p_WO": v[0:3], "q_WO": v[3:7], "v_WO": v[7:10]})[0]
    assert json.loads(c._pose_spliced(t, raw)) == fg.pose_in_frame(t, "world", v[0:3], v[3:7])
    assert c._pose_spliced(t, raw.replace(b'"p_WO":[', b'"p_WO":[null,')) is None  # falls back


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


# Foxglove's published message definitions (docs.foxglove.dev, "Message schemas"): every
# field of SceneUpdate and of what it nests, by type name
FOXGLOVE_FIELDS = {
    "foxglove.SceneUpdate": {"deletions", "entities"},
    "foxglove.SceneEntityDeletion": {"timestamp", "type", "id"},
    "foxglove.SceneEntity": {"timestamp", "frame_id", "id", "lifetime", "frame_locked", "metadata", "arrows", "cubes",
                             "spheres", "cylinders", "lines", "triangles", "texts", "models"},
    "foxglove.KeyValuePair": {"key", "value"},
    "foxglove.ArrowPrimitive": {"pose", "shaft_length", "shaft_diameter", "head_length", "head_diameter", "color"},
    "foxglove.CubePrimitive": {"pose", "size", "color"},
    "foxglove.SpherePrimitive": {"pose", "size", "color"},
    "foxglove.CylinderPrimitive": {"pose", "size", "bottom_scale", "top_scale", "color"},
    "foxglove.LinePrimitive": {"type", "pose", "thickness", "scale_invariant", "points", "color", "colors", "indices"},
    "foxglove.TriangleListPrimitive": {"pose", "points", "color", "colors", "indices"},
    "foxglove.TextPrimitive": {"pose", "billboard", "font_size", "scale_invariant", "color", "text"},
    "foxglove.ModelPrimitive": {"pose", "scale", "color", "override_color", "url", "media_type", "data"},
    "foxglove.Pose": {"position", "orientation"},
    "foxglove.Vector3": {"x", "y", "z"},
    "foxglove.Point3": {"x", "y", "z"},
    "foxglove.Quaternion": {"x", "y", "z", "w"},
    "foxglove.Color": {"r", "g", "b", "a"},
}


def _typed_nodes(schema: dict):
    """Every (sub)schema with a foxglove title, through properties and array items."""
    if str(schema.get("title", "")).startswith("foxglove.") and "properties" in schema:
        yield schema
    for sub in schema.get("properties", {}).values():
        yield from _typed_nodes(sub)
    if isinstance(schema.get("items"), dict):
        yield from _typed_nodes(schema["items"])


def test_the_scene_update_schema_has_every_field_of_foxglove_s_definitions():
    from ground_station.foxglove import SCENE_UPDATE

    seen = {}
    for node in _typed_nodes(SCENE_UPDATE):
        seen.setdefault(node["title"], set(node["properties"]))
    assert seen == FOXGLOVE_FIELDS
    entity = SCENE_UPDATE["properties"]["entities"]["items"]
    for name, sub in entity["properties"].items():  # no list left untyped
        if sub.get("type") == "array":
            assert "items" in sub, name
    assert not errors({"deletions": [{"timestamp": {"sec": 1, "nsec": 0}, "type": 1, "id": ""}], "entities": []},
                      SCENE_UPDATE)
    assert errors({"deletions": [{"timestamp": {"sec": 1, "nsec": 0}, "type": 2, "id": ""}], "entities": []},
                  SCENE_UPDATE)  # no such deletion type
