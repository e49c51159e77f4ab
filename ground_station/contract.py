"""The MCAP topic contract: what the recorder writes for each telemetry key. Pure.

    key (telemetry.schema.Keys)      MCAP topic                   schema
    <p>/am/<id>/controller      ->   /am/<id>/controller          amstack/ControllerState (ros1) as received
    <p>/am/<id>/event           ->   /am/<id>/event               amstack.Event (as received)
                                     /am/<id>/events              foxglove.Log
    <p>/sim/am/<id>/truth       ->   /tf                          foxglove.FrameTransforms: world->am<id>/base, world->am<id>/ee
                                     /sim/am/<id>/truth           amstack/AmTruth (ros1) as received
    <p>/sim/am/<id>/contact     ->   /sim/am/<id>/contact         amstack/PadContact (ros1) as received
    <p>/sim/object              ->   /sim/object/pose             foxglove.PoseInFrame (frame world)
                                     /sim/object/state            amstack/ObjectTruth (ros1) as received
    <p>/sim/event               ->   /sim/event                   amstack.Event (as received)
                                     /events                      foxglove.Log
    <p>/telemetry/<name>        ->   /telemetry/<name>            amstack.PublisherStats (as received)
    (derived, scene_rate_hz)    ->   /scene                       foxglove.SceneUpdate: object, AM bases, arms, pads, contact forces
    (recorder, every flush)     ->   /recorder/stats              amstack.RecorderStats
    anything else under <p>/    ->   /unknown/<key>               (no schema) JSON as received; binary: counted only

The foxglove.* channels are Foxglove's own protobuf types (foxglove-schemas-protobuf; message
encoding `protobuf`, the schema the type's FileDescriptorSet), declared once in DERIVED: topic,
type and builder. Other schemas with a dot are JSON Schemas of JSON messages; those with a slash
are ROS 1 .msg texts of binary messages (telemetry.binary), written when the channel's first
sample was binary (a JSON-speaking publisher's channel is JSON: amstack.ControllerState, ...).
Log time and publish time of every message = simulation time "t" of its payload [ns].
Every channel is fed by one process, so its log times do not decrease.
"""
from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass
from typing import Callable

import msgspec

from telemetry.binary import (BY_NAME as ROS1_SCHEMAS, HEADER, JSON_TITLE, MESSAGES as BINARY_MESSAGES,
                              OBJECT_POSE as OBJECT_POSE_STRUCT, TRUTH_POSES, from_dict, to_dict)
from telemetry.schema import SCHEMAS as PAYLOAD_SCHEMAS, Channel, Keys, encode, peek_header

from . import foxglove as fg
from .scene import SceneState

RECORDER_STATS_SCHEMA = {
    "title": "amstack.RecorderStats", "type": "object",
    "description": "What the recorder received and lost, per telemetry key, so far",
    "required": ["t", "wall_s", "keys", "inbox_overflow", "malformed", "unknown"],
    "properties": {
        "t": {"type": "number"}, "wall_s": {"type": "number"},
        "inbox_overflow": {"type": "integer", "minimum": 0}, "malformed": {"type": "integer", "minimum": 0},
        "unknown": {"type": "integer", "minimum": 0},
        "rejected": {"type": "integer", "minimum": 0,
                     "description": "samples dropped unauthenticated (telemetry.auth; optional)"},
        "keys": {"type": "object", "description": "key -> {received, first_seq, last_seq, missing, reordered, restarts}"},
    },
}

SCHEMAS: dict[str, dict] = {s["title"]: s for s in PAYLOAD_SCHEMAS.values()}  # JSON Schemas by title
SCHEMAS[RECORDER_STATS_SCHEMA["title"]] = RECORDER_STATS_SCHEMA
_RAW_SCHEMA = {ch: PAYLOAD_SCHEMAS[ch]["title"] for ch in Channel}
ROS1 = "ros1"  # MCAP message encoding of the binary channels (schema encoding ros1msg; ROS1_SCHEMAS by name)
PROTOBUF = "protobuf"  # MCAP message encoding of Foxglove's types (schema encoding protobuf; PROTOBUF_TYPES by name)


def json_schema(name: str) -> dict:
    """The JSON Schema of a schema name of the contract: the payload's, also for the .msg
    name of a binary channel ('amstack/ControllerState' -> amstack.ControllerState)."""
    return SCHEMAS[JSON_TITLE.get(name, name)]


@dataclass(frozen=True)
class Derived:
    """A channel the recorder derives in one of Foxglove's types: its topic ('{sysid}' stands
    for the AM's), the protobuf message type, the builder that makes or fills the message
    (ground_station.foxglove, .scene), and what it is made of."""

    topic: str
    message: type
    build: Callable
    source: str

    @property
    def schema(self) -> str:
        """The MCAP schema name: the type's full protobuf name (foxglove.FrameTransforms, ...)."""
        return self.message.DESCRIPTOR.full_name


TF = Derived("/tf", fg.FrameTransforms, fg.set_transforms,
             "each AM truth sample: world -> am<sysid>/base, world -> am<sysid>/ee")
OBJECT_POSE = Derived("/sim/object/pose", fg.PoseInFrame, fg.set_pose_in_frame, "each object sample, frame world")
SCENE = Derived("/scene", fg.SceneUpdate, SceneState.update,
                "scene_rate_hz per simulated second, at an object sample: the object, each AM's base, arm, pad "
                "and contact force")
SIM_LOG = Derived("/events", fg.Log, fg.log, "each simulator event")
AM_LOG = Derived("/am/{sysid}/events", fg.Log, fg.log, "each event of the AM's companion")
DERIVED = (TF, OBJECT_POSE, SCENE, SIM_LOG, AM_LOG)
PROTOBUF_TYPES: dict[str, type] = {d.schema: d.message for d in DERIVED}  # MCAP schema name -> message type

TF_TOPIC = TF.topic
SCENE_TOPIC = SCENE.topic
STATS_TOPIC = "/recorder/stats"
OBJECT_POSE_TOPIC = OBJECT_POSE.topic
OBJECT_STATE_TOPIC = "/sim/object/state"
SIM_EVENT_TOPIC = "/sim/event"
EVENTS_TOPIC = SIM_LOG.topic


def controller_topic(sysid: int) -> str:
    return f"/am/{sysid}/controller"


def contact_topic(sysid: int) -> str:
    return f"/sim/am/{sysid}/contact"


def truth_topic(sysid: int) -> str:
    """The AM's ground truth as sent, beside /tf: it carries the flight controller's estimate
    of the base (p_WB_est, ...) next to the true pose, to plot one against the other."""
    return f"/sim/am/{sysid}/truth"


def am_event_topic(sysid: int) -> str:
    return f"/am/{sysid}/event"


def am_log_topic(sysid: int) -> str:
    return AM_LOG.topic.format(sysid=sysid)


def publisher_topic(name: str) -> str:
    return f"/telemetry/{name}"


def base_frame(sysid: int) -> str:
    return f"am{sysid}/base"


def ee_frame(sysid: int) -> str:
    return f"am{sysid}/ee"


@dataclass(frozen=True)
class Out:
    """One MCAP message to write. schema: a key of SCHEMAS (encoding json), of ROS1_SCHEMAS
    (encoding ros1), of PROTOBUF_TYPES (encoding protobuf), or None (schemaless JSON)."""

    topic: str
    schema: str | None
    log_time_ns: int
    data: bytes
    encoding: str = "json"


@dataclass
class KeyStats:
    """Sequence accounting of one key. missing: seq numbers skipped, the head (seq numbers
    before the first one received) included (lost in the publisher's queue, in zenoh or in
    the recorder's inbox, or published before the recorder listened); reordered: seq not above the last one;
    restarts: seq fell back to 0 (the publisher restarted)."""

    received: int = 0
    first_seq: int = -1
    last_seq: int = -1
    missing: int = 0
    reordered: int = 0
    restarts: int = 0

    def close(self, issued: int) -> None:
        """The publisher's final count: seq numbers 0..issued-1 were issued. Those after the
        last one received are lost at the tail of the key (no later sample shows the gap)."""
        if issued - 1 > self.last_seq:
            self.missing += issued - 1 - self.last_seq
            self.last_seq = issued - 1

    def see(self, seq: int) -> None:
        self.received += 1
        if self.first_seq < 0:
            # seq numbers start at 0: those before the first arrival never reached the log
            # (lost in zenoh, or published before this recorder listened)
            self.first_seq = self.last_seq = seq
            self.missing += seq
            return
        if seq == self.last_seq + 1:
            self.last_seq = seq
        elif seq > self.last_seq:
            self.missing += seq - self.last_seq - 1
            self.last_seq = seq
        elif seq == 0:
            self.restarts += 1
            self.last_seq = 0
        else:
            self.reordered += 1

    def as_dict(self) -> dict:
        return dict(received=self.received, first_seq=self.first_seq, last_seq=self.last_seq, missing=self.missing,
                    reordered=self.reordered, restarts=self.restarts)


_SCENE_SLACK = 1e-3  # of a /scene period: a sample this close before its slot is on it (float time stamps)
MAX_SIM_TIME_S = 1e7  # a payload claiming a later simulation time (or NaN) is malformed


def _ns(t: float) -> int:
    return max(0, round(t * 1e9))


def _dumps(obj) -> bytes:
    return json.dumps(obj, separators=(",", ":")).encode()


# The poses /tf and /sim/object/pose need, decoded from a JSON sample by msgspec into just
# these fields (the rest skipped unread). JSON has no NaN: a non-finite number comes as
# null (telemetry.schema.encode), and goes into the protobuf double as NaN.
_X = float | None
_V3 = tuple[_X, _X, _X]
_Q = tuple[_X, _X, _X, _X]


class _TruthPoses(msgspec.Struct):
    p_WB: _V3
    q_WB: _Q
    p_WE: _V3
    q_WE: _Q


class _ObjectPose(msgspec.Struct):
    p_WO: _V3
    q_WO: _Q


_TRUTH_POSES = msgspec.json.Decoder(_TruthPoses)
_OBJECT_POSE = msgspec.json.Decoder(_ObjectPose)


def _nan_for_null(v: tuple) -> tuple:
    return v if None not in v else tuple(math.nan if x is None else x for x in v)


class Translator:
    """Turns (key, sample bytes) into MCAP messages per the contract and counts seq gaps.

    A sample is a JSON text or, with binary=True, a binary sample (telemetry.binary) of a
    hot channel. Channels fed as received keep the form their first sample had: JSON on a
    `json` channel with its JSON Schema, binary on a `ros1` channel with its .msg text; a
    later sample of the other form is converted (a publisher of another version), so that
    a topic has one schema. The derived Foxglove topics (DERIVED) are protobuf whatever the
    input; /tf and /sim/object/pose are filled into messages kept here, one per AM and one
    for the object, and serialized (ground_station.foxglove).

    scene_rate_hz: /scene messages per simulated second (0: none), drawn when an object
    sample arrives (the simulator publishes the object after every AM of a step)."""

    def __init__(self, keys: Keys, scene_rate_hz: float = 20.0):
        self.keys = keys
        self.scene_period_s = 1.0 / scene_rate_hz if scene_rate_hz > 0 else math.inf
        self.stats: dict[str, KeyStats] = {}
        self.malformed = 0
        self.unknown = 0
        self.last_error = ""
        self.latest_t = 0.0
        self.run_start: dict | None = None
        self.run_end: dict | None = None
        self._next_scene_t = 0.0 if scene_rate_hz > 0 else math.inf
        self._parsed: dict = {}  # key -> KeyMatch | None (a deployment has few keys)
        self._binary_topic: dict[str, bool] = {}  # topic fed as received -> its first sample was binary
        self._scene = SceneState()
        self._tf: dict[int, fg.FrameTransforms] = {}  # sysid -> its /tf message, filled per sample
        self._object_pose = fg.pose_in_frame("world")

    def _tf_out(self, t: float, ns: int, sysid: int, p_WB, q_WB, p_WE, q_WE) -> Out:
        msg = self._tf.get(sysid)
        if msg is None:
            msg = self._tf[sysid] = fg.frame_transforms("world", (base_frame(sysid), ee_frame(sysid)))
        TF.build(msg, t, ((p_WB, q_WB), (p_WE, q_WE)))
        return Out(TF.topic, TF.schema, ns, msg.SerializeToString(), PROTOBUF)

    def _match(self, key: str):
        try:
            return self._parsed[key]
        except KeyError:
            m = self.keys.parse(key)
            if len(self._parsed) < 10_000:
                self._parsed[key] = m
            return m

    def _bad(self, key: str, why: str) -> list[Out]:
        self.malformed += 1
        self.last_error = f"{key}: {why}"
        return []

    def _seen(self, key: str, t: float, seq: int) -> bool:
        """Count a sample's seq; False (and counted as malformed) if t or seq is implausible."""
        if not (0.0 <= t <= MAX_SIM_TIME_S and 0 <= seq < 2**63):  # NaN fails too
            self._bad(key, f"implausible t = {t!r} or seq = {seq!r}")
            return False
        self.stats.setdefault(key, KeyStats()).see(seq)
        if t > self.latest_t:
            self.latest_t = t
        return True

    def translate(self, key: str, data: bytes, binary: bool = False) -> list[Out]:
        m = self._match(key)
        if binary:
            return self._translate_binary(key, m, data)
        head = peek_header(data)
        parsed = None
        if head is None:  # not in the contract's shape: decode to see whether it is usable at all
            try:
                parsed = json.loads(data)
                head = float(parsed["t"]), int(parsed["seq"])
            except (ValueError, KeyError, TypeError, OverflowError) as exc:
                if m is None:
                    self.unknown += 1
                    return [Out(f"/unknown/{key}", None, _ns(self.latest_t), bytes(data))]
                return self._bad(key, f"payload without t/seq ({exc}): {bytes(data[:80])!r}")
        t, seq = head
        if not self._seen(key, t, seq):
            return []
        ns = _ns(t)
        if m is None:
            self.unknown += 1
            return [Out(f"/unknown/{key}", None, ns, bytes(data))]
        ch, sysid = m.channel, m.sysid
        raw = bytes(data)
        try:
            if ch is Channel.CONTROLLER:
                return [self._as_received(controller_topic(sysid), ch, ns, raw, parsed)]
            if ch is Channel.CONTACT:
                self._scene.contact[sysid] = raw
                return [self._as_received(contact_topic(sysid), ch, ns, raw, parsed)]
            if ch is Channel.PUBLISHER:
                p = parsed if parsed is not None else json.loads(raw)
                if p["final"]:
                    for k, issued in p["seq_issued"].items():
                        self.stats.setdefault(k, KeyStats()).close(int(issued))
                return [Out(publisher_topic(m.name), _RAW_SCHEMA[ch], ns, raw)]
            if ch is Channel.AM_TRUTH:
                self._scene.truth[sysid] = raw
                v = _TRUTH_POSES.decode(raw)
                return [self._tf_out(t, ns, sysid, _nan_for_null(v.p_WB), _nan_for_null(v.q_WB),
                                     _nan_for_null(v.p_WE), _nan_for_null(v.q_WE)),
                        self._as_received(truth_topic(sysid), ch, ns, raw, parsed)]
            if ch is Channel.OBJECT:
                v = _OBJECT_POSE.decode(raw)
                return self._object(t, ns, _nan_for_null(v.p_WO), _nan_for_null(v.q_WO),
                                    self._as_received(OBJECT_STATE_TOPIC, ch, ns, raw, parsed), raw)
            return self._event(key, m, t, ns, raw, parsed if parsed is not None else json.loads(raw))
        except (ValueError, KeyError, TypeError, IndexError, OverflowError, AttributeError, struct.error) as exc:
            return self._bad(key, f"{type(exc).__name__}: {exc}")

    def _translate_binary(self, key: str, m, data: bytes) -> list[Out]:
        msg = None if m is None else BINARY_MESSAGES.get(m.channel)
        if msg is None:
            if m is None:
                self.unknown += 1  # no contract to tell its layout: counted, not written
                return []
            return self._bad(key, "a binary sample on a key whose channel is JSON only")
        try:  # one whole message of the channel's layout (its counts and lengths; the values are not read)
            size = msg.size_of(data)
            if size != len(data):
                raise ValueError(f"{len(data) - size} bytes after the end of the message")
        except ValueError as exc:
            return self._bad(key, f"binary sample: {exc}")
        t, seq = HEADER.unpack_from(data)
        if not self._seen(key, t, seq):
            return []
        ch, sysid, ns, raw = m.channel, m.sysid, _ns(t), bytes(data)
        try:
            if ch is Channel.CONTROLLER:
                return [self._as_received(controller_topic(sysid), ch, ns, raw, None, True)]
            if ch is Channel.CONTACT:
                self._scene.contact[sysid] = (ch, raw)  # decoded if drawn
                return [self._as_received(contact_topic(sysid), ch, ns, raw, None, True)]
            if ch is Channel.AM_TRUTH:
                self._scene.truth[sysid] = (ch, raw)
                v = TRUTH_POSES.unpack_from(raw)  # t, seq, sysid, p_WB, q_WB, p_WE, q_WE
                return [self._tf_out(t, ns, sysid, v[3:6], v[6:10], v[10:13], v[13:17]),
                        self._as_received(truth_topic(sysid), ch, ns, raw, None, True)]
            v = OBJECT_POSE_STRUCT.unpack_from(raw)  # t, seq, p_WO, q_WO
            state = self._as_received(OBJECT_STATE_TOPIC, ch, ns, raw, None, True)
            return self._object(t, ns, v[2:5], v[5:9], state, (ch, raw))
        except (ValueError, KeyError, TypeError, IndexError, OverflowError, struct.error) as exc:
            return self._bad(key, f"{type(exc).__name__}: {exc}")

    def _as_received(self, topic: str, ch: Channel, ns: int, raw: bytes, fields: dict | None,
                     binary: bool = False) -> Out:
        """The message of a channel fed as received, in the form of the topic's first sample.
        fields: the sample decoded, if it was (None: not yet)."""
        first = self._binary_topic.setdefault(topic, binary)
        if first == binary:
            pass
        elif binary:  # a binary sample on a JSON topic
            raw = encode(fields if fields is not None else to_dict(ch, raw))[0]
        else:  # a JSON sample on a binary topic
            raw = from_dict(ch, fields if fields is not None else json.loads(raw))
        if first:
            return Out(topic, BINARY_MESSAGES[ch].name, ns, raw, ROS1)
        return Out(topic, _RAW_SCHEMA[ch], ns, raw)

    def _object(self, t: float, ns: int, p_WO, q_WO, state: Out, sample) -> list[Out]:
        """/sim/object/pose, the state as received and, on its slot, /scene. sample: the object
        sample as SceneState keeps samples (JSON bytes, or (channel, binary sample))."""
        pose = OBJECT_POSE.build(self._object_pose, t, p_WO, q_WO).SerializeToString()
        out = [Out(OBJECT_POSE.topic, OBJECT_POSE.schema, ns, pose, PROTOBUF), state]
        if t >= self._next_scene_t - _SCENE_SLACK * self.scene_period_s:
            # the next slot of the fixed grid k * period (t + period would drift: a sample
            # a hair before its slot waits for the next one)
            self._next_scene_t = (math.floor(t / self.scene_period_s + _SCENE_SLACK) + 1) * self.scene_period_s
            scene = SCENE.build(self._scene, t, sample)
            out.append(Out(SCENE.topic, SCENE.schema, ns, scene.SerializeToString(), PROTOBUF))
        return out

    def _event(self, key: str, m, t: float, ns: int, raw: bytes, p: dict) -> list[Out]:
        ch, sysid = m.channel, m.sysid
        level, kind = p["level"], p["kind"]
        if ch is Channel.SIM_EVENT and kind == "run_start":
            self.run_start = p
            self._scene.object_geometry = (p.get("data") or {}).get("object")
        if ch is Channel.SIM_EVENT and kind == "run_end":
            self.run_end = p
        name = p.get("source", "simulator" if sysid is None else f"am{sysid}")
        log = SIM_LOG if ch is Channel.SIM_EVENT else AM_LOG
        msg = log.build(t, level, f"[{kind}] {p['text']}", name).SerializeToString()
        raw_topic = SIM_EVENT_TOPIC if ch is Channel.SIM_EVENT else am_event_topic(sysid)
        return [Out(raw_topic, _RAW_SCHEMA[ch], ns, raw),
                Out(log.topic.format(sysid=sysid), log.schema, ns, msg, PROTOBUF)]

    def stats_out(self, wall_s: float, inbox_overflow: int, rejected: int = 0) -> Out:
        body = {"t": self.latest_t, "wall_s": wall_s, "inbox_overflow": inbox_overflow, "malformed": self.malformed,
                "unknown": self.unknown, "rejected": rejected, "keys": {k: s.as_dict() for k, s in sorted(self.stats.items())}}
        return Out(STATS_TOPIC, RECORDER_STATS_SCHEMA["title"], _ns(self.latest_t), _dumps(body))
