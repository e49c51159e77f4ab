"""Per-AM references for the paper's grasp scenario (Sec. V), derived from a scenario.

Each AM computes its own references from the shared [mission] table, the object's
nominal geometry and its own [[am]] entry; it never sees another AM's state.

Task frame {t} of an AM: origin at the object's rest centre, x axis pointing from the
AM towards the object (the AM's heading), z up. In {t} the AM's pad works at negative x.
Phases (paper Sec. V): approach 0..approach_end_s (free flight; the pad stops pre_gap_m
outside the surface), grasp ..grasp_end_s (y_x,d moves squeeze_m inside the object so the
pads squeeze; the CoM moves only by pre_gap_m so that at contact the arm sits at its
nominal pose), lift and hover ..hover_end_s (CoM and y_z,d rise by lift_m).
The CoM reference is derived from the end-effector reference through the nominal arm
pose (paper Sec. IV, "CoM trajectory"), computed from the URDF, not entered.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import pinocchio as pin

from . import law
from .config import (GRASP_COMPONENTS, AmSpec, MissionSpec, ScenarioSpec, VehicleParams, design_mass_kg, grasped_face,  # noqa: F401
                     surface_distance)  # (surface_distance: re-exported)
from .control import Reference
from .model import AmModel, AmState, create_data, decoupled_terms
from .so3 import Rz
from .task import TaskFrame, angle_of, task_terms


# ------------------------------------------------------------------ smooth paths
# Smooth rest-to-rest reference trajectories.
#
# The desired attitude R_b,d (eq. Rd) is built from f_d, whose second derivative contains
# the CoM reference's fourth derivative, so CoM references must be C3 or smoother. Each
# move here follows the minimum-snap rest-to-rest profile
#     s(tau) = 35 tau^4 - 84 tau^5 + 70 tau^6 - 20 tau^7,  tau in [0, 1],
# whose velocity, acceleration and jerk vanish at both ends (C3 across segments).


@dataclass(frozen=True)
class Move:
    """Rest-to-rest move from p0 at t0 to p1 at t1."""

    t0: float
    t1: float
    p0: np.ndarray
    p1: np.ndarray


@dataclass(frozen=True)
class SmoothPath:
    """A sequence of rest-to-rest moves; holds between and after them."""

    start: np.ndarray
    moves: tuple[Move, ...]

    def eval(self, t: float, orders: int) -> list[np.ndarray]:
        """[p, pdot, ..., p^(orders)] at time t [s]."""
        return list(self.eval_array(t, orders))

    def eval_array(self, t: float, orders: int) -> np.ndarray:
        """Rows p, pdot, ..., p^(orders) at time t [s], as one (orders + 1, dim) array
        (amcore.law.smooth_path, compiled)."""
        return law.smooth_path(float(t), *self._arrays, orders)

    @cached_property
    def _arrays(self) -> tuple[np.ndarray, ...]:
        """start, and each move's t0, duration, p0 and p1 - p0, as arrays (law.smooth_path)."""
        dim = np.asarray(self.start).size
        return (np.asarray(self.start, dtype=float).ravel().copy(),
                np.array([mv.t0 for mv in self.moves], dtype=float),
                np.array([mv.t1 - mv.t0 for mv in self.moves], dtype=float),
                np.array([np.asarray(mv.p0, dtype=float).ravel() for mv in self.moves]).reshape(-1, dim),
                np.array([np.asarray(mv.p1 - mv.p0, dtype=float).ravel() for mv in self.moves]).reshape(-1, dim))

    def transformed(self, R: np.ndarray, p: np.ndarray) -> "SmoothPath":
        """The path of R x + p (every derivative turns with R)."""
        def f(x):
            return R.dot(x) + p
        return SmoothPath(f(self.start), tuple(Move(mv.t0, mv.t1, f(mv.p0), f(mv.p1)) for mv in self.moves))


def path_through(start: np.ndarray, moves: list[tuple[float, float, np.ndarray]]) -> SmoothPath:
    """Build a SmoothPath from (t0, t1, target) triples; each move starts where the last ended."""
    p = np.array(start, dtype=float)
    out = []
    for t0, t1, target in moves:
        target = np.array(target, dtype=float)
        if not t1 > t0:
            raise ValueError(f"move must have t1 > t0, got {t0}..{t1}")
        if out and t0 < out[-1].t1:
            raise ValueError("moves overlap")
        out.append(Move(t0, t1, p, target))
        p = target
    return SmoothPath(np.array(start, dtype=float), tuple(out))


# Free-running flight (the wall-clock companion, simulator.freerun): the vehicles stand landed
# below their mission's start; once OFFBOARD is engaged the references blend from the ground to
# the start over this time [s] (JoinBlend), and the mission's t = 0 is this long after the engage.
TAKEOFF_S = 3.0


@dataclass(frozen=True)
class NominalGeometry:
    """At q_nominal with a level base: end-effector and CoM offsets from {b}'s origin [m], and
    the end-effector's orientation R_BE."""

    p_BE: np.ndarray
    r_BC: np.ndarray
    pitch_rad: float
    R_BE: np.ndarray

    def task_values(self, components: tuple[str, ...], x_t: float, z_t: float) -> np.ndarray:
        """y for `components` with the pad at x_t, z_t [m] in {t} and everything else as at the
        nominal pose with the CoM on {t}'s x-z plane: "y" the pad's lateral offset from the CoM,
        each angle component the nominal pose's angle (amcore.task.angle_of of R_BE)."""
        lateral = float(self.p_BE[1] - self.r_BC[1])
        value = {"x": x_t, "y": lateral, "z": z_t}
        return np.array([value[c] if c in value else angle_of(self.R_BE, c) for c in components])


def nominal_geometry(model: AmModel) -> NominalGeometry:
    pm = model.pin_model
    data = create_data(model)
    q = pin.neutral(pm)
    q[7:] = model.vehicle.q_nominal_rad
    pin.framesForwardKinematics(pm, data, q)
    com = pin.centerOfMass(pm, data, q)
    R_BE = data.oMf[model.ee_frame_id].rotation
    return NominalGeometry(
        p_BE=data.oMf[model.ee_frame_id].translation.copy(), r_BC=com.copy(), pitch_rad=angle_of(R_BE, "pitch"),
        R_BE=R_BE.copy()
    )


@dataclass(frozen=True)
class SqueezePlan:
    """The grasp's normal force per pad [N] and the task depth that makes it through the
    x task spring K_y,x (eq. desired_task_behavior at rest: K_y,x y~_x = -F_y,x).

    required_n: friction_margin * m_obj g / (n_AM mu); feasible_n: the most the AM can push
    while its thrust also carries its weight and its share, within thrust_fraction_max of
    the maximum: sqrt((k T_max)^2 - (m_AM g + m_obj g / n_AM)^2), and at most
    [mission].squeeze_max_n."""

    force_n: float
    depth_m: float
    required_n: float
    feasible_n: float


def squeeze_plan(spec: ScenarioSpec, model: AmModel) -> SqueezePlan:
    """The squeeze of `spec`'s team for the object it plans for (`design_mass_kg`)."""
    return squeeze_for(spec.mission, spec.vehicle, model.mass_kg, design_mass_kg(spec), len(spec.ams))


def squeeze_for(ms: MissionSpec, v: VehicleParams, am_mass_kg: float, object_mass_kg: float, n: int) -> SqueezePlan:
    """SqueezePlan of a team of n AMs of mass am_mass_kg [kg] holding object_mass_kg [kg] (the
    pre-flight check asks it of other team sizes, amcore.preflight)."""
    k_x = v.gains.K_y[v.task.components.index("x")]
    fixed = k_x * ms.squeeze_m
    g = v.gravity_mps2
    share = object_mass_kg * g / n
    required = ms.friction_margin * share / ms.friction_assumed
    weight = am_mass_kg * g + share
    thrust = ms.thrust_fraction_max * v.rotors.thrust_max_z_n
    feasible = min(math.sqrt(max(thrust * thrust - weight * weight, 0.0)), ms.squeeze_max_n)
    if not ms.squeeze_sizing:
        return SqueezePlan(fixed, ms.squeeze_m, required, feasible)
    force = max(fixed, min(required, feasible))
    return SqueezePlan(force, force / k_x, required, feasible)


@dataclass(frozen=True)
class AmMission:
    """References of one AM: CoM and task paths in {t}, heading, and the task frame."""

    sysid: int
    frame: TaskFrame
    psi: float
    com_path_t: SmoothPath  # CoM in {t}
    y_path: SmoothPath  # y_d, one entry per [task].components, in {t}
    nominal: NominalGeometry
    q_nominal: tuple[float, ...]
    phase_ends_s: tuple[float, float, float]
    contact_point_W: np.ndarray  # where the pad plans to touch the face, in {w} [m]

    def reference(self, t: float) -> Reference:
        r = self._com_path_w.eval_array(t, 4)  # the CoM path taken to {w} once (_com_path_w)
        y = self.y_path.eval_array(t, 2)
        return Reference(r_c=r[0], r_c_d1=r[1], r_c_d2=r[2], r_c_d3=r[3], r_c_d4=r[4], psi=self.psi, psi_d1=0.0,
                         psi_d2=0.0, y=y[0], y_d1=y[1], y_d2=y[2])

    @cached_property
    def _com_path_w(self) -> SmoothPath:
        """The CoM path in {w}: p_WT + R_WT c(t)."""
        return self.com_path_t.transformed(self.frame.R_WT, self.frame.p_WT)

    def phase(self, t: float) -> str:
        a, g, _ = self.phase_ends_s
        return "approach" if t < a else ("grasp" if t < g else "hover")

    def initial_state(self) -> AmState:
        """At rest on the reference at t = 0, level, arm at the nominal pose."""
        r = self.reference(0.0)
        R_WB = Rz(self.psi)
        p_WB = r.r_c - R_WB @ self.nominal.r_BC
        return AmState(p_WB=p_WB, R_WB=R_WB, v_B=np.zeros(3), w_B=np.zeros(3),
                       q=np.array(self.q_nominal), qdot=np.zeros(len(self.q_nominal)))


@dataclass(frozen=True)
class ObjectPose:
    """The object's pose as the team knows it: its centre p_W_m [m, W] and its yaw about z_W
    [rad] (the config's, or the motion capture's measurement, simulator.object_mocap)."""

    p_W_m: tuple[float, float, float]
    yaw_rad: float


def config_object_pose(spec: ScenarioSpec) -> ObjectPose:
    """[object].position_m and yaw_deg, as written."""
    return ObjectPose(tuple(spec.object.position_m), math.radians(spec.object.yaw_deg))


def am_mission(spec: ScenarioSpec, am: AmSpec, model: AmModel, object_pose: ObjectPose | None = None) -> AmMission:
    """Build AM `am`'s references from the scenario and the object's pose (None: the config's,
    `config_object_pose`; [mission].object_pose = "mocap": the measurement the simulator's
    motion capture shares). Each AM uses only the pose and its own [[am]] entry: with
    `faces_from_pose`, it approaches the box's face whose normal is nearest its azimuth.

    The task references follow the vehicle's [task].components: "x" approaches and squeezes,
    "z" carries the start height and the lift, every other component holds its value at the
    nominal pose (`NominalGeometry.task_values`). The loader refuses a set without "x" and "z"
    (amcore.config.GRASP_COMPONENTS)."""
    comps = tuple(spec.vehicle.task.components)
    missing = [c for c in GRASP_COMPONENTS if c not in comps]
    if missing:
        raise ValueError(f"the grasp mission needs task components {GRASP_COMPONENTS}, vehicle has {comps}")
    ms = spec.mission
    pose = object_pose or config_object_pose(spec)
    az, half = grasped_face(spec, am, pose.yaw_rad)
    # face the object; a misaligned AM approaches and faces along a direction turned by its
    # misalignment about the object centre, believing the face is where it would be
    psi = az + np.pi + np.deg2rad(am.misalignment_deg)
    frame = TaskFrame(R_WT=Rz(psi), p_WT=np.array(pose.p_W_m, dtype=float))
    geo = nominal_geometry(model)
    d = geo.p_BE - geo.r_BC  # end-effector relative to CoM, level, in {b} = {t} orientation

    def y_at(x_t, z_t):  # the other components hold the nominal pose's values
        return geo.task_values(comps, x_t, z_t)

    y0 = y_at(-(half + ms.standoff_m), ms.start_height_m)
    y_app = y_at(-(half + ms.pre_gap_m), 0.0)
    y_grasp = y_at(-(half - squeeze_plan(spec, model).depth_m), 0.0)
    y_lift = y_at(-(half - squeeze_plan(spec, model).depth_m), ms.lift_m)
    t_a, t_g = ms.approach_end_s, ms.grasp_end_s
    if ms.approach_move_s > t_a or t_a + ms.grasp_move_s > t_g or t_g + ms.lift_move_s > ms.hover_end_s:
        raise ValueError("mission moves do not fit in their phases")
    grasp_moves = [(t_a, t_a + ms.grasp_move_s, y_grasp)]
    if ms.touch_hold_s > 0.0:  # touch, align, squeeze: the first move presses touch_force_n only
        k_x = spec.vehicle.gains.K_y[comps.index("x")]
        y_touch = y_at(-(half - ms.touch_force_n / k_x), 0.0)
        t_s = t_a + ms.grasp_move_s + ms.touch_hold_s
        grasp_moves = [(t_a, t_a + ms.grasp_move_s, y_touch), (t_s, t_s + ms.grasp_move_s, y_grasp)]
    y_path = path_through(y0, [(0.0, ms.approach_move_s, y_app), *grasp_moves,
                               (t_g, t_g + ms.lift_move_s, y_lift)])

    ix, iz = comps.index("x"), comps.index("z")

    def com_of(y):  # the CoM under the pad's x and z, on {t}'s x-z plane
        return np.array([y[ix] - d[0], 0.0, y[iz] - d[2]])

    c_contact = com_of(y_at(-half, 0.0))
    com_path = path_through(com_of(y0), [
        (0.0, ms.approach_move_s, com_of(y_app)),
        (t_a, t_a + ms.grasp_move_s, c_contact),
        (t_g, t_g + ms.lift_move_s, c_contact + np.array([0.0, 0.0, ms.lift_m])),
    ])
    mission = AmMission(sysid=am.sysid, frame=frame, psi=psi, com_path_t=com_path, y_path=y_path,
                        nominal=geo, q_nominal=tuple(spec.vehicle.q_nominal_rad),
                        phase_ends_s=(t_a, t_g, ms.hover_end_s),
                        contact_point_W=frame.p_WT + frame.R_WT @ np.array([-half, 0.0, 0.0]))
    return mission


@dataclass(frozen=True)
class JoinBlend:
    """References for a controller that starts while its vehicle is away from the mission:
    a companion restarted during a run, whose vehicle the flight controller's failsafe has
    held while the mission moved on. They start at rest at the vehicle's own CoM and task
    values at t0 (so the first command holds it where it is, instead of a jump the actuators
    cannot make) and join the mission's over duration_s along the minimum-snap profile s of
    the smooth paths above (C3, as eq. Rd needs):

        r_c,d(t) = r_0 + s(tau) (r_mission(t) - r_0),  tau = (t - t0) / duration_s,

    with derivatives by Leibniz's rule; likewise y_d from y_0. The heading is the mission's."""

    t0: float
    duration_s: float
    r_c0: tuple[float, ...]
    y0: tuple[float, ...]

    def apply(self, ref: Reference, t: float) -> Reference:
        """`ref` (the mission's at t) blended; the mission's own once the blend is over."""
        tau = (t - self.t0) / self.duration_s
        if tau >= 1.0:
            return ref
        s = [law.smoothstep(max(tau, 0.0), k) / self.duration_s ** k for k in range(5)]  # d^k s / dt^k
        r = [ref.r_c - np.array(self.r_c0), ref.r_c_d1, ref.r_c_d2, ref.r_c_d3, ref.r_c_d4]
        y = [ref.y - np.array(self.y0), ref.y_d1, ref.y_d2]

        def d(k, e):  # d^k/dt^k (s e) = sum_j C(k, j) s^(j) e^(k-j)
            return sum(math.comb(k, j) * s[j] * e[k - j] for j in range(k + 1))

        return Reference(self.r_c0 + d(0, r), d(1, r), d(2, r), d(3, r), d(4, r), ref.psi, ref.psi_d1,
                         ref.psi_d2, self.y0 + d(0, y), d(1, y), d(2, y))


def join_blend(model: AmModel, mission: AmMission, components: tuple[str, ...], state: AmState, t0: float,
               duration_s: float, wrench_E=None, K_y=None) -> JoinBlend:
    """The JoinBlend from `state` at t0 into `mission` (CoM and task values from the model).

    With the wrist sensor's reading `wrench_E` (on {e}, [N, N m]) and the task stiffness
    K_y (diagonal entries), a pad that is pushing on something resumes that push: the x task
    reference starts N / K_y,x deeper than the pad, N the measured normal force along the
    task x axis, so that the spring of eq. desired_task_behavior (K_y y~ = F_y at rest) holds
    the force it found instead of starting from zero squeeze and letting go."""
    if not duration_s > 0.0:
        raise ValueError(f"join blend duration must be > 0, got {duration_s}")
    data = create_data(model)
    tm = decoupled_terms(model, data, state)
    tk = task_terms(model, data, tm, mission.frame, components)
    y0 = tk.y.copy()
    if wrench_E is not None and K_y is not None and "x" in components:
        f_T = mission.frame.R_WT.T @ (tk.H_WE[0:3, 0:3] @ np.asarray(wrench_E, dtype=float)[0:3])
        i = components.index("x")
        y0[i] += max(0.0, -f_T[0]) / K_y[i]
    return JoinBlend(t0=t0, duration_s=duration_s, r_c0=tuple(tm.r_c.tolist()), y0=tuple(y0.tolist()))
