"""The MCAP topic contract: what the recorder writes for each telemetry key. Pure.

    key (telemetry.schema.Keys)      MCAP topic                   schema (jsonschema, JSON)
    <p>/am/<id>/controller      ->   /am/<id>/controller          amstack.ControllerState (as received)
    <p>/am/<id>/event           ->   /am/<id>/event               amstack.Event (as received)
                                     /am/<id>/events              foxglove.Log
    <p>/sim/am/<id>/truth       ->   /tf                          foxglove.FrameTransforms: world->am<id>/base, world->am<id>/ee
    <p>/sim/am/<id>/contact     ->   /sim/am/<id>/contact         amstack.PadContact (as received)
    <p>/sim/object              ->   /sim/object/pose             foxglove.PoseInFrame (frame world)
                                     /sim/object/state            amstack.ObjectTruth (as received)
    <p>/sim/event               ->   /sim/event                   amstack.Event (as received)
                                     /events                      foxglove.Log
    <p>/telemetry/<name>        ->   /telemetry/<name>            amstack.PublisherStats (as received)
    (derived, scene_rate_hz)    ->   /scene                       foxglove.SceneUpdate: object, AM bases, arms, pads, contact forces
    (recorder, every flush)     ->   /recorder/stats              amstack.RecorderStats
    anything else under <p>/    ->   /unknown/<key>               (no schema) as received

Log time and publish time of every message = simulation time "t" of its payload [ns].
Every channel is fed by one process, so its log times do not decrease.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field

from telemetry.schema import SCHEMAS as PAYLOAD_SCHEMAS, Channel, Keys, peek_header

from . import foxglove as fg

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

SCHEMAS: dict[str, dict] = {s["title"]: s for s in PAYLOAD_SCHEMAS.values()}
SCHEMAS.update(fg.SCHEMAS)
SCHEMAS[RECORDER_STATS_SCHEMA["title"]] = RECORDER_STATS_SCHEMA
_RAW_SCHEMA = {ch: PAYLOAD_SCHEMAS[ch]["title"] for ch in Channel}

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
    """One MCAP message to write. schema: a key of SCHEMAS, or None (schemaless JSON)."""

    topic: str
    schema: str | None
    log_time_ns: int
    data: bytes


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


@dataclass
class _SceneState:
    truth: dict = field(default_factory=dict)  # sysid -> raw truth payload (parsed when drawn)
    contact: dict = field(default_factory=dict)  # sysid -> raw contact bytes (parsed when drawn)
    object_geometry: dict | None = None  # run_start data["object"]


class Translator:
    """Turns (key, payload bytes) into MCAP messages per the contract and counts seq gaps.

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
        self._scene = _SceneState()

    def translate(self, key: str, data: bytes) -> list[Out]:
        try:
            m = self._parsed[key]
        except KeyError:
            m = self.keys.parse(key)
            if len(self._parsed) < 10_000:
                self._parsed[key] = m

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
                self.malformed += 1
                self.last_error = f"{key}: payload without t/seq ({exc}): {bytes(data[:80])!r}"
                return []
        t, seq = head
        if not (0.0 <= t <= MAX_SIM_TIME_S and 0 <= seq < 2**63):  # NaN fails too
            self.malformed += 1
            self.last_error = f"{key}: implausible t = {t!r} or seq = {seq!r}"
            return []
        self.stats.setdefault(key, KeyStats()).see(seq)
        if t > self.latest_t:
            self.latest_t = t
        ns = _ns(t)
        if m is None:
            self.unknown += 1
            return [Out(f"/unknown/{key}", None, ns, bytes(data))]
        ch, sysid = m.channel, m.sysid
        raw = bytes(data)
        if ch is Channel.CONTROLLER:
            return [Out(controller_topic(sysid), _RAW_SCHEMA[ch], ns, raw)]
        if ch is Channel.CONTACT:
            self._scene.contact[sysid] = raw
            return [Out(contact_topic(sysid), _RAW_SCHEMA[ch], ns, raw)]
        if ch is Channel.PUBLISHER:
            try:
                p = parsed if parsed is not None else json.loads(raw)
                if p["final"]:
                    for k, issued in p["seq_issued"].items():
                        self.stats.setdefault(k, KeyStats()).close(int(issued))
            except (ValueError, KeyError, TypeError, AttributeError) as exc:
                self.malformed += 1
                self.last_error = f"{key}: {type(exc).__name__}: {exc}"
                return []
            return [Out(publisher_topic(m.name), _RAW_SCHEMA[ch], ns, raw)]
        try:
            if ch is Channel.AM_TRUTH:
                self._scene.truth[sysid] = raw
                tf = _tf_spliced(t, sysid, raw)
                if tf is None:  # not our encoder's layout: the slow, general way
                    p = parsed if parsed is not None else json.loads(raw)
                    tf = _dumps({"transforms": [
                        fg.frame_transform(t, "world", base_frame(sysid), p["p_WB"], p["q_WB"]),
                        fg.frame_transform(t, "world", ee_frame(sysid), p["p_WE"], p["q_WE"])]})
                return [Out(TF_TOPIC, "foxglove.FrameTransforms", ns, tf)]
            if ch is Channel.OBJECT:
                pose = _pose_spliced(t, raw)
                p = None
                if pose is None:
                    p = parsed if parsed is not None else json.loads(raw)
                    pose = _dumps(fg.pose_in_frame(t, "world", p["p_WO"], p["q_WO"]))
                out = [Out(OBJECT_POSE_TOPIC, "foxglove.PoseInFrame", ns, pose),
                       Out(OBJECT_STATE_TOPIC, _RAW_SCHEMA[ch], ns, raw)]
                if t >= self._next_scene_t - _SCENE_SLACK * self.scene_period_s:
                    # the next slot of the fixed grid k * period (t + period would drift: a sample
                    # a hair before its slot waits for the next one)
                    self._next_scene_t = (math.floor(t / self.scene_period_s + _SCENE_SLACK) + 1) * self.scene_period_s
                    p = p if p is not None else json.loads(raw)
                    out.append(Out(SCENE_TOPIC, "foxglove.SceneUpdate", ns, _dumps(self._scene_update(t, p))))
                return out
            p = parsed if parsed is not None else json.loads(raw)
            # events
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
            return [Out(am_event_topic(sysid), _RAW_SCHEMA[ch], ns, raw),
                    Out(am_log_topic(sysid), "foxglove.Log", ns, msg)]
        except (ValueError, KeyError, TypeError, IndexError, OverflowError, AttributeError) as exc:
            self.malformed += 1
            self.last_error = f"{key}: {type(exc).__name__}: {exc}"
            return []

    def stats_out(self, wall_s: float, inbox_overflow: int, rejected: int = 0) -> Out:
        body = {"t": self.latest_t, "wall_s": wall_s, "inbox_overflow": inbox_overflow, "malformed": self.malformed,
                "unknown": self.unknown, "rejected": rejected, "keys": {k: s.as_dict() for k, s in sorted(self.stats.items())}}
        return Out(STATS_TOPIC, RECORDER_STATS_SCHEMA["title"], _ns(self.latest_t), _dumps(body))

    # ------------------------------------------------------------------ scene
    def _scene_update(self, t: float, obj: dict) -> dict:
        geo = self._scene.object_geometry or {"shape": "box", "size_m": [0.2, 0.2, 0.2]}
        obj_pose = fg.pose(obj["p_WO"], obj["q_WO"])
        blue = fg.color(0.2, 0.4, 0.8, 0.9)
        if geo.get("shape") == "cylinder":
            d = 2.0 * geo.get("radius_m", 0.1)
            prim = {"cylinders": [{"pose": obj_pose, "size": fg.vec3([d, d, geo.get("height_m", 0.2)]),
                                   "bottom_scale": 1.0, "top_scale": 1.0, "color": blue}]}
        else:
            prim = {"cubes": [{"pose": obj_pose, "size": fg.vec3(geo.get("size_m", [0.2, 0.2, 0.2])), "color": blue}]}
        entities = [fg.entity(t, "object", **prim)]
        for sysid, raw in sorted(self._scene.truth.items()):
            entities.append(self._am_entity(t, sysid, json.loads(raw)))
        return {"deletions": [], "entities": entities}

    def _am_entity(self, t: float, sysid: int, tr: dict) -> dict:
        grey, orange = fg.color(0.25, 0.25, 0.25), fg.color(1.0, 0.55, 0.0)
        base = {"pose": fg.pose(tr["p_WB"], tr["q_WB"]), "size": fg.vec3([0.5, 0.5, 0.04]),
                "bottom_scale": 1.0, "top_scale": 1.0, "color": fg.color(0.3, 0.3, 0.3, 0.6)}
        arm = {"type": 0, "pose": fg.pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]), "thickness": 0.015,
               "scale_invariant": False, "points": [fg.vec3(p) for p in [tr["p_WB"], *tr.get("p_W_joints", ()), tr["p_WE"]]], "color": grey,
               "colors": [], "indices": []}
        pad = {"pose": fg.pose(tr["p_WE"], tr["q_WE"]), "size": fg.vec3([0.01, 0.06, 0.06]), "color": orange}
        label = {"pose": fg.pose([tr["p_WB"][0], tr["p_WB"][1], tr["p_WB"][2] + 0.15], [1.0, 0.0, 0.0, 0.0]),
                 "billboard": True, "font_size": 14.0, "scale_invariant": True, "color": fg.color(1, 1, 1),
                 "text": f"am{sysid}"}
        arrows = []
        raw = self._scene.contact.get(sysid)
        if raw is not None:
            c = json.loads(raw)
            if c.get("n_points", 0) > 0:
                f = [c["normal_force_n"] * n + s for n, s in zip(c["normal_W"], c["tangential_force_W"])]
                mag = math.sqrt(sum(v * v for v in f))
                if mag > 1e-6:
                    arrows.append({"pose": fg.pose(c["point_W"], fg.quat_x_to(f)), "shaft_length": 0.02 * mag,
                                   "shaft_diameter": 0.008, "head_length": 0.02, "head_diameter": 0.02,
                                   "color": fg.color(0.9, 0.1, 0.1)})
        return fg.entity(t, f"am{sysid}", cylinders=[base], lines=[arm], cubes=[pad], texts=[label], arrows=arrows)
