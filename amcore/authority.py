"""What a vehicle's rotors can do: thrust margin, torque authority at hover and in a loaded,
squeezing hover (pure: numpy and pinocchio, no I/O).

The loaded hover is a static balance of the whole AM, rigid at arm configuration q, pushing a
vertical face with normal force N and carrying a load share m_s on its pad (friction holds it):

    forces:  T z_B = (m + m_s) g z_W + N x_W          (the object pushes the pad back by -N x_W)
    moments about the base origin, in W:
             R tau_B + c_W x (-m g z_W) + p_W x (-N x_W - m_s g z_W) = 0

with c_W = R c_B(q) the AM's centre of mass and p_W = R p_E(q) the pad's face centre relative to
the base, both from the URDF (pinocchio). So the base pitches by theta = atan2(N, (m + m_s) g)
about y_B, T = |(N, 0, (m + m_s) g)|, and tau_B is what the rotors must add. The arm holds the
pad where it was at the unloaded hover (relative to the base's position, in W: the task
law's job), so q follows theta (inverse kinematics on the pad's pose); the face's normal is
horizontal and the arm planar (x-z plane of B), as in the paper's grasp. The joint torques
are internal to the AM and drop out.

Authority around an operating point is what `amcore.allocation.Allocation.authority` gives:
the torque the allocator can add on one axis before a rotor leaves its range.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .allocation import AXES, Allocation
from .config import ConfigError, VehicleParams
from .model import AmModel, build_model, create_data


@dataclass(frozen=True)
class OperatingPoint:
    """A static hover: thrust [N] along z_B, body torque tau_B [N m], base pitch [rad], the
    rotors' thrusts [N] and each as a fraction of its range, and the authority left per
    torque axis {axis: (down, up)} [N m]."""

    squeeze_n: float
    load_kg: float
    thrust_n: float
    tau_B_nm: tuple[float, float, float]
    pitch_rad: float
    rotor_thrusts_n: tuple[float, ...]
    rotor_fractions: tuple[float, ...]
    feasible: bool
    authority_nm: dict[str, tuple[float, float]]
    joint_torques_nm: tuple[float, ...] = ()  # what the arm's joints hold, g_q - (J_E^T W)_q [N m]
    joint_fractions: tuple[float, ...] = ()  # each |torque| over its joint's limit


@dataclass(frozen=True)
class VehicleAuthority:
    """A vehicle's figures (see `vehicle_authority`)."""

    name: str
    rotor_count: int
    mass_kg: float
    weight_n: float
    thrust_max_z_n: float
    thrust_margin: float  # thrust_max_z_n / weight_n
    cant_loss: float  # 1 - (thrust along z_B) / (sum of rotor thrusts), all at maximum
    hover: OperatingPoint
    loaded: OperatingPoint | None


def operating_point(vehicle: VehicleParams, model: AmModel, q: np.ndarray, squeeze_n: float = 0.0,
                    load_kg: float = 0.0, alloc: Allocation | None = None) -> OperatingPoint:
    """The static hover of the module docstring, allocated."""
    alloc = alloc or Allocation(vehicle.rotors)
    g = vehicle.gravity_mps2
    m = model.mass_kg
    data = create_data(model)
    vertical = (m + load_kg) * g
    theta = math.atan2(squeeze_n, vertical)
    thrust = math.hypot(squeeze_n, vertical)
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # pitch theta about y: z_B leans to +x_W
    q = _hold_pad(model, data, np.asarray(q, dtype=float), R)
    q_pin = np.concatenate([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], q])
    c_B = pin.centerOfMass(model.pin_model, data, q_pin).copy()
    pin.updateFramePlacements(model.pin_model, data)
    p_B = data.oMf[model.ee_frame_id].translation.copy()
    z_W, x_W = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    M = np.cross(R @ c_B, -m * g * z_W) + np.cross(R @ p_B, -squeeze_n * x_W - load_kg * g * z_W)
    tau_B = -(R.T @ M)
    # the joints: tau = g(q) - J_E^T W (static), W the pad's wrench from the object, at E, in W axes
    q_pin = np.concatenate([[0.0, 0.0, 0.0], pin.Quaternion(R).coeffs(), q])
    grav = pin.computeGeneralizedGravity(model.pin_model, data, q_pin)
    J_E = pin.computeFrameJacobian(model.pin_model, data, q_pin, model.ee_frame_id, pin.LOCAL_WORLD_ALIGNED)
    W = np.concatenate([-squeeze_n * x_W - load_kg * g * z_W, np.zeros(3)])
    tau_q = (grav - J_E.T @ W)[6:]
    a = alloc.allocate_wrench(thrust, tau_B)
    f_min, f_max = np.array(vehicle.rotors.thrust_min()), np.array(vehicle.rotors.thrust_max())
    frac = (np.array(a.rotor_thrusts_n) - f_min) / (f_max - f_min)
    return OperatingPoint(squeeze_n, load_kg, thrust, tuple(tau_B.tolist()), theta, a.rotor_thrusts_n,
                          tuple(frac.tolist()), not a.saturated, alloc.authority(thrust, tau_B),
                          tuple(tau_q.tolist()),
                          tuple((np.abs(tau_q) / np.array(vehicle.joint_torque_max_nm)).tolist()))


def _hold_pad(model: AmModel, data, q0: np.ndarray, R_WB: np.ndarray) -> np.ndarray:
    """The arm configuration that keeps the pad's pose relative to the base origin in W as at q0
    with a level base, once the base is turned by R_WB (damped Gauss-Newton on the frame's
    pose error; the arm is planar, so the pose is reachable while the turn is about y_B)."""
    base = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    pin.framesForwardKinematics(model.pin_model, data, np.concatenate([base, q0]))
    target = pin.SE3(R_WB.T, np.zeros(3)) * data.oMf[model.ee_frame_id]  # the same pose, seen from B
    q = q0.copy()
    for _ in range(50):
        q_pin = np.concatenate([base, q])
        pin.framesForwardKinematics(model.pin_model, data, q_pin)
        err = pin.log6(data.oMf[model.ee_frame_id].actInv(target)).vector
        if np.linalg.norm(err) < 1e-10:
            break
        J = pin.computeFrameJacobian(model.pin_model, data, q_pin, model.ee_frame_id, pin.LOCAL)[:, 6:]
        q = q + np.linalg.solve(J.T @ J + 1e-9 * np.eye(len(q)), J.T @ err)
    if np.linalg.norm(err) > HOLD_PAD_TOLERANCE:
        pitch = math.degrees(math.atan2(R_WB[0, 2], R_WB[0, 0]))
        raise ArmCannotHoldPad(f"{model.vehicle.urdf}: [vehicle].arm_joints {list(model.vehicle.arm_joints)}: the arm "
                               f"cannot keep the pad's pose with the base pitched {pitch:.1f} deg (pose error "
                               f"{np.linalg.norm(err):.2g}); the loaded hover (amcore.authority, the envelope) needs "
                               f"joints that turn the pad about the body y axis")
    return q


HOLD_PAD_TOLERANCE = 1e-6  # |log6| of the pad's pose error [m, rad] that counts as held


class ArmCannotHoldPad(ConfigError):
    """The loaded hover's model does not fit this arm: a configuration the envelope refuses."""


def vehicle_authority(vehicle: VehicleParams, squeeze_n: float = 0.0, load_kg: float = 0.0,
                      q: np.ndarray | None = None) -> VehicleAuthority:
    """Thrust margin and cant loss; the hover's authority; with a squeeze or a load, the loaded
    hover's (arm at q, default the vehicle's q_nominal_rad)."""
    model = build_model(vehicle)
    alloc = Allocation(vehicle.rotors)
    q = np.array(vehicle.q_nominal_rad if q is None else q, dtype=float)
    weight = model.mass_kg * vehicle.gravity_mps2
    r = vehicle.rotors
    hover = operating_point(vehicle, model, q, 0.0, 0.0, alloc)
    loaded = operating_point(vehicle, model, q, squeeze_n, load_kg, alloc) if (squeeze_n or load_kg) else None
    return VehicleAuthority(vehicle.name, r.count, model.mass_kg, weight, r.thrust_max_z_n, r.thrust_max_z_n / weight,
                            1.0 - r.thrust_max_z_n / r.thrust_max_total_n, hover, loaded)


def report_lines(va: VehicleAuthority) -> list[str]:
    """The figures as `am-vehicle` prints them."""
    lines = [f"vehicle {va.name}: {va.rotor_count} rotors, {va.mass_kg:.3f} kg with its arm ({va.weight_n:.2f} N)",
             f"thrust along z_B, all rotors at maximum: {va.thrust_max_z_n:.2f} N; thrust margin "
             f"{va.thrust_margin:.2f} x weight",
             f"thrust lost to cant: {va.cant_loss * 100:.1f} %"]
    for label, op in (("hover", va.hover), ("loaded hover", va.loaded)):
        if op is None:
            continue
        head = label if label == "hover" else (f"loaded hover (squeeze {op.squeeze_n:g} N, load {op.load_kg:g} kg, "
                                               f"base pitched {math.degrees(op.pitch_rad):.1f} deg)")
        lines.append(f"{head}: thrust {op.thrust_n:.2f} N, torque needed "
                     f"({op.tau_B_nm[0]:+.3f}, {op.tau_B_nm[1]:+.3f}, {op.tau_B_nm[2]:+.3f}) N m"
                     + ("" if op.feasible else "  ** NOT FEASIBLE: the rotors cannot make it **"))
        lines.append(f"  rotors [N]: {', '.join(f'{f:.2f}' for f in op.rotor_thrusts_n)}; highest at "
                     f"{max(op.rotor_fractions) * 100:.0f} % of its range, lowest at {min(op.rotor_fractions) * 100:.0f} %")
        for ax in AXES[:3]:
            down, up = op.authority_nm[ax]
            lines.append(f"  {ax:5s} torque it can add: -{down:.3f} / +{up:.3f} N m")
        lines.append(f"  arm joints hold [N m]: {', '.join(f'{t:+.2f}' for t in op.joint_torques_nm)}; the busiest at "
                     f"{max(op.joint_fractions) * 100:.0f} % of its limit")
    lo, hi = va.hover.authority_nm["yaw"]
    lines.append(f"yaw authority at hover: {min(lo, hi):.3f} N m")
    return lines
