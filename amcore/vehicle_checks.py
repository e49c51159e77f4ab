"""Checks of a vehicle's URDF against what the controller and the simulator assume (pure: the
URDF's XML, numpy and pinocchio; the loader, amcore.config.vehicle_from_dict, runs them).

The controller (pinocchio) and the simulator (PyBullet) read the same URDF, but they do not
read every URDF alike; these checks refuse what they would read differently, or what could not
fly, before anything flies:

- the base link's <inertial> sits at its origin: {b}'s origin is the base's CoM (eq. dynamics),
  and PyBullet refuses a base whose inertial frame is offset;
- every link has an <inertial> with a positive mass and an inertia whose principal moments are
  positive and satisfy the triangle inequality (I_a + I_b >= I_c): pinocchio reads a link
  without one as 0 kg where PyBullet gives it 1 kg, and PyBullet zeroes an inertia no rigid body
  can have while pinocchio keeps it;
- q_nominal_rad lies inside the joint limits;
- at q_nominal_rad, level and hovering, every joint's static torque (pinocchio's generalized
  gravity) is within joint_torque_max_nm.

`task_warnings` names the task components the arm cannot move at the nominal pose (a zero row
of dy/dq): the loader warns, it does not refuse (the pose may be a singular one by choice).
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

BASE_INERTIAL_TOLERANCE_M = 1e-9  # |xyz| of the base's <inertial><origin> counted as zero
TRIANGLE_TOLERANCE = 1e-9  # relative: I_a + I_b >= I_c (1 - this), for rounding in the file
MOVE_TOLERANCE = 1e-6  # |dy_r/dq| below this (per rad) counts as "the arm cannot move y_r"


class UrdfCheckError(ValueError):
    """One check failed; the message names the URDF element and its value (the loader adds the file)."""


def _floats(text: str | None, n: int, default: float = 0.0) -> list[float]:
    if text is None:
        return [default] * n
    try:
        vals = [float(x) for x in text.split()]
    except ValueError:
        vals = []
    if len(vals) != n:
        raise UrdfCheckError(f"expected {n} numbers, got {text!r}")
    return vals


def check_inertials(root: ET.Element, base_link: str) -> None:
    """The base's inertial at its origin; every link's mass and inertia physical (module doc)."""
    for link in root.findall("link"):
        name = link.get("name")
        inertial = link.find("inertial")
        if inertial is None:
            raise UrdfCheckError(f"<link name='{name}'> has no <inertial>: pinocchio would read 0 kg where "
                                 f"PyBullet uses 1 kg; give its mass and inertia")
        origin = inertial.find("origin")
        if name == base_link:
            try:
                xyz = _floats(origin.get("xyz") if origin is not None else None, 3)
            except UrdfCheckError as exc:
                raise UrdfCheckError(f"<link name='{name}'><inertial><origin xyz>: {exc}") from None
            if math.hypot(*xyz) > BASE_INERTIAL_TOLERANCE_M:
                raise UrdfCheckError(f"<link name='{name}'><inertial><origin xyz='{origin.get('xyz')}'>: the base "
                                     f"link's inertial must sit at its origin (the base's CoM is {{b}}'s origin); "
                                     f"move the link's origin to its CoM")
        mass = inertial.find("mass")
        try:
            m = float(mass.get("value")) if mass is not None else math.nan
        except (TypeError, ValueError):
            m = math.nan
        if not (m > 0.0 and math.isfinite(m)):
            raise UrdfCheckError(f"<link name='{name}'><inertial><mass value='{None if mass is None else mass.get('value')}'>: "
                                 f"must be a positive number of kg")
        inertia = inertial.find("inertia")
        keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        if inertia is None or any(inertia.get(k) is None for k in keys):
            raise UrdfCheckError(f"<link name='{name}'><inertial><inertia>: needs all of {', '.join(keys)}")
        try:
            ixx, ixy, ixz, iyy, iyz, izz = (float(inertia.get(k)) for k in keys)
        except ValueError:
            raise UrdfCheckError(f"<link name='{name}'><inertial><inertia>: not numbers: "
                                 f"{dict(inertia.attrib)}") from None
        I = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        if not np.all(np.isfinite(I)):
            raise UrdfCheckError(f"<link name='{name}'><inertial><inertia>: not finite: {dict(inertia.attrib)}")
        lam = np.linalg.eigvalsh(I)
        text = " ".join(f"{k}='{inertia.get(k)}'" for k in keys)
        if not lam[0] > 0.0:
            raise UrdfCheckError(f"<link name='{name}'><inertia {text}>: not positive definite (principal "
                                 f"moments {', '.join(f'{x:.3g}' for x in lam)} kg m^2); PyBullet would zero it")
        if lam[0] + lam[1] < lam[2] * (1.0 - TRIANGLE_TOLERANCE):
            raise UrdfCheckError(f"<link name='{name}'><inertia {text}>: principal moments "
                                 f"{', '.join(f'{x:.3g}' for x in lam)} kg m^2 break the triangle inequality "
                                 f"I_1 + I_2 >= I_3 (no rigid body has them)")


def joint_limits(root: ET.Element, joints: tuple[str, ...]) -> dict[str, tuple[float, float]]:
    """(lower, upper) [rad or m] of each named joint; (-inf, inf) for a continuous one."""
    out = {}
    by_name = {j.get("name"): j for j in root.findall("joint")}
    for name in joints:
        j = by_name[name]
        lim = j.find("limit")
        if j.get("type") == "continuous" or lim is None:
            out[name] = (-math.inf, math.inf)
        else:
            out[name] = (float(lim.get("lower", "0")), float(lim.get("upper", "0")))
    return out


def check_nominal_in_limits(root: ET.Element, joints: tuple[str, ...], q_nominal: tuple[float, ...]) -> str | None:
    """None, or why q_nominal_rad lies outside a joint's <limit>."""
    for (name, (lo, hi)), q in zip(joint_limits(root, joints).items(), q_nominal):
        if not lo <= q <= hi:
            return (f"{q!r} for '{name}' is outside its <limit lower='{lo:g}' upper='{hi:g}'> in the URDF")
    return None


def nominal_statics(urdf: Path, q_nominal, gravity_mps2: float):
    """(pinocchio model, data, q) at q_nominal, level, and the joints' static torques [N m] there."""
    import pinocchio as pin

    pm = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())
    pm.gravity.linear = np.array([0.0, 0.0, -gravity_mps2])
    data = pm.createData()
    q = pin.neutral(pm)
    q[7:] = np.asarray(q_nominal, dtype=float)
    g = pin.computeGeneralizedGravity(pm, data, q)
    return pm, data, q, np.array(g[6:])


def whole_am_inertia(urdf: Path, q_nominal) -> np.ndarray:
    """(3, 3) rotational inertia of the whole AM about the base's origin, body axes, arm locked at
    q_nominal [kg m^2] (pinocchio's CRBA, M[3:6, 3:6])."""
    import pinocchio as pin

    pm, data, q, _ = nominal_statics(urdf, q_nominal, 9.81)
    return np.array(pin.crba(pm, data, q)[3:6, 3:6])


def check_static_torques(urdf: Path, joints, q_nominal, torque_max, gravity_mps2: float) -> str | None:
    """None, or the first joint whose static torque at the nominal hover exceeds its limit."""
    *_, tau = nominal_statics(urdf, q_nominal, gravity_mps2)
    for name, t, lim in zip(joints, tau, torque_max):
        if abs(t) > lim:
            return (f"'{name}' needs {abs(t):.3g} N m to hold the arm at q_nominal_rad in a level hover, more "
                    f"than its {lim:g} N m")
    return None


def task_warnings(urdf: Path, ee_frame: str, q_nominal, components: tuple[str, ...]) -> list[str]:
    """The components whose row of dy/dq (central differences of amcore.task's y, base level at
    the origin) vanishes at the nominal pose: no joint moves them there."""
    import pinocchio as pin

    from .task import angle_of

    pm, data, q0, _ = nominal_statics(urdf, q_nominal, 9.81)
    fid = pm.getFrameId(ee_frame)
    axis = {"x": 0, "y": 1, "z": 2}

    def y_of(q):
        pin.framesForwardKinematics(pm, data, q)
        H = data.oMf[fid]
        return np.array([H.translation[axis[c]] if c in axis else angle_of(H.rotation, c) for c in components])

    h = 1e-6
    cols = []
    for k in range(7, pm.nq):
        dq = np.zeros(pm.nq)
        dq[k] = h
        cols.append((y_of(q0 + dq) - y_of(q0 - dq)) / (2 * h))
    dy_dq = np.column_stack(cols)
    return [f"[task].components: '{c}' cannot be moved by the arm at q_nominal_rad (no joint changes it there)"
            for c, row in zip(components, dy_dq) if np.linalg.norm(row) < MOVE_TOLERANCE]
