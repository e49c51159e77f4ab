"""Bodies of the PyBullet world: ground, table, object and the aerial manipulators.

Every function takes the physics client id explicitly (never PyBullet's global default
client), so several worlds can live in one process.

Collision filtering (Bullet: two shapes collide iff (group_a & mask_b) and (group_b & mask_a)):
environment bodies (ground, table, object) are in ENV_GROUP and collide with everything;
AM links are in AM_GROUP and collide with the environment only, so AMs pass through each
other and an AM's own base and pad never touch. Only the AM base and pad have shapes.

Friction: Bullet combines two surfaces' coefficients by multiplication, so the pad-object
pair sees mu = pad coefficient * object coefficient. The object takes
`ObjectSpec.lateral_friction`; the pad takes `pad_lateral_friction`, which makes the pair's
product `ObjectSpec.pad_friction` when that is set (else the pad takes the object's
coefficient too, and the pair has its square).
"""
from __future__ import annotations

import math
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from .bullet import pb

from amcore.config import ObjectSpec, VehicleParams
from amcore.model import AmState
from amcore.so3 import R_to_quat_wxyz, quat_xyzw_of_wxyz

ENV_GROUP = 0b01
AM_GROUP = 0b10
ENV_MASK = ENV_GROUP | AM_GROUP
AM_MASK = ENV_GROUP

TABLE_FOOTPRINT_FRACTION = 0.8  # table top is this fraction of the object's footprint
GROUND_LATERAL_FRICTION = 1.0
TABLE_LATERAL_FRICTION = 1.0
OBJECT_ROLLING_FRICTION = 1e-4
OBJECT_SPINNING_FRICTION = 1e-3
_GROUND_HALF_THICKNESS_M = 0.05  # visual slab only; the collision shape is a plane


def _set_env_filter(client: int, body: int) -> None:
    pb.setCollisionFilterGroupMask(body, -1, ENV_GROUP, ENV_MASK, physicsClientId=client)


# ----------------------------------------------------------------------------- ground, table
def add_ground(client: int) -> int:
    """Static plane z = 0 (normal +z), built from a GEOM_PLANE shape (no data files needed)."""
    shape = pb.createCollisionShape(pb.GEOM_PLANE, planeNormal=[0, 0, 1], physicsClientId=client)
    visual = pb.createVisualShape(pb.GEOM_BOX, halfExtents=[10.0, 10.0, _GROUND_HALF_THICKNESS_M],
                                  visualFramePosition=[0, 0, -_GROUND_HALF_THICKNESS_M],
                                  rgbaColor=[0.6, 0.6, 0.6, 1], physicsClientId=client)
    body = pb.createMultiBody(0.0, shape, visual, [0, 0, 0], physicsClientId=client)
    pb.changeDynamics(body, -1, lateralFriction=GROUND_LATERAL_FRICTION, physicsClientId=client)
    _set_env_filter(client, body)
    return body


@dataclass(frozen=True)
class TableGeometry:
    """Static table under the object: same shape as the object, footprint scaled by
    TABLE_FOOTPRINT_FRACTION, standing on the ground with its top at the object's bottom.

    shape: "box" | "cylinder"; half_extents_m (box) or radius_m (cylinder); height_m;
    p_W_centre_m: centre of the table in W [m].
    """

    shape: str
    half_extents_m: tuple[float, float, float]
    radius_m: float
    height_m: float
    p_W_centre_m: tuple[float, float, float]

    @property
    def top_z_m(self) -> float:
        return self.p_W_centre_m[2] + 0.5 * self.height_m


def table_geometry(obj: ObjectSpec) -> TableGeometry:
    x, y, z = obj.position_m
    height = z - obj.half_height_m
    if height <= 0.0:
        raise ValueError(f"object bottom is at z = {height} m: it must be above the ground for the table")
    k = TABLE_FOOTPRINT_FRACTION
    if obj.shape == "box":
        half = (0.5 * k * obj.size_m[0], 0.5 * k * obj.size_m[1], 0.5 * height)
        radius = 0.0
    else:
        half = (0.0, 0.0, 0.5 * height)
        radius = k * obj.radius_m
    return TableGeometry(shape=obj.shape, half_extents_m=half, radius_m=radius, height_m=height,
                         p_W_centre_m=(x, y, 0.5 * height))


def _shapes(client: int, shape: str, half_extents, radius: float, height: float, rgba):
    if shape == "box":
        col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=list(half_extents), physicsClientId=client)
        vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=list(half_extents), rgbaColor=rgba, physicsClientId=client)
    else:
        col = pb.createCollisionShape(pb.GEOM_CYLINDER, radius=radius, height=height, physicsClientId=client)
        vis = pb.createVisualShape(pb.GEOM_CYLINDER, radius=radius, length=height, rgbaColor=rgba,
                                   physicsClientId=client)
    return col, vis


def _yawed(obj: ObjectSpec) -> dict:
    """createMultiBody's orientation for an object (and its table) turned by [object].yaw_deg about z;
    none when it is not turned (Bullet's default, as before the key existed)."""
    if obj.yaw_deg == 0.0:
        return {}
    return {"baseOrientation": pb.getQuaternionFromEuler([0.0, 0.0, math.radians(obj.yaw_deg)])}


def add_table(client: int, obj: ObjectSpec) -> int:
    t = table_geometry(obj)
    col, vis = _shapes(client, t.shape, t.half_extents_m, t.radius_m, t.height_m, [0.45, 0.3, 0.2, 1])
    body = pb.createMultiBody(0.0, col, vis, list(t.p_W_centre_m), **_yawed(obj), physicsClientId=client)
    pb.changeDynamics(body, -1, lateralFriction=TABLE_LATERAL_FRICTION, physicsClientId=client)
    _set_env_filter(client, body)
    return body


def add_object(client: int, obj: ObjectSpec) -> int:
    """The grasped object at rest at `obj.position_m`, uniform density (inertia from the shape)."""
    half = tuple(0.5 * s for s in obj.size_m)
    col, vis = _shapes(client, obj.shape, half, obj.radius_m, obj.height_m, [0.2, 0.4, 0.8, 1])
    body = pb.createMultiBody(obj.mass_kg, col, vis, list(obj.position_m), **_yawed(obj), physicsClientId=client)
    # frictionAnchor keeps the contact points of a resting contact fixed; without it Bullet
    # lets a box resting on the table creep at ~1e-5 m/s (and likewise a held object slip).
    pb.changeDynamics(body, -1, lateralFriction=obj.lateral_friction, rollingFriction=OBJECT_ROLLING_FRICTION,
                      spinningFriction=OBJECT_SPINNING_FRICTION, linearDamping=0.0, angularDamping=0.0,
                      frictionAnchor=1, physicsClientId=client)
    _set_env_filter(client, body)
    return body


# ----------------------------------------------------------------------------- AMs
@dataclass(frozen=True)
class AmBody:
    """PyBullet handles of one loaded AM.

    PyBullet's link index equals the index of the joint whose child it is; -1 is the base.
    tool_link_ids: the links the wrist sensor carries (the pad and everything below it).
    """

    body_id: int
    arm_joint_ids: tuple[int, ...]
    ft_joint_id: int
    pad_link_id: int
    ee_link_id: int
    tool_link_ids: tuple[int, ...]
    tool_link_masses_kg: tuple[float, ...]
    tool_mass_kg: float
    total_mass_kg: float


def pad_lateral_friction(obj: ObjectSpec) -> float:
    """The pad's own Bullet coefficient that gives the pad-object pair `obj.pad_object_friction`
    (Bullet multiplies the two bodies' coefficients)."""
    return obj.pad_friction / obj.lateral_friction if obj.pad_friction > 0.0 else obj.lateral_friction


def crowned_pad_urdf(vehicle: VehicleParams) -> str:
    """The vehicle's URDF text with the pad's collision box replaced by its crowned face
    (`PadSpec`): a cylinder along the pad's z axis, as tall as the box, whose front line is
    the box's front face centre. Everything else, inertias included, is unchanged."""
    tree = ET.parse(vehicle.urdf)
    root = tree.getroot()
    joint = next((j for j in root.iter("joint") if j.get("name") == vehicle.ft_frame), None)
    if joint is None or joint.find("child") is None:
        raise ValueError(f"{vehicle.urdf}: no joint '{vehicle.ft_frame}' with a child link for the pad")
    pad_name = joint.find("child").get("link")
    link = next(l for l in root.iter("link") if l.get("name") == pad_name)
    col = link.find("collision")
    box = col.find("geometry/box") if col is not None else None
    if box is None:
        raise ValueError(f"{vehicle.urdf}: the pad link '{pad_name}' needs a box collision to crown")
    sx, sy, sz = (float(v) for v in box.get("size").split())
    origin = col.find("origin")
    ox, oy, oz = (float(v) for v in (origin.get("xyz") if origin is not None else "0 0 0").split())
    r = vehicle.pad.crown_radius_m
    geometry = col.find("geometry")
    geometry.remove(box)
    ET.SubElement(geometry, "cylinder", radius=repr(r), length=repr(sz))
    if origin is None:
        origin = ET.SubElement(col, "origin")
    origin.set("xyz", f"{ox + 0.5 * sx - r!r} {oy!r} {oz!r}")
    origin.set("rpy", "0 0 0")
    return ET.tostring(root, encoding="unicode")


def _load_urdf(client: int, vehicle: VehicleParams) -> int:
    flags = pb.URDF_USE_INERTIA_FROM_FILE
    if vehicle.pad.shape == "flat":
        return pb.loadURDF(str(vehicle.urdf), flags=flags, physicsClientId=client)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / vehicle.urdf.name
        path.write_text(crowned_pad_urdf(vehicle))
        # an exact cylinder: without this flag PyBullet loads a faceted convex hull, whose flat
        # facets bring back the edges the crown is there to remove
        return pb.loadURDF(str(path), flags=flags | pb.URDF_USE_IMPLICIT_CYLINDER, physicsClientId=client)


def load_am(client: int, vehicle: VehicleParams, friction: float) -> AmBody:
    """Load the vehicle URDF (inertias from the file; the pad's face as [pad] says), strip
    PyBullet's default damping and velocity motors so the joints are purely torque
    controlled, enable the wrist sensor."""
    body = _load_urdf(client, vehicle)
    n = pb.getNumJoints(body, physicsClientId=client)
    info = [pb.getJointInfo(body, j, physicsClientId=client) for j in range(n)]
    joint_id = {i[1].decode(): i[0] for i in info}
    link_id = {i[12].decode(): i[0] for i in info}
    parent = {i[0]: i[16] for i in info}
    missing = [name for name in (*vehicle.arm_joints, vehicle.ft_frame) if name not in joint_id]
    if missing or vehicle.ee_frame not in link_id:
        raise ValueError(f"{vehicle.urdf}: PyBullet finds no joint/link named {missing or [vehicle.ee_frame]}")
    arm = tuple(joint_id[name] for name in vehicle.arm_joints)
    ft = joint_id[vehicle.ft_frame]
    pad = ft  # the child link of the sensor joint

    def below(link: int) -> bool:
        while link != -1:
            if link == pad:
                return True
            link = parent[link]
        return False

    tool = tuple(j for j in range(n) if below(j))
    masses = {l: pb.getDynamicsInfo(body, l, physicsClientId=client)[0] for l in range(-1, n)}

    base_info = pb.getDynamicsInfo(body, -1, physicsClientId=client)
    if not (np.allclose(base_info[3], 0.0, atol=1e-12) and np.allclose(base_info[4], [0, 0, 0, 1], atol=1e-12)):
        # PyBullet's base pose and velocity are those of the base's inertial frame; the
        # state conversion below relies on it coinciding with base_link's frame {b}.
        raise ValueError(f"{vehicle.urdf}: base inertial frame must coincide with the base link frame, "
                         f"PyBullet has offset {base_info[3]}, orientation {base_info[4]}")
    pad_info = pb.getDynamicsInfo(body, pad, physicsClientId=client)
    if not np.allclose(pad_info[4], [0, 0, 0, 1], atol=1e-12):
        # The wrist sensor reports in the pad's inertial frame; `World.wrench_ee` handles any
        # frame, but PyBullet's convention was verified with parallel inertial and link frames.
        raise ValueError(f"{vehicle.urdf}: the pad's inertial frame must be parallel to its link frame")
    for link in range(-1, n):
        pb.changeDynamics(body, link, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0,
                          physicsClientId=client)
        pb.setCollisionFilterGroupMask(body, link, AM_GROUP, AM_MASK, physicsClientId=client)
    pb.changeDynamics(body, pad, lateralFriction=friction, physicsClientId=client)
    if vehicle.pad.rolling_friction_m > 0.0:
        pb.changeDynamics(body, pad, rollingFriction=vehicle.pad.rolling_friction_m, physicsClientId=client)
    if vehicle.pad.contact_stiffness_n_per_m > 0.0:
        pb.changeDynamics(body, pad, contactStiffness=vehicle.pad.contact_stiffness_n_per_m,
                          contactDamping=vehicle.pad.contact_damping_n_s_per_m, physicsClientId=client)
    pb.setJointMotorControlArray(body, list(arm), pb.VELOCITY_CONTROL, forces=[0.0] * len(arm),
                                 physicsClientId=client)
    pb.enableJointForceTorqueSensor(body, ft, True, physicsClientId=client)
    return AmBody(body_id=body, arm_joint_ids=arm, ft_joint_id=ft, pad_link_id=pad, ee_link_id=link_id[vehicle.ee_frame],
                  tool_link_ids=tool, tool_link_masses_kg=tuple(masses[l] for l in tool),
                  tool_mass_kg=float(sum(masses[l] for l in tool)),
                  total_mass_kg=float(sum(masses.values())))


def reset_am(client: int, am: AmBody, state: AmState) -> None:
    """Put the AM at `state` (pose of {b}, body-frame velocities, joint angles and rates)."""
    R = np.asarray(state.R_WB, dtype=float)
    quat_xyzw = quat_xyzw_of_wxyz(R_to_quat_wxyz(R))  # PyBullet's order
    pb.resetBasePositionAndOrientation(am.body_id, list(map(float, state.p_WB)), quat_xyzw, physicsClientId=client)
    pb.resetBaseVelocity(am.body_id, list(R @ state.v_B), list(R @ state.w_B), physicsClientId=client)
    if len(state.q) != len(am.arm_joint_ids) or len(state.qdot) != len(am.arm_joint_ids):
        raise ValueError(f"state has {len(state.q)} joint angles and {len(state.qdot)} rates for "
                         f"{len(am.arm_joint_ids)} arm joints")
    for j, q, qd in zip(am.arm_joint_ids, state.q, state.qdot):
        pb.resetJointState(am.body_id, j, float(q), float(qd), physicsClientId=client)
