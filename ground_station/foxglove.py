"""Builders of Foxglove's messages from our quantities. Pure.

The types are Foxglove's own, as Foxglove maintains them: the protobuf messages of
`foxglove-schemas-protobuf` (foxglove.FrameTransforms, PoseInFrame, Log, SceneUpdate and what
they nest). ground_station.mcap_io writes them with protobuf encoding, each type's
FileDescriptorSet stored in the log as its schema.

Conventions at this edge: our quaternions are (w, x, y, z), Foxglove's fields x, y, z, w;
times are simulation time [s], a google.protobuf.Timestamp in Foxglove's messages. Doubles
carry NaN and infinity as they are (protobuf has no null).

The recorder's most frequent messages (/tf: one per AM and physics step; /sim/object/pose:
one per step) are filled in place: `frame_transforms` and `pose_in_frame` make a message once
with its frame names, `set_transforms` and `set_pose_in_frame` write a sample's time and poses
into it, ~3x cheaper than building the nested messages anew (a test compares the bytes with
such a literal construction).
"""
from __future__ import annotations

from typing import Sequence

from foxglove_schemas_protobuf.ArrowPrimitive_pb2 import ArrowPrimitive
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
from foxglove_schemas_protobuf.CylinderPrimitive_pb2 import CylinderPrimitive
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from foxglove_schemas_protobuf.TextPrimitive_pb2 import TextPrimitive
from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
from google.protobuf.timestamp_pb2 import Timestamp

__all__ = ["ArrowPrimitive", "Color", "CubePrimitive", "CylinderPrimitive", "FrameTransforms", "LinePrimitive", "Log",
           "Point3", "Pose", "PoseInFrame", "SceneEntity", "SceneUpdate", "TextPrimitive", "Vector3"]

LOG_LEVELS = {"debug": Log.DEBUG, "info": Log.INFO, "warning": Log.WARNING, "error": Log.ERROR, "fatal": Log.FATAL}


def sec_nsec(t_s: float) -> tuple[int, int]:
    """(seconds, nanoseconds) of a simulation time t_s >= 0 [s], rounded to the nanosecond."""
    return divmod(max(0, round(t_s * 1e9)), 1_000_000_000)


def stamp(t_s: float) -> Timestamp:
    s, ns = sec_nsec(t_s)
    return Timestamp(seconds=s, nanos=ns)


def vec3(p: Sequence[float]) -> Vector3:
    x, y, z = p
    return Vector3(x=x, y=y, z=z)


def point3(p: Sequence[float]) -> Point3:
    x, y, z = p
    return Point3(x=x, y=y, z=z)


def pose(p: Sequence[float], q_wxyz: Sequence[float]) -> Pose:
    out = Pose()
    set_pose(out, p, q_wxyz)
    return out


def set_pose(out: Pose, p: Sequence[float], q_wxyz: Sequence[float]) -> None:
    """out's position p [m] and orientation, our (w, x, y, z) in Foxglove's fields. ValueError
    for a vector that is not 3 long or a quaternion that is not 4 long."""
    v, q = out.position, out.orientation
    v.x, v.y, v.z = p
    q.w, q.x, q.y, q.z = q_wxyz


# ----------------------------------------------------------------------------- the hot messages, filled in place
def frame_transforms(parent: str, children: Sequence[str]) -> FrameTransforms:
    """A FrameTransforms of one transform parent -> child per child, frame names set: the
    message set_transforms fills."""
    out = FrameTransforms()
    for child in children:
        out.transforms.add(parent_frame_id=parent, child_frame_id=child)
    return out


def set_transforms(out: FrameTransforms, t_s: float, poses: Sequence[tuple[Sequence[float], Sequence[float]]]
                   ) -> FrameTransforms:
    """out (made by frame_transforms) at time t_s [s], its transforms' translations [m] and
    rotations (w, x, y, z) those of `poses`, one (p, q) per child in order."""
    s, ns = sec_nsec(t_s)
    for tf, (p, q) in zip(out.transforms, poses, strict=True):
        ts = tf.timestamp
        ts.seconds, ts.nanos = s, ns
        v, r = tf.translation, tf.rotation
        v.x, v.y, v.z = p
        r.w, r.x, r.y, r.z = q
    return out


def pose_in_frame(frame_id: str) -> PoseInFrame:
    """A PoseInFrame in frame_id: the message set_pose_in_frame fills."""
    return PoseInFrame(frame_id=frame_id)


def set_pose_in_frame(out: PoseInFrame, t_s: float, p: Sequence[float], q_wxyz: Sequence[float]) -> PoseInFrame:
    ts = out.timestamp
    ts.seconds, ts.nanos = sec_nsec(t_s)
    set_pose(out.pose, p, q_wxyz)
    return out


# ----------------------------------------------------------------------------- the rare ones, built anew
def log(t_s: float, level: str, message: str, name: str) -> Log:
    """A foxglove.Log; a level we do not know is UNKNOWN."""
    return Log(timestamp=stamp(t_s), level=LOG_LEVELS.get(level, Log.UNKNOWN), message=message, name=name)


def color(r: float, g: float, b: float, a: float = 1.0) -> Color:
    return Color(r=r, g=g, b=b, a=a)


def entity(t_s: float, eid: str, frame_id: str = "world", **primitives) -> SceneEntity:
    """A SceneEntity at time t_s with the given primitive lists (arrows=[...], cubes=[...], ...);
    lifetime 0 (until replaced), not frame-locked. ValueError for a list SceneEntity has not."""
    return SceneEntity(timestamp=stamp(t_s), frame_id=frame_id, id=eid, **primitives)
