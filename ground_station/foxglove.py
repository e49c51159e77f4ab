"""Foxglove message types as JSON schemas (MCAP 'jsonschema' encoding, JSON messages),
and builders for the messages the recorder writes. Pure.

Field names follow Foxglove's published message definitions (foxglove.PoseInFrame,
FrameTransforms, Log, SceneUpdate); the schemas below are written out here, every field
of Foxglove's definitions included, also those the recorder leaves empty (bytes as base64
strings, as Foxglove's JSON schemas have them).
"""
from __future__ import annotations

import math
from typing import Sequence

# ----------------------------------------------------------------------------- schemas
_TIME = {"type": "object", "title": "time", "required": ["sec", "nsec"],
         "properties": {"sec": {"type": "integer", "minimum": 0},
                        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}
_DURATION = {"type": "object", "title": "duration", "required": ["sec", "nsec"],
             "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}}


def _xyz(title: str, names: str = "xyz") -> dict:
    return {"title": title, "type": "object", "required": list(names),
            "properties": {n: {"type": "number"} for n in names}}


_VECTOR3 = _xyz("foxglove.Vector3")
_POINT3 = _xyz("foxglove.Point3")
_QUATERNION = _xyz("foxglove.Quaternion", "xyzw")
_COLOR = _xyz("foxglove.Color", "rgba")
_POSE = {"title": "foxglove.Pose", "type": "object", "required": ["position", "orientation"],
         "properties": {"position": _VECTOR3, "orientation": _QUATERNION}}


def _message(title: str, props: dict, description: str = "") -> dict:
    return {"title": title, "description": description, "type": "object", "properties": props,
            "required": list(props)}


POSE_IN_FRAME = _message("foxglove.PoseInFrame", {"timestamp": _TIME, "frame_id": {"type": "string"}, "pose": _POSE},
                         "A timestamped pose for an object or reference frame in 3D space")

_FRAME_TRANSFORM = _message("foxglove.FrameTransform", {
    "timestamp": _TIME, "parent_frame_id": {"type": "string"}, "child_frame_id": {"type": "string"},
    "translation": _VECTOR3, "rotation": _QUATERNION})
FRAME_TRANSFORMS = _message("foxglove.FrameTransforms", {"transforms": {"type": "array", "items": _FRAME_TRANSFORM}},
                            "An array of FrameTransform messages")

LOG = _message("foxglove.Log", {
    "timestamp": _TIME,
    "level": {"title": "foxglove.LogLevel", "oneOf": [{"title": n, "const": i} for i, n in enumerate(
        ("UNKNOWN", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL"))]},
    "message": {"type": "string"}, "name": {"type": "string"}, "file": {"type": "string"},
    "line": {"type": "integer", "minimum": 0}}, "A log message")

_ARROW = _message("foxglove.ArrowPrimitive", {
    "pose": _POSE, "shaft_length": {"type": "number"}, "shaft_diameter": {"type": "number"},
    "head_length": {"type": "number"}, "head_diameter": {"type": "number"}, "color": _COLOR})
_CUBE = _message("foxglove.CubePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR})
_CYLINDER = _message("foxglove.CylinderPrimitive", {
    "pose": _POSE, "size": _VECTOR3, "bottom_scale": {"type": "number"}, "top_scale": {"type": "number"},
    "color": _COLOR})
_LINE = _message("foxglove.LinePrimitive", {
    "type": {"title": "foxglove.LineType", "oneOf": [{"title": n, "const": i} for i, n in enumerate(
        ("LINE_STRIP", "LINE_LOOP", "LINE_LIST"))]},
    "pose": _POSE, "thickness": {"type": "number"}, "scale_invariant": {"type": "boolean"},
    "points": {"type": "array", "items": _POINT3}, "color": _COLOR,
    "colors": {"type": "array", "items": _COLOR}, "indices": {"type": "array", "items": {"type": "integer"}}})
_SPHERE = _message("foxglove.SpherePrimitive", {"pose": _POSE, "size": _VECTOR3, "color": _COLOR})
_TRIANGLES = _message("foxglove.TriangleListPrimitive", {
    "pose": _POSE, "points": {"type": "array", "items": _POINT3}, "color": _COLOR,
    "colors": {"type": "array", "items": _COLOR}, "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}}})
_MODEL = _message("foxglove.ModelPrimitive", {
    "pose": _POSE, "scale": _VECTOR3, "color": _COLOR, "override_color": {"type": "boolean"},
    "url": {"type": "string"}, "media_type": {"type": "string"},
    "data": {"type": "string", "contentEncoding": "base64"}})
_KEY_VALUE = _message("foxglove.KeyValuePair", {"key": {"type": "string"}, "value": {"type": "string"}})
_DELETION = _message("foxglove.SceneEntityDeletion", {
    "timestamp": _TIME,
    "type": {"title": "foxglove.SceneEntityDeletionType", "oneOf": [{"title": n, "const": i} for i, n in enumerate(
        ("MATCHING_ID", "ALL"))]},
    "id": {"type": "string"}})
_TEXT = _message("foxglove.TextPrimitive", {
    "pose": _POSE, "billboard": {"type": "boolean"}, "font_size": {"type": "number"},
    "scale_invariant": {"type": "boolean"}, "color": _COLOR, "text": {"type": "string"}})
_ENTITY = _message("foxglove.SceneEntity", {
    "timestamp": _TIME, "frame_id": {"type": "string"}, "id": {"type": "string"}, "lifetime": _DURATION,
    "frame_locked": {"type": "boolean"}, "metadata": {"type": "array", "items": _KEY_VALUE},
    "arrows": {"type": "array", "items": _ARROW}, "cubes": {"type": "array", "items": _CUBE},
    "spheres": {"type": "array", "items": _SPHERE}, "cylinders": {"type": "array", "items": _CYLINDER},
    "lines": {"type": "array", "items": _LINE}, "triangles": {"type": "array", "items": _TRIANGLES},
    "texts": {"type": "array", "items": _TEXT}, "models": {"type": "array", "items": _MODEL}})
SCENE_UPDATE = _message("foxglove.SceneUpdate", {"deletions": {"type": "array", "items": _DELETION},
                                                 "entities": {"type": "array", "items": _ENTITY}},
                        "An update to the entities displayed in a 3D scene")

SCHEMAS = {s["title"]: s for s in (POSE_IN_FRAME, FRAME_TRANSFORMS, LOG, SCENE_UPDATE)}

LOG_LEVELS = {"debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}


# ----------------------------------------------------------------------------- builders
def stamp(t_s: float) -> dict:
    """Foxglove time of a simulation time t_s >= 0 [s]."""
    ns = max(0, round(t_s * 1e9))
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def vec3(p: Sequence[float]) -> dict:
    return {"x": p[0], "y": p[1], "z": p[2]}


def quat(q_wxyz: Sequence[float]) -> dict:
    """Foxglove quaternion (x, y, z, w) of our (w, x, y, z)."""
    return {"x": q_wxyz[1], "y": q_wxyz[2], "z": q_wxyz[3], "w": q_wxyz[0]}


def pose(p: Sequence[float], q_wxyz: Sequence[float]) -> dict:
    return {"position": vec3(p), "orientation": quat(q_wxyz)}


def pose_in_frame(t_s: float, frame_id: str, p, q_wxyz) -> dict:
    return {"timestamp": stamp(t_s), "frame_id": frame_id, "pose": pose(p, q_wxyz)}


def frame_transform(t_s: float, parent: str, child: str, p, q_wxyz) -> dict:
    return {"timestamp": stamp(t_s), "parent_frame_id": parent, "child_frame_id": child,
            "translation": vec3(p), "rotation": quat(q_wxyz)}


def log(t_s: float, level: str, message: str, name: str) -> dict:
    return {"timestamp": stamp(t_s), "level": LOG_LEVELS.get(level, 0), "message": message, "name": name,
            "file": "", "line": 0}


def color(r: float, g: float, b: float, a: float = 1.0) -> dict:
    return {"r": r, "g": g, "b": b, "a": a}


def quat_x_to(d: Sequence[float]) -> list[float]:
    """(w, x, y, z) of the shortest rotation taking +x to the direction d (arrows point along +x)."""
    n = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
    if n == 0.0:
        return [1.0, 0.0, 0.0, 0.0]
    ux, uy, uz = d[0] / n, d[1] / n, d[2] / n
    w = 1.0 + ux  # q = (1 + x.u, x cross u) normalised
    if w < 1e-9:  # opposite to +x: half turn about z
        return [0.0, 0.0, 0.0, 1.0]
    qx, qy, qz = 0.0, -uz, uy
    m = math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
    return [w / m, qx / m, qy / m, qz / m]


def entity(t_s: float, eid: str, frame_id: str = "world", **primitives) -> dict:
    e = {"timestamp": stamp(t_s), "frame_id": frame_id, "id": eid, "lifetime": {"sec": 0, "nsec": 0},
         "frame_locked": False, "metadata": [], "arrows": [], "cubes": [], "spheres": [], "cylinders": [],
         "lines": [], "triangles": [], "texts": [], "models": []}
    for k, v in primitives.items():
        if k not in e:
            raise KeyError(f"SceneEntity has no primitive list {k!r}")
        e[k] = v
    return e
