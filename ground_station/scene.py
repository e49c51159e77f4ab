"""The /scene topic: a foxglove.SceneUpdate (Foxglove's protobuf type) of the object and every
AM, drawn from the latest ground truth the recorder saw (pure).

The recorder keeps each AM's latest truth and contact sample as it arrived (JSON bytes, or a
binary sample with its channel) and draws only at the scene rate, so a sample is decoded only
when it is drawn.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from amcore.so3 import quat_wxyz_from_x_to
from telemetry.binary import to_dict

from . import foxglove as fg


def nan_for_null(x):
    """x with every None (in nested dicts and lists) replaced by NaN: a JSON sample's null
    stands for a non-finite number (telemetry.schema.encode), which a protobuf double holds."""
    if x is None:
        return math.nan
    if isinstance(x, dict):
        return {k: nan_for_null(v) for k, v in x.items()}
    if isinstance(x, list):
        return [nan_for_null(v) for v in x]
    return x


def _fields(sample: bytes | dict | tuple) -> dict:
    """A kept sample's fields: JSON bytes parsed, a (channel, binary sample) decoded; nulls as NaN."""
    if isinstance(sample, (bytes, bytearray)):
        return nan_for_null(json.loads(sample))
    return to_dict(*sample) if isinstance(sample, tuple) else nan_for_null(sample)


@dataclass
class SceneState:
    truth: dict = field(default_factory=dict)  # sysid -> latest truth sample: JSON bytes, (channel, binary), a dict
    contact: dict = field(default_factory=dict)  # sysid -> latest contact sample (likewise)
    object_geometry: dict | None = None  # run_start data["object"]

    def update(self, t: float, obj: bytes | dict | tuple) -> fg.SceneUpdate:
        """The SceneUpdate at time t of the object sample `obj` (as kept: JSON bytes, (channel,
        binary sample), or its fields)."""
        geo = self.object_geometry or {"shape": "box", "size_m": [0.2, 0.2, 0.2]}
        obj = _fields(obj)
        obj_pose = fg.pose(obj["p_WO"], obj["q_WO"])
        blue = fg.color(0.2, 0.4, 0.8, 0.9)
        if geo.get("shape") == "cylinder":
            d = 2.0 * geo.get("radius_m", 0.1)
            prim = {"cylinders": [fg.CylinderPrimitive(pose=obj_pose, size=fg.vec3([d, d, geo.get("height_m", 0.2)]),
                                                       bottom_scale=1.0, top_scale=1.0, color=blue)]}
        else:
            prim = {"cubes": [fg.CubePrimitive(pose=obj_pose, size=fg.vec3(geo.get("size_m", [0.2, 0.2, 0.2])),
                                               color=blue)]}
        entities = [fg.entity(t, "object", **prim)]
        for sysid, sample in sorted(self.truth.items()):
            entities.append(self._am_entity(t, sysid, _fields(sample)))
        return fg.SceneUpdate(entities=entities)

    def _am_entity(self, t: float, sysid: int, tr: dict) -> fg.SceneEntity:
        grey, orange = fg.color(0.25, 0.25, 0.25), fg.color(1.0, 0.55, 0.0)
        base = fg.CylinderPrimitive(pose=fg.pose(tr["p_WB"], tr["q_WB"]), size=fg.vec3([0.5, 0.5, 0.04]),
                                    bottom_scale=1.0, top_scale=1.0, color=fg.color(0.3, 0.3, 0.3, 0.6))
        arm = fg.LinePrimitive(type=fg.LinePrimitive.LINE_STRIP, pose=fg.pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]),
                               thickness=0.015, scale_invariant=False,
                               points=[fg.point3(p) for p in [tr["p_WB"], *tr.get("p_W_joints", ()), tr["p_WE"]]],
                               color=grey)
        pad = fg.CubePrimitive(pose=fg.pose(tr["p_WE"], tr["q_WE"]), size=fg.vec3([0.01, 0.06, 0.06]), color=orange)
        above = [tr["p_WB"][0], tr["p_WB"][1], tr["p_WB"][2] + 0.15]
        label = fg.TextPrimitive(pose=fg.pose(above, [1.0, 0.0, 0.0, 0.0]), billboard=True, font_size=14.0,
                                 scale_invariant=True, color=fg.color(1, 1, 1), text=f"am{sysid}")
        arrows = []
        sample = self.contact.get(sysid)
        if sample is not None:
            c = _fields(sample)
            if c.get("n_points", 0) > 0:
                f = [c["normal_force_n"] * n + s for n, s in zip(c["normal_W"], c["tangential_force_W"])]
                mag = math.sqrt(sum(v * v for v in f))
                if mag > 1e-6:
                    arrows.append(fg.ArrowPrimitive(pose=fg.pose(c["point_W"], quat_wxyz_from_x_to(f)),
                                                    shaft_length=0.02 * mag, shaft_diameter=0.008, head_length=0.02,
                                                    head_diameter=0.02, color=fg.color(0.9, 0.1, 0.1)))
        return fg.entity(t, f"am{sysid}", cylinders=[base], lines=[arm], cubes=[pad], texts=[label], arrows=arrows)
