"""The MCAP topic contract: what the recorder writes for each telemetry key. Pure.

    key (telemetry.schema.Keys)      MCAP topic                   schema
    <p>/am/<id>/controller      ->   /am/<id>/controller          amstack/ControllerState (ros1) as received
    <p>/am/<id>/event           ->   /am/<id>/event               amstack.Event (as received)
                                     /am/<id>/events              foxglove.Log
    <p>/sim/am/<id>/truth       ->   /tf                          foxglove.FrameTransforms: world->am<id>/base, world->am<id>/ee
    <p>/sim/am/<id>/contact     ->   /sim/am/<id>/contact         amstack/PadContact (ros1) as received
    <p>/sim/object              ->   /sim/object/pose             foxglove.PoseInFrame (frame world)
                                     /sim/object/state            amstack/ObjectTruth (ros1) as received
    <p>/sim/event               ->   /sim/event                   amstack.Event (as received)
                                     /events                      foxglove.Log
    <p>/telemetry/<name>        ->   /telemetry/<name>            amstack.PublisherStats (as received)
    (derived, scene_rate_hz)    ->   /scene                       foxglove.SceneUpdate: object, AM bases, arms, pads, contact forces
    (recorder, every flush)     ->   /recorder/stats              amstack.RecorderStats
    anything else under <p>/    ->   /unknown/<key>               (no schema) JSON as received; binary: counted only

Schemas with a dot are JSON Schemas of JSON messages; those with a slash are ROS 1 .msg
texts of binary messages (telemetry.binary), written when the channel's first sample was
binary (a JSON-speaking publisher's channel is JSON: amstack.ControllerState, ...).
Log time and publish time of every message = simulation time "t" of its payload [ns].
Every channel is fed by one process, so its log times do not decrease.
"""
from __future__ import annotations

import json
import math
import re
import struct
from dataclasses import dataclass

from telemetry.binary import (BY_NAME as ROS1_SCHEMAS, HEADER, JSON_TITLE, MESSAGES as BINARY_MESSAGES, OBJECT_POSE,
                              TRUTH_POSES, from_dict, to_dict)
from telemetry.schema import SCHEMAS as PAYLOAD_SCHEMAS, Channel, Keys, encode, finite_or_null, peek_header

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
SCHEMAS.update(fg.SCHEMAS)
SCHEMAS[RECORDER_STATS_SCHEMA["title"]] = RECORDER_STATS_SCHEMA
_RAW_SCHEMA = {ch: PAYLOAD_SCHEMAS[ch]["title"] for ch in Channel}
ROS1 = "ros1"  # MCAP message encoding of the binary channels (schema encoding ros1msg; ROS1_SCHEMAS by name)


def json_schema(name: str) -> dict:
    """The JSON Schema of a schema name of the contract: the payload's, also for the .msg
    name of a binary channel ('amstack/ControllerState' -> amstack.ControllerState)."""
    return SCHEMAS[JSON_TITLE.get(name, name)]

TF_TOPIC = "/tf"
SCENE_TOPIC = "/scene"
STATS_TOPIC = "/recorder/stats"
OBJECT_POSE_TOPIC = "/sim/object/pose"
OBJECT_STATE_TOPIC = "/sim/object/state"
SIM_EVENT_TOPIC = "/sim/event"
EVENTS_TOPIC = "/events"


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
    return f"/am/{sysid}/events"


def publisher_topic(name: str) -> str:
    return f"/telemetry/{name}"


def base_frame(sysid: int) -> str:
    return f"am{sysid}/base"


def ee_frame(sysid: int) -> str:
    return f"am{sysid}/ee"


@dataclass(frozen=True)
class Out:
    """One MCAP message to write. schema: a key of SCHEMAS (encoding json), of ROS1_SCHEMAS
    (encoding ros1), or None (schemaless JSON)."""

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


# Fast path for the high-rate poses: our encoder writes `"name":[a,b,c]` with each number
# in Python's shortest repr, which is valid JSON as it stands; splicing that text into the
# Foxglove message avoids parsing and re-printing ~14 floats per sample (the recorder's
# hottest path). Anything else (nulls, other layouts) takes the general json path.
_ARRAY = re.compile(rb'"([A-Za-z_]+)":\[([^\[\]]*)\]')
_NUMBERS = re.compile(rb"-?[0-9][0-9.eE+\-]*(?:,-?[0-9][0-9.eE+\-]*)*")
_TF = (b'{"timestamp":{"sec":%d,"nsec":%d},"parent_frame_id":"world","child_frame_id":"%s",'
       b'"translation":{"x":%s,"y":%s,"z":%s},"rotation":{"x":%s,"y":%s,"z":%s,"w":%s}}')
_POSE = (b'{"timestamp":{"sec":%d,"nsec":%d},"frame_id":"world","pose":{"position":{"x":%s,"y":%s,"z":%s},'
         b'"orientation":{"x":%s,"y":%s,"z":%s,"w":%s}}}')


def _numbers(data: bytes, names: tuple[bytes, ...], sizes: tuple[int, ...]) -> list[list[bytes]] | None:
    found = dict(_ARRAY.findall(data))
    out = []
    for name, n in zip(names, sizes):
        v = found.get(name)
        if v is None or not _NUMBERS.fullmatch(v):  # null, NaN, strings: not for splicing
            return None
        parts = v.split(b",")
        if len(parts) != n:
            return None
        out.append(parts)
    return out


def _sec_nsec(t: float) -> tuple[int, int]:
    return divmod(_ns(t), 1_000_000_000)


def _tf_spliced(t: float, sysid: int, data: bytes) -> bytes | None:
    v = _numbers(data, (b"p_WB", b"q_WB", b"p_WE", b"q_WE"), (3, 4, 3, 4))
    if v is None:
        return None
    (pb, qb, pe, qe), (sec, nsec) = v, _sec_nsec(t)
    base = _TF % (sec, nsec, base_frame(sysid).encode(), *pb, qb[1], qb[2], qb[3], qb[0])
    ee = _TF % (sec, nsec, ee_frame(sysid).encode(), *pe, qe[1], qe[2], qe[3], qe[0])
    return b'{"transforms":[' + base + b"," + ee + b"]}"


def _pose_spliced(t: float, data: bytes) -> bytes | None:
    v = _numbers(data, (b"p_WO", b"q_WO"), (3, 4))
    if v is None:
        return None
    (p, q), (sec, nsec) = v, _sec_nsec(t)
    return _POSE % (sec, nsec, *p, q[1], q[2], q[3], q[0])


def _poses(p: dict) -> tuple:
    return p["p_WB"], p["q_WB"], p["p_WE"], p["q_WE"]


def _finite_numbers(*vectors) -> bool:
    return all(math.isfinite(x) for v in vectors for x in v)


# The same messages from a decoded binary sample's floats: `%r` prints Python's shortest
# repr, which is what json.dumps writes for a finite float (non-finite ones take the
# general path, where they become null as in a JSON sample).
_TF_R = _TF.replace(b'"child_frame_id":"%s"', b'"child_frame_id":"%b"').replace(b"%s", b"%r")
_POSE_R = _POSE.replace(b"%s", b"%r")


def _tf_of(t: float, sysid: int, pb, qb, pe, qe) -> bytes:
    if not _finite_numbers(pb, qb, pe, qe) or (len(pb), len(qb), len(pe), len(qe)) != (3, 4, 3, 4):
        return _dumps(finite_or_null({"transforms": [fg.frame_transform(t, "world", base_frame(sysid), pb, qb),
                                              fg.frame_transform(t, "world", ee_frame(sysid), pe, qe)]}))
    sec, nsec = _sec_nsec(t)
    base = _TF_R % (sec, nsec, base_frame(sysid).encode(), *pb, qb[1], qb[2], qb[3], qb[0])
    ee = _TF_R % (sec, nsec, ee_frame(sysid).encode(), *pe, qe[1], qe[2], qe[3], qe[0])
    return b'{"transforms":[' + base + b"," + ee + b"]}"


def _pose_of(t: float, pos, q) -> bytes:
    if not _finite_numbers(pos, q) or (len(pos), len(q)) != (3, 4):
        return _dumps(finite_or_null(fg.pose_in_frame(t, "world", pos, q)))
    sec, nsec = _sec_nsec(t)
    return _POSE_R % (sec, nsec, *pos, q[1], q[2], q[3], q[0])


class Translator:
    """Turns (key, sample bytes) into MCAP messages per the contract and counts seq gaps.

    A sample is a JSON text or, with binary=True, a binary sample (telemetry.binary) of a
    hot channel. Channels fed as received keep the form their first sample had: JSON on a
    `json` channel with its JSON Schema, binary on a `ros1` channel with its .msg text; a
    later sample of the other form is converted (a publisher of another version), so that
    a topic has one schema. The derived Foxglove topics are JSON whatever the input.

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
                tf = _tf_spliced(t, sysid, raw)  # None: not our encoder's layout, the slow, general way
                return [Out(TF_TOPIC, "foxglove.FrameTransforms", ns,
                            tf if tf is not None else _tf_of(t, sysid, *_poses(parsed or json.loads(raw)))),
                        self._as_received(truth_topic(sysid), ch, ns, raw, parsed)]
            if ch is Channel.OBJECT:
                pose = _pose_spliced(t, raw)
                if pose is None:
                    parsed = parsed or json.loads(raw)
                    pose = _pose_of(t, parsed["p_WO"], parsed["q_WO"])
                return self._object(t, ns, pose, self._as_received(OBJECT_STATE_TOPIC, ch, ns, raw, parsed),
                                    lambda: parsed or json.loads(raw))
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
                v = TRUTH_POSES.unpack_from(raw)
                tf = _tf_of(t, sysid, v[3:6], v[6:10], v[10:13], v[13:17])  # p_WB, q_WB, p_WE, q_WE
                return [Out(TF_TOPIC, "foxglove.FrameTransforms", ns, tf),
                        self._as_received(truth_topic(sysid), ch, ns, raw, None, True)]
            v = OBJECT_POSE.unpack_from(raw)
            state = self._as_received(OBJECT_STATE_TOPIC, ch, ns, raw, None, True)
            return self._object(t, ns, _pose_of(t, v[2:5], v[5:9]), state, lambda: to_dict(ch, raw))
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

    def _object(self, t: float, ns: int, pose: bytes, state: Out, fields) -> list[Out]:
        out = [Out(OBJECT_POSE_TOPIC, "foxglove.PoseInFrame", ns, pose), state]
        if t >= self._next_scene_t - _SCENE_SLACK * self.scene_period_s:
            # the next slot of the fixed grid k * period (t + period would drift: a sample
            # a hair before its slot waits for the next one)
            self._next_scene_t = (math.floor(t / self.scene_period_s + _SCENE_SLACK) + 1) * self.scene_period_s
            scene = finite_or_null(self._scene.update(t, fields()))
            out.append(Out(SCENE_TOPIC, "foxglove.SceneUpdate", ns, _dumps(scene)))
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
        msg = _dumps(fg.log(t, level, f"[{kind}] {p['text']}", name))
        if ch is Channel.SIM_EVENT:
            return [Out(SIM_EVENT_TOPIC, _RAW_SCHEMA[ch], ns, raw), Out(EVENTS_TOPIC, "foxglove.Log", ns, msg)]
        return [Out(am_event_topic(sysid), _RAW_SCHEMA[ch], ns, raw), Out(am_log_topic(sysid), "foxglove.Log", ns, msg)]

    def stats_out(self, wall_s: float, inbox_overflow: int, rejected: int = 0) -> Out:
        body = {"t": self.latest_t, "wall_s": wall_s, "inbox_overflow": inbox_overflow, "malformed": self.malformed,
                "unknown": self.unknown, "rejected": rejected, "keys": {k: s.as_dict() for k, s in sorted(self.stats.items())}}
        return Out(STATS_TOPIC, RECORDER_STATS_SCHEMA["title"], _ns(self.latest_t), _dumps(body))
