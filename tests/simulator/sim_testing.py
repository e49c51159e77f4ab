"""Helpers of the simulator tests: AM placements and experiment set-ups (imported by tests, and
by benchmarks/bench_world.py for the 10-AM ring)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pybullet as pb

from amcore.config import AmSpec, ObjectSpec, ScenarioSpec
from amcore.model import AmState, build_model, generalized_gravity
from amcore.so3 import Rz
from simulator.world import World


def at_rest(p_WB, R_WB, q) -> AmState:
    n = len(q)
    return AmState(p_WB=np.array(p_WB, dtype=float), R_WB=np.array(R_WB, dtype=float), v_B=np.zeros(3),
                   w_B=np.zeros(3), q=np.array(q, dtype=float), qdot=np.zeros(n))


def p_BE(model, q) -> np.ndarray:
    """End-effector origin in the base frame at joint angles q (pinocchio forward kinematics)."""
    pm = model.pin_model
    data = pm.createData()
    q_pin = np.concatenate([np.zeros(3), [0, 0, 0, 1], q])
    pin.framesForwardKinematics(pm, data, q_pin)
    return data.oMf[model.ee_frame_id].translation.copy()


def far_apart(spec, height_m: float = 3.0) -> dict[int, AmState]:
    """AMs 2 m from the object on either side, nominal arm, high above the ground: no contacts."""
    q = spec.vehicle.q_nominal_rad
    xs = {a.sysid: (-2.0 if i == 0 else 2.0) for i, a in enumerate(spec.ams)}
    return {s: at_rest([x, 0.0, height_m], np.eye(3), q) for s, x in xs.items()}


def facing_object(spec, model, depth_m: float) -> dict[int, AmState]:
    """Each AM at its azimuth, facing the box centre, pad face `depth_m` inside the box surface
    (negative: outside), ee at the object's centre height."""
    q = np.array(spec.vehicle.q_nominal_rad)
    e = p_BE(model, q)
    half = 0.5 * spec.object.size_m[0]
    c = np.array(spec.object.position_m)
    states = {}
    for a in spec.ams:
        az = np.deg2rad(a.azimuth_deg)
        u = np.array([np.cos(az), np.sin(az), 0.0])  # from the object centre to the AM
        R = Rz(az + np.pi)
        p_ee = c + (half - depth_m) * u
        states[a.sysid] = at_rest(p_ee - R @ e, R, q)
    return states


# The paper's 10-AM layout (Sec. V-C): a cylinder of radius 0.6 m and 5 kg, AMs 36 deg apart,
# each facing the object, arm at RING_Q, pad face RING_GAP_M outside the surface.
RING_Q = np.array([1.0472, -1.0472, 0.0])
RING_GAP_M = 0.02


def ten_am_spec(base: ScenarioSpec) -> ScenarioSpec:
    """`base` with the 10-AM layout's cylinder and ten AMs at azimuths 0, 36, ..., 324 deg."""
    obj = ObjectSpec(shape="cylinder", mass_kg=5.0, position_m=(0.0, 0.0, 0.6), radius_m=0.6, height_m=0.3,
                     lateral_friction=base.object.lateral_friction)
    ams = tuple(AmSpec(sysid=2 + i, azimuth_deg=36.0 * i) for i in range(10))
    return dataclasses.replace(base, name="ten_am_bench", object=obj, ams=ams)


def ring_placement(spec: ScenarioSpec, q: np.ndarray, gap_m: float) -> dict[int, AmState]:
    """Each AM on its azimuth, facing the object (yaw = azimuth + 180 deg), arm at q, pad face
    gap_m [m] outside the surface (cylinder or box), ee at the object's centre height."""
    obj = spec.object
    e = p_BE(build_model(spec.vehicle), q)
    half_width = obj.radius_m if obj.shape == "cylinder" else 0.5 * obj.size_m[0]
    c = np.array(obj.position_m)
    states = {}
    for a in spec.ams:
        az = np.deg2rad(a.azimuth_deg)
        R = Rz(az + np.pi)
        p_ee = c + (half_width + gap_m) * np.array([np.cos(az), np.sin(az), 0.0])
        states[a.sysid] = at_rest(p_ee - R @ e, R, q)
    return states


# Reaching into the world's PyBullet handles is confined to these helpers: they set up
# experiments (hold a base, push a link) that the public API deliberately does not offer.
def hold_base(world: World, sysid: int) -> None:
    """Pin the AM's base to the world at its current pose with a fixed constraint."""
    c, am = world._client, world._am(sysid)
    p, quat = pb.getBasePositionAndOrientation(am.body_id, physicsClientId=c)
    pb.createConstraint(am.body_id, -1, -1, -1, pb.JOINT_FIXED, [0, 0, 0], [0, 0, 0], p,
                        childFrameOrientation=quat, physicsClientId=c)


def push_link(world: World, sysid: int, link: str, force_W, point_W) -> None:
    """Apply force_W [N] at point_W [m] (both in W) on the AM's "pad" or "base" for the next step."""
    c, am = world._client, world._am(sysid)
    index = {"pad": am.pad_link_id, "base": -1}[link]
    pb.applyExternalForce(am.body_id, index, list(force_W), list(point_W), pb.WORLD_FRAME, physicsClientId=c)


def push_object(world: World, force_W) -> None:
    c = world._client
    p, _ = pb.getBasePositionAndOrientation(world._object_id, physicsClientId=c)
    pb.applyExternalForce(world._object_id, -1, list(force_W), list(p), pb.WORLD_FRAME, physicsClientId=c)


def hold_arm(world: World, sysid: int, q_ref, model, stiffness=(20.0, 5.0, 1.0), damping=(1.1, 0.28, 0.02)) -> None:
    """Joint-space PD towards q_ref plus the arm's gravity torques; with the base held, the
    pad settles where the PD balances the external load."""
    x = world.state(sysid)
    g_q = generalized_gravity(model, model.pin_model.createData(), x)[6:]
    tau = g_q - np.asarray(stiffness) * (x.q - np.asarray(q_ref)) - np.asarray(damping) * x.qdot
    world.apply(sysid, 0.0, np.zeros(3), tau)
