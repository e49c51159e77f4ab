"""The motion capture's measurement of the object before flight, shared by the team
([mission].object_pose = "mocap"; amcore.mission.am_mission plans each AM's approach from it).

A marker set on the object, tracked by the same motion-capture system as the vehicles
(`simulator.devices.Mocap` with [devices.mocap]'s rate, latency, noise, fixed biases and
frame losses, scaled by [devices].scale): the first frame that arrives of the object at rest
on its table, before the run starts. The object is still, so the frame's latency delays it
but does not change it. With [devices] off the measurement is exact. The generator is the
object's own, seeded by (scenario seed, 1: the simulator's system id, no AM's), so the
object's noise and bias draw nothing from any AM's sensors.
"""
from __future__ import annotations

import math

import numpy as np

from amcore.config import ScenarioSpec
from amcore.mission import ObjectPose, config_object_pose
from amcore.so3 import quat_wxyz_to_R

from .devices import Mocap

_STREAM = 0x0B1EC7  # this device's generator stream, apart from every AM's


def measure_object(spec: ScenarioSpec) -> ObjectPose:
    """The object's pose as the motion capture first reports it (module docstring)."""
    truth = config_object_pose(spec)
    d = spec.devices
    if not d.enabled:
        return truth
    rng = np.random.default_rng([spec.seed, 1, _STREAM])
    mocap = Mocap(d.mocap, d.scale, spec.dt_s, rng)
    c, s = math.cos(0.5 * truth.yaw_rad), math.sin(0.5 * truth.yaw_rad)
    quat = np.array([c, 0.0, 0.0, s])
    p = np.array(truth.p_W_m, dtype=float)
    pose = np.concatenate([p, quat])
    while (got := mocap.sample_values(pose)) is None:
        pass
    (p_m, q_m), _age = got
    R = quat_wxyz_to_R(np.asarray(q_m))
    return ObjectPose(tuple(float(x) for x in p_m), math.atan2(R[1, 0], R[0, 0]))
