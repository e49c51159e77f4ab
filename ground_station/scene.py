"""The /scene topic: a foxglove.SceneUpdate of the object and every AM, drawn from the latest
ground truth the recorder saw (pure).

The recorder keeps each AM's latest truth and contact sample as it arrived (JSON bytes, or a
binary sample with its channel) and draws only at the scene rate, so a sample is decoded only
when it is drawn.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

from telemetry.binary import to_dict

from . import foxglove as fg


def _fields(sample: bytes | dict | tuple) -> dict:
    """A kept sample's fields: JSON bytes parsed, a (channel, binary sample) decoded."""
    if isinstance(sample, (bytes, bytearray)):
        return json.loads(sample)
    return to_dict(*sample) if isinstance(sample, tuple) else sample


@dataclass
class SceneState:
    truth: dict = field(default_factory=dict)  # sysid -> latest truth sample: JSON bytes, (channel, binary), a dict
    contact: dict = field(default_factory=dict)  # sysid -> latest contact sample (likewise)
    object_geometry: dict | None = None  # run_start data["object"]

    def update(self, t: float, obj: dict) -> dict:
        """The SceneUpdate at time t of the object sample `obj` (JSON payload fields)."""
        geo = self.object_geometry or {"shape": "box", "size_m": [0.2, 0.2, 0.2]}
        obj_pose = fg.pose(obj["p_WO"], obj["q_WO"])
        blue = fg.color(0.2, 0.4, 0.8, 0.9)
        if geo.get("shape") == "cylinder":
            d = 2.0 * geo.get("radius_m", 0.1)
            prim = {"cylinders": [{"pose": obj_pose, "size": fg.vec3([d, d, geo.get("height_m", 0.2)]),
                                   "bottom_scale": 1.0, "top_scale": 1.0, "color": blue}]}
        else:
            prim = {"cubes": [{"pose": obj_pose, "size": fg.vec3(geo.get("size_m", [0.2, 0.2, 0.2])), "color": blue}]}
        entities = [fg.entity(t, "object", **prim)]
        for sysid, sample in sorted(self.truth.items()):
            entities.append(self._am_entity(t, sysid, _fields(sample)))
        return {"deletions": [], "entities": entities}

    def _am_entity(self, t: float, sysid: int, tr: dict) -> dict:
        grey, orange = fg.color(0.25, 0.25, 0.25), fg.color(1.0, 0.55, 0.0)
        base = {"pose": fg.pose(tr["p_WB"], tr["q_WB"]), "size": fg.vec3([0.5, 0.5, 0.04]),
                "bottom_scale": 1.0, "top_scale": 1.0, "color": fg.color(0.3, 0.3, 0.3, 0.6)}
        arm = {"type": 0, "pose": fg.pose([0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]), "thickness": 0.015,
               "scale_invariant": False,
               "points": [fg.vec3(p) for p in [tr["p_WB"], *tr.get("p_W_joints", ()), tr["p_WE"]]], "color": grey,
               "colors": [], "indices": []}
        pad = {"pose": fg.pose(tr["p_WE"], tr["q_WE"]), "size": fg.vec3([0.01, 0.06, 0.06]), "color": orange}
        label = {"pose": fg.pose([tr["p_WB"][0], tr["p_WB"][1], tr["p_WB"][2] + 0.15], [1.0, 0.0, 0.0, 0.0]),
                 "billboard": True, "font_size": 14.0, "scale_invariant": True, "color": fg.color(1, 1, 1),
                 "text": f"am{sysid}"}
        arrows = []
        sample = self.contact.get(sysid)
        if sample is not None:
            c = _fields(sample)
            if c.get("n_points", 0) > 0:
                f = [c["normal_force_n"] * n + s for n, s in zip(c["normal_W"], c["tangential_force_W"])]
                mag = math.sqrt(sum(v * v for v in f))
                if mag > 1e-6:
                    arrows.append({"pose": fg.pose(c["point_W"], fg.quat_x_to(f)), "shaft_length": 0.02 * mag,
                                   "shaft_diameter": 0.008, "head_length": 0.02, "head_diameter": 0.02,
                                   "color": fg.color(0.9, 0.1, 0.1)})
        return fg.entity(t, f"am{sysid}", cylinders=[base], lines=[arm], cubes=[pad], texts=[label], arrows=arrows)
