"""Baseline controller of one AM: what a practitioner writes first (no I/O).

A peer to the paper's law (`amcore.control`), with the same `step` signature and the same
`Command` and `Diagnostics`, so that the companion, its outcome summary and the telemetry
treat both alike. It has no inertial decoupling, no task impedance and no F/T sensor:

- Base: geometric tracking on SE(3) (T. Lee, M. Leok, N. H. McClamroch, "Geometric tracking
  control of a quadrotor UAV on SE(3)", CDC 2010; its thrust and moment laws, written here for
  a z-up world frame), with integral terms as autopilots have them (PX4 integrates in its
  velocity and rate loops; F. Goodarzi, D. Lee and T. Lee, ECC 2013, add one to the geometric
  attitude law; this one integrates e_R itself).
  With e_x = p_WB - p_d, e_v its rate, i_x = int e_x dt and i_R = int e_R dt, each clamped per
  axis so that |k_i i_x| <= integral_limit_n and |k_iR i_R| <= attitude_integral_limit_nm
  (anti-windup):

      F_d = -k_x e_x - k_v e_v - k_i i_x + m g e_3 + m p_d''
      f   = F_d . R e_3                                              (thrust)
      R_d = [b_2d x b_3d, b_2d, b_3d],  b_3d = F_d / |F_d|            (amcore.attitude)
      e_R = vee(R_d^T R - R^T R_d) / 2,  e_W = W - R^T R_d W_d
      M   = -k_R e_R - k_W e_W - k_iR i_R + W x J W - J (hat(W) R^T R_d W_d - R^T R_d Wdot_d)
            + g_B(q, R)

  m is the whole AM's mass and J the composite rigid-body inertia of the whole AM about its
  CoM with the arm locked at q_nominal (`composite_inertia`): Lee's rigid body is the AM with
  its arm frozen. g_B is the base-torque part of pinocchio's generalized gravity, the moment
  of the arm's weight about the base origin where the thrust acts. The gains are diagonal
  (per axis, as autopilots tune them; equal entries and k_i = k_iR = 0 give Lee's law). W_d
  and Wdot_d are the feed-forward of the reference alone (F_d's first two rates taken as
  m p_d^(3) and m p_d^(4)): the feedback terms' rates would need the measured acceleration,
  which this controller does not have. The base reference is the mission's CoM reference less
  the nominal CoM offset, p_d = r_c,d - R_z(psi) r_BC (`amcore.mission.NominalGeometry`).
- Arm: joint-space PD with gravity compensation,

      tau_q = K_q (q_d - q) - D_q qdot + g_q(q, R),

  with q_d the inverse kinematics of the task reference y_d = (x, z, pitch) of the pad in the
  AM's task frame, taken relative to the base's reference pose (p_d, R_d): a few damped Newton
  steps per control step, warm-started from the last q_d, clipped to the joint limits. In the
  grasp the target lies inside the object; the squeeze is what K_q makes of the joints' offset,
  F = J^-T K_q (q_d - q).

Two additions a practitioner makes next, options of [baseline] (`amcore.config.BaselineGains`;
off by default, the law above):

- arm = "cartesian": an impedance at the pad through the arm's Jacobian instead of the joint PD,

      tau_q = J^T w + g_q(q, R),  w = (A^T f, m),
      f = K_y,xz e_xz - D_y,xz edot_xz,  m = K_y,pitch e_pitch - D_y,pitch edot_pitch,

  e = y_d - y and edot = ydot - y_d' the pad's (x, z, pitch) error in the task frame from the
  measured state (as the diagnostics' y), J = d(x, z, pitch)/dq in {b}, and A the x-z block of
  R_WT^T R: it turns {b}'s x-z plane into the task frame's, where K_y acts (the base pitches by
  tenths of a radian in the grasp; a stiffness along the body axes would push askew). At rest
  with the pad held on the face, the squeeze is K_y,x times the grasp target's depth, which the
  mission sizes as force / [gains].K_y,x (amcore.mission.squeeze_for): with K_y,x equal to it,
  exactly the planned force, wherever the base is. A load along z no longer turns the joints'
  offsets into pitch. (The pad's error is measured from the base's pose, not from its
  reference as the IK's target is: seen from the reference, the feed-forward below closes a
  loop through R_d, F_d -> R_d -> the target -> w -> F_d, that diverged in the grasp.)
- reaction_feedforward: the base adds the reaction of the spring wrench w the arm commanded at
  the last step, F_d += R f and M += p_BE x f + m (f = (w_x, 0, w_z), m = (0, w_pitch, 0) and
  p_BE, the pad's position, in {b}): the squeeze's reaction and the load's share, which the
  integrals otherwise take seconds to build up, while the base is pushed back by centimetres.
  With the cartesian arm only: the joint PD's wrench, J^-T K_q (q_d - q), comes from the IK's
  target seen from the base's reference, and fed forward it closed the loop through R_d above
  (measured: diverged in the grasp).

Diagnostics are defined as in `amcore.control` where a quantity exists for both laws: r_c
and rdot_c are the model's CoM (not the base), y and ydot the task values in the same task
frame (`amcore.task`), e_R, e_w, R_d, w_bd, wdot_bd, Omega_d as above, f_d = F_d. The wrist
F/T reading is low-pass filtered with the vehicle's wrench filter for the diagnostics only
(F_rc, wrench_E_filtered, wrench_W_filtered): it never reaches the command. Fields without a
counterpart hold placeholders: F_y = 0, Lambda_y = 0, u = 0 (no decoupled coordinates),
y_err_saturated = False. Reused with this law's meaning: sigma_min_J3 is the smallest
singular value of the arm's planar Jacobian at q_d (the IK's margin from a straight elbow; at q
in the cartesian mode),
damping the IK's damping squared, com_err_saturated whether the position integral sits at
its anti-windup clamp.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from . import linalg3
from .attitude import desired_attitude
from .config import BASELINE_COMPONENTS, VehicleParams
from .control import Command, Diagnostics, Reference, StepResult
from .filters import FilterState, LowPass2, lowpass_update_floats
from .mission import nominal_geometry
from .model import AmModel, AmState
from .so3 import cross
from .task import TaskFrame, angle_of

PLANAR_COMPONENTS = BASELINE_COMPONENTS  # the arm's plane in {b}: joints turn about the body y axis


@dataclass(frozen=True)
class BaselineParams:
    """Everything constant about one AM's baseline controller (gains from [baseline])."""

    k_x: np.ndarray  # (3,) [N/m]
    k_v: np.ndarray  # (3,) [N s/m]
    k_i: np.ndarray  # (3,) [N/(m s)]
    i_max: np.ndarray  # (3,) bound on |int e_x dt| per axis, integral_limit_n / k_i (0 where k_i = 0) [m s]
    k_R: np.ndarray  # (3,) [N m/rad]
    k_w: np.ndarray  # (3,) [N m s/rad]
    k_iR: np.ndarray  # (3,) [N m/(rad s)]
    i_R_max: np.ndarray  # (3,) bound on |int e_R dt| per axis, attitude_integral_limit_nm / k_iR [rad s]
    J: np.ndarray  # (3, 3) composite rigid-body inertia about the CoM, body axes [kg m^2]
    K_q: np.ndarray  # (n,) [N m/rad]
    D_q: np.ndarray  # (n,) [N m s/rad]
    ik_iterations: int
    ik_damping: float
    q_min: np.ndarray  # joint limits from the URDF [rad]
    q_max: np.ndarray
    q_nominal: np.ndarray
    r_BC: np.ndarray  # nominal CoM offset from the base origin, level base, {b} [m]
    wrench_filter: LowPass2  # diagnostics only
    task_frame: TaskFrame
    components: tuple[str, ...]
    arm: str = "joint"  # "joint" (K_q, D_q on the IK's q_d) or "cartesian" (K_y, D_y at the pad)
    K_y: np.ndarray | None = None  # (3,) x, z, pitch in the task frame [N/m, N/m, N m/rad] (arm = "cartesian")
    D_y: np.ndarray | None = None  # (3,) [N s/m, N s/m, N m s/rad]
    reaction_feedforward: bool = False

    def __post_init__(self) -> None:
        if self.arm not in ("joint", "cartesian"):
            raise ValueError(f"arm: expected 'joint' or 'cartesian', got {self.arm!r}")
        if self.arm == "cartesian" and (self.K_y is None or self.D_y is None):
            raise ValueError("arm = 'cartesian' needs K_y and D_y")
        if self.reaction_feedforward and self.arm != "cartesian":
            raise ValueError("reaction_feedforward needs arm = 'cartesian'")

    @staticmethod
    def from_vehicle(v: VehicleParams, model: AmModel, task_frame: TaskFrame) -> "BaselineParams":
        b = v.baseline
        if b is None:
            raise ValueError(f"vehicle '{v.name}' has no [baseline] table")
        if tuple(v.task.components) != PLANAR_COMPONENTS:
            raise ValueError(f"the baseline's inverse kinematics is for task components {PLANAR_COMPONENTS}, "
                             f"vehicle has {v.task.components}")
        pm = model.pin_model
        return BaselineParams(
            k_x=np.array(b.k_x), k_v=np.array(b.k_v), k_i=np.array(b.k_i),
            i_max=np.array([lim / k if k > 0.0 else 0.0 for lim, k in zip(b.integral_limit_n, b.k_i)]),
            k_R=np.array(b.k_R), k_w=np.array(b.k_w), k_iR=np.array(b.k_iR),
            i_R_max=np.array([lim / k if k > 0.0 else 0.0 for lim, k in zip(b.attitude_integral_limit_nm, b.k_iR)]),
            J=composite_inertia(model, v.q_nominal_rad), K_q=np.array(b.K_q), D_q=np.array(b.D_q),
            ik_iterations=b.ik_iterations, ik_damping=b.ik_damping,
            q_min=np.array(pm.lowerPositionLimit[7:]), q_max=np.array(pm.upperPositionLimit[7:]),
            q_nominal=np.array(v.q_nominal_rad), r_BC=nominal_geometry(model).r_BC,
            wrench_filter=LowPass2(v.options.force_filter_hz, v.options.force_filter_zeta),
            task_frame=task_frame, components=tuple(v.task.components),
            arm=b.arm, K_y=np.array(b.K_y) if b.K_y else None, D_y=np.array(b.D_y) if b.D_y else None,
            reaction_feedforward=b.reaction_feedforward,
        )


@dataclass(frozen=True)
class BaselineMemory:
    """What the baseline carries from one step to the next (passed back in)."""

    t_s: float | None = None
    wrench: FilterState | None = None  # filtered [f; m] of F_e, world-aligned at {e} (diagnostics only)
    i_x: tuple[float, float, float] = (0.0, 0.0, 0.0)  # int e_x dt [m s]
    i_R: tuple[float, float, float] = (0.0, 0.0, 0.0)  # int e_R dt [rad s]
    q_d: np.ndarray | None = None  # last IK solution (warm start) [rad]
    w_arm: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the arm's spring wrench on the pad, (x, z, pitch) in {b} [N, N, N m]


def composite_inertia(model: AmModel, q_arm) -> np.ndarray:
    """Rotational inertia of the whole AM about its CoM with the arm locked at q_arm and the base
    level, in body axes [kg m^2] (pinocchio's centroidal composite rigid-body inertia)."""
    pm = model.pin_model
    data = pm.createData()
    q = pin.neutral(pm)
    q[7:] = q_arm
    pin.ccrba(pm, data, q, np.zeros(pm.nv))
    return np.array(data.Ig.inertia)


def base_reference(params: BaselineParams, ref: Reference) -> tuple[np.ndarray, ...]:
    """p_d and its first four derivatives [m, m/s, ...]: the CoM reference less the nominal offset
    R_z(psi) r_BC (constant for a constant heading; the mission's is)."""
    c, s = math.cos(ref.psi), math.sin(ref.psi)
    x, y, z = params.r_BC.tolist()
    off = np.array([c * x - s * y, s * x + c * y, z])
    return ref.r_c - off, ref.r_c_d1, ref.r_c_d2, ref.r_c_d3, ref.r_c_d4


def planar_fk(model: AmModel, data: pin.Data, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pad pose (x, z, pitch) in {b} at joint angles q, and its Jacobian d(x, z, pitch)/dq (3 x n)."""
    pm = model.pin_model
    fid = model.ee_frame_id
    q_pin = np.concatenate(((0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0), q))
    pin.computeJointJacobians(pm, data, q_pin)
    H = pin.updateFramePlacement(pm, data, fid)
    J = pin.getFrameJacobian(pm, data, fid, pin.LOCAL_WORLD_ALIGNED)
    p, R = H.translation, H.rotation
    return np.array([p[0], p[2], angle_of(R, "pitch")]), J[[0, 2, 4], 6:]


IK_TOLERANCE = 1e-10  # [m, rad]: a pose error below this ends the Newton steps early


def inverse_kinematics(model: AmModel, data: pin.Data, target: np.ndarray, q0: np.ndarray, iterations: int,
                       damping: float, q_min: np.ndarray, q_max: np.ndarray) -> tuple[np.ndarray, float]:
    """Up to `iterations` damped Newton steps dq = J^T (J J^T + damping^2 I)^-1 (target - fk(q))
    from q0, each clipped to the joint limits; they stop once the pose error is below
    IK_TOLERANCE. Returns q and the smallest singular value of J at it."""
    q = np.array(q0, dtype=float)
    damp = damping * damping * np.eye(len(q))
    y, J = planar_fk(model, data, q)
    for _ in range(iterations):
        e = target - y
        e[2] = math.remainder(e[2], 2.0 * math.pi)
        if np.abs(e).max() < IK_TOLERANCE:
            break
        q = np.clip(q + J.T.dot(linalg3.solve(J.dot(J.T) + damp, e)), q_min, q_max)
        y, J = planar_fk(model, data, q)
    return q, linalg3.sigma_min(J)


def ik_target(params: BaselineParams, p_d: np.ndarray, R_d: np.ndarray, y_d: np.ndarray) -> np.ndarray:
    """The pad's reference (x, z, pitch in {t}) seen from the base's reference pose (p_d, R_d):
    (x, z, pitch) of the pad in that {b}."""
    fr = params.task_frame
    x, z, theta = y_d.tolist()
    c, s = math.cos(theta), math.sin(theta)
    R_TE = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # pitch theta about {t}'s y
    p_BE = R_d.T.dot(fr.p_WT + fr.R_WT.dot((x, 0.0, z)) - p_d)
    R_BE = R_d.T.dot(fr.R_WT).dot(R_TE)
    return np.array([p_BE[0], p_BE[2], angle_of(R_BE, "pitch")])


def body_to_task_xz(frame: TaskFrame, R_d: np.ndarray) -> np.ndarray:
    """A: the x-z block of R_WT^T R_d, which turns a vector of the arm's plane from the base's
    reference axes into the task frame's (a pitch rotation when R_d's heading is {t}'s)."""
    M = frame.R_WT.T.dot(R_d)
    return M[np.ix_((0, 2), (0, 2))]


def cartesian_wrench(params: BaselineParams, A: np.ndarray, e: np.ndarray,
                     edot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pad impedance's (x, z, pitch) wrench in {b}, its spring part K_y e and its damping
    part -D_y edot, from the pad's task error e = y_d - y and its rate edot = ydot - y_d' (in the
    task frame); A turns {b}'s x-z plane into the task frame's (`body_to_task_xz`)."""
    e = np.array(e, dtype=float)
    e[2] = math.remainder(e[2], 2.0 * math.pi)
    k, d = params.K_y, params.D_y
    spring = np.concatenate((A.T.dot(k[0:2] * e[0:2]), (k[2] * e[2],)))
    damp = -np.concatenate((A.T.dot(d[0:2] * edot[0:2]), (d[2] * edot[2],)))
    return spring, damp


def measured_task_pose(model: AmModel, data: pin.Data, frame: TaskFrame, q_pin: np.ndarray,
                       v_pin: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pad's (x, z, pitch) in the task frame and their rates, from the measured state."""
    pin.forwardKinematics(model.pin_model, data, q_pin, v_pin)
    return task_pose_of(model, data, frame)


def task_pose_of(model: AmModel, data: pin.Data, frame: TaskFrame) -> tuple[np.ndarray, np.ndarray]:
    """As `measured_task_pose`, from `data` whose forward kinematics (with velocities) is done."""
    fid = model.ee_frame_id
    H = pin.updateFramePlacement(model.pin_model, data, fid)
    twist = pin.getFrameVelocity(model.pin_model, data, fid, pin.LOCAL_WORLD_ALIGNED)
    p_T = frame.R_WT.T.dot(H.translation - frame.p_WT)
    R_TE = frame.R_WT.T.dot(H.rotation)
    v_T, w_T = frame.R_WT.T.dot(twist.linear), frame.R_WT.T.dot(twist.angular)
    return (np.array([p_T[0], p_T[2], angle_of(R_TE, "pitch")]),
            np.array([v_T[0], v_T[2], _pitch_rate(R_TE, w_T)]))


def _pitch_rate(R_TE: np.ndarray, w_T: np.ndarray) -> float:
    """d/dt of angle_of(R_TE, "pitch") for {e} turning at w_T (in {t}); see amcore.task."""
    u = R_TE[:, 2]  # {e}'s z axis in {t}: i = z, j = x, k = y
    D = 1.0 - u[1] * u[1]
    a = -u[1] * u
    a[1] += 1.0
    return float(a.dot(w_T) / D)


def step(model: AmModel, data: pin.Data, params: BaselineParams, state: AmState, ref: Reference,
         wrench_E: np.ndarray, memory: BaselineMemory, t_s: float) -> StepResult:
    """One evaluation of the baseline at time t_s [s] (see the module docstring).

    wrench_E: the wrist F/T reading [f_e; tau_e] in {e} [N, N m]; filtered for the diagnostics,
    never used by the law.
    """
    p = params
    pm = model.pin_model
    m, g, n = model.mass_kg, model.gravity_mps2, model.n
    R = state.R_WB
    w = state.w_B
    dt = 0.0 if memory.t_s is None else t_s - memory.t_s

    # --- position loop (Lee's eq. 12 with an integral term)
    p_d, p_d1, p_d2, p_d3, p_d4 = base_reference(p, ref)
    e_x = state.p_WB - p_d
    e_v = R.dot(state.v_B) - p_d1
    i_x = np.asarray(memory.i_x) + dt * e_x
    clamped = bool(np.any((np.abs(i_x) > p.i_max) & (p.k_i > 0.0)))  # anti-windup acts
    i_x = np.clip(i_x, -p.i_max, p.i_max)
    F_d = -p.k_x * e_x - p.k_v * e_v - p.k_i * i_x + m * (p_d2 + (0.0, 0.0, g))
    if p.reaction_feedforward:  # the reaction of the pad wrench the arm commanded at the last step
        f_b = np.array((memory.w_arm[0], 0.0, memory.w_arm[1]))
        F_d = F_d + R.dot(f_b)
    thrust = float(F_d.dot(R[:, 2]))

    # --- desired attitude and Lee's attitude law; W_d, Wdot_d from the reference's jerk and snap
    c, sn = math.cos(ref.psi), math.sin(ref.psi)
    pd1, pd2 = ref.psi_d1, ref.psi_d2
    b1 = (c, sn, 0.0)
    b1_d = (pd1 * -sn, pd1 * c, 0.0)
    b1_dd = (pd2 * -sn - pd1**2 * c, pd2 * c - pd1**2 * sn, 0.0)
    R_d, Omega_d, Omegadot_d = desired_attitude(F_d, m * p_d3, m * p_d4, b1, b1_d, b1_dd)
    Q = R.T.dot(R_d)  # R^T R_d
    S = Q.T - Q  # R_d^T R - R^T R_d
    e_R = 0.5 * np.array([S[2, 1], S[0, 2], S[1, 0]])
    w_bd = Q.dot(Omega_d)
    e_w = w - w_bd
    wdot_bd = Q.dot(Omegadot_d) - cross(w, w_bd)
    i_R = np.clip(np.asarray(memory.i_R) + dt * e_R, -p.i_R_max, p.i_R_max)

    # --- the state's kinematics and gravity: CoM, pad, g(q, R)
    q_pin, v_pin = state.pin_q(), state.pin_v()
    grav = pin.computeGeneralizedGravity(pm, data, q_pin).copy()  # [f_B; tau_B; tau_q] holding the AM still
    tau_B = -p.k_R * e_R - p.k_w * e_w - p.k_iR * i_R + cross(w, p.J.dot(w)) + p.J.dot(wdot_bd) + grav[3:6]
    # (-J (hat(W) R^T R_d W_d - R^T R_d Wdot_d) = J wdot_bd)

    # --- arm: the pad's reference seen from the base's reference pose; joint PD on its IK, or
    # the impedance at the pad; gravity compensation either way
    if p.arm == "cartesian":
        q_d = memory.q_d  # no IK
        y_m, ydot_m = measured_task_pose(model, data, p.task_frame, q_pin, v_pin)
        _, J_b = planar_fk(model, data, state.q)
        p_BE = data.oMf[model.ee_frame_id].translation.copy()  # base at the origin: the pad in {b}
        sigma = linalg3.sigma_min(J_b)
        w_arm, w_damp = cartesian_wrench(p, body_to_task_xz(p.task_frame, R), ref.y - y_m, ydot_m - ref.y_d1)
        tau_q = J_b.T.dot(w_arm + w_damp) + grav[6:]
    else:
        q_start = p.q_nominal if memory.q_d is None else memory.q_d
        iterations = p.ik_iterations if memory.q_d is not None else 10 * p.ik_iterations  # the first from q_nominal
        q_d, sigma = inverse_kinematics(model, data, ik_target(p, p_d, R_d, ref.y), q_start, iterations,
                                        p.ik_damping, p.q_min, p.q_max)
        tau_q = p.K_q * (q_d - state.q) - p.D_q * state.qdot + grav[6:]
    if p.reaction_feedforward:  # the moment of the last step's wrench, as its force above
        f_b = np.array((memory.w_arm[0], 0.0, memory.w_arm[1]))
        tau_B = tau_B + cross(p_BE, f_b) + np.array((0.0, memory.w_arm[2], 0.0))
    w_next = tuple(w_arm.tolist()) if p.reaction_feedforward else memory.w_arm

    # --- diagnostics on the measured state (after the IK, which used `data` for its own poses)
    r_c = pin.centerOfMass(pm, data, q_pin, v_pin).copy()
    rdot_c = data.vcom[0].copy()
    # centerOfMass(q, v) ran the forward kinematics: the pad's task pose from it, once per step
    y, ydot = (y_m, ydot_m) if p.arm == "cartesian" else task_pose_of(model, data, p.task_frame)
    R_WE = pin.updateFramePlacement(pm, data, model.ee_frame_id).rotation
    wr = np.asarray(wrench_E, dtype=float)
    raw_W = np.concatenate((R_WE.dot(wr[0:3]), R_WE.dot(wr[3:6]))).tolist()
    x_W, xd_W = lowpass_update_floats(p.wrench_filter, memory.wrench, raw_W, dt)
    x_W = np.array(x_W)
    wrench_E_f = np.concatenate((R_WE.T.dot(x_W[0:3]), R_WE.T.dot(x_W[3:6])))

    tau = np.concatenate(((0.0, 0.0, thrust), tau_B, tau_q))
    cmd = Command(thrust, tau_B.copy(), tau_q.copy())
    diag = Diagnostics(
        r_c=r_c, r_c_d=ref.r_c, r_c_err=r_c - ref.r_c, rdot_c=rdot_c,
        e_R=e_R, e_w=e_w, R_WB=R, R_d=R_d, w_bd=w_bd, wdot_bd=wdot_bd, Omega_d=Omega_d, f_d=F_d,
        y=y, y_d=ref.y, y_err=y - ref.y, ydot=ydot, F_y=np.zeros(n),
        F_rc=x_W[0:3], wrench_E_filtered=wrench_E_f,
        sigma_min_J3=sigma, damping=p.ik_damping**2, com_err_saturated=clamped, y_err_saturated=False,
        u=np.zeros(n + 6), tau=tau, Lambda_y=np.zeros((n, n)), wrench_W_filtered=x_W,
    )
    mem = BaselineMemory(t_s, FilterState(x_W.copy(), np.array(xd_W)), tuple(i_x.tolist()), tuple(i_R.tolist()), q_d,
                         w_next)
    return StepResult(cmd, diag, mem)
