"""Rigid-body model of one aerial manipulator and the inertially decoupled dynamics.

Conventions (paper Sec. II): V = [v_b, w_b, qdot] with v_b, w_b the body-frame linear and
angular velocity of the base {b} (its origin is the quadrotor's CoM) and qdot the joint
rates. This is exactly pinocchio's free-flyer velocity, so M, C and g come from pinocchio
unchanged (eq. dynamics). World frame {w} is z-up.

`decoupled_terms` evaluates the transform T (eq. new_coord), its inverse, its time
derivative, the decoupled inertia Lambda_xi and the product Gamma_xi xi (eq. new_dynamics).
Everything is closed form: with r_b the CoM offset in {b} and J_b = d r_b / d q,

    T     = [[R, -R hat(r_b), R J_b], [0, I, 0], [0, N_1, I]]
    T^-1  = [[R^T, hat(r_b) + J_b N_1, -J_b], [0, I, 0], [0, -N_1, I]]

and Tdot follows from Mdot = C + C^T, which holds because pinocchio's C is the
skew-consistent (Christoffel) one; Gamma_xi's zero blocks rely on that choice.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from .config import VehicleParams
from .so3 import hat, quat_wxyz_to_R


@dataclass(frozen=True)
class AmModel:
    """Immutable model of one AM: pinocchio model, frame ids and derived constants."""

    vehicle: VehicleParams
    pin_model: pin.Model = field(repr=False)
    mass_kg: float
    n: int
    ee_frame_id: int
    ft_frame_id: int
    gravity_mps2: float

    @property
    def nv(self) -> int:
        return self.n + 6


def build_model(vehicle: VehicleParams) -> AmModel:
    """Load the URDF with a free-flyer root and check it matches the vehicle parameters."""
    model = pin.buildModelFromUrdf(str(vehicle.urdf), pin.JointModelFreeFlyer())
    names = list(model.names)[2:]
    if tuple(names) != tuple(vehicle.arm_joints):
        raise ValueError(
            f"{vehicle.urdf}: arm joints in the URDF are {names}, the vehicle config lists {list(vehicle.arm_joints)}"
        )
    for frame in (vehicle.ee_frame, vehicle.ft_frame, vehicle.base_link):
        if not model.existFrame(frame):
            raise ValueError(f"{vehicle.urdf}: no frame named '{frame}'")
    model.gravity.linear = np.array([0.0, 0.0, -vehicle.gravity_mps2])
    return AmModel(
        vehicle=vehicle,
        pin_model=model,
        mass_kg=float(pin.computeTotalMass(model)),
        n=model.nv - 6,
        ee_frame_id=model.getFrameId(vehicle.ee_frame),
        ft_frame_id=model.getFrameId(vehicle.ft_frame),
        gravity_mps2=vehicle.gravity_mps2,
    )


def create_data(model: AmModel) -> pin.Data:
    """Scratch workspace for one model; not shared between threads."""
    return model.pin_model.createData()


@dataclass(frozen=True)
class AmState:
    """Measured state of one AM.

    p_WB: base position in {w} [m]; R_WB: base orientation ({w} <- {b});
    v_B, w_B: body-frame linear [m/s] and angular [rad/s] velocity; q [rad], qdot [rad/s].
    """

    p_WB: np.ndarray
    R_WB: np.ndarray
    v_B: np.ndarray
    w_B: np.ndarray
    q: np.ndarray
    qdot: np.ndarray

    @staticmethod
    def from_pin(q_pin: np.ndarray, v_pin: np.ndarray) -> "AmState":
        x, y, z, w = q_pin[3:7]
        return AmState(
            p_WB=np.array(q_pin[0:3]),
            R_WB=quat_wxyz_to_R(np.array([w, x, y, z])),
            v_B=np.array(v_pin[0:3]),
            w_B=np.array(v_pin[3:6]),
            q=np.array(q_pin[7:]),
            qdot=np.array(v_pin[6:]),
        )

    def pin_q(self) -> np.ndarray:
        quat = pin.Quaternion(self.R_WB)
        quat.normalize()
        return np.concatenate([self.p_WB, quat.coeffs(), self.q])  # coeffs are (x, y, z, w)

    def pin_v(self) -> np.ndarray:
        """V = [v_b, w_b, qdot] of eq. dynamics."""
        return np.concatenate([self.v_B, self.w_B, self.qdot])


@dataclass
class DecoupledTerms:
    """Model terms at one state (eq. dynamics, eq. new_coord, eq. new_dynamics).

    All arrays are in the paper's coordinates; `xi` = [rdot_c, w_b, rho].
    """

    M: np.ndarray  # (n+6, n+6) joint-space inertia
    C: np.ndarray  # (n+6, n+6) skew-consistent Coriolis matrix
    V: np.ndarray
    R_WB: np.ndarray
    r_c: np.ndarray  # CoM in {w} [m]
    r_b: np.ndarray  # CoM offset from {b}'s origin, in {b} [m]
    J_b: np.ndarray  # (3, n) d r_b / d q, in {b}
    N1: np.ndarray  # (n, 3) block of N = [0, N_1, I]
    T: np.ndarray
    T_inv: np.ndarray
    Tdot_V: np.ndarray  # Tdot @ V
    xi: np.ndarray
    Lambda_xi: np.ndarray
    Lambda_xi_inv: np.ndarray
    Gamma_xi_xi: np.ndarray  # Gamma_xi @ xi
    Mdot: np.ndarray  # C + C^T
    Tdot: np.ndarray | None = None  # only with full=True
    Gamma_xi: np.ndarray | None = None  # only with full=True

    @property
    def rdot_c(self) -> np.ndarray:
        return self.xi[0:3]

    @property
    def rho(self) -> np.ndarray:
        return self.xi[6:]


def decoupled_terms(model: AmModel, data: pin.Data, state: AmState, full: bool = False) -> DecoupledTerms:
    """Evaluate M, C, T, T^-1, Tdot V, xi, Lambda_xi, Gamma_xi xi at `state`.

    Also runs pinocchio's forward kinematics, Jacobians and their time variation into
    `data`, which `amcore.task` then reads. With full=True the matrices Tdot and Gamma_xi
    (= T^-T (C - M T^-1 Tdot) T^-1) are formed too; the controller only needs products.
    """
    pm = model.pin_model
    n, m = model.n, model.mass_kg
    q_pin, V = state.pin_q(), state.pin_v()
    pin.computeJointJacobiansTimeVariation(pm, data, q_pin, V)
    pin.updateFramePlacements(pm, data)
    M = pin.crba(pm, data, q_pin)
    M = np.triu(M) + np.triu(M, 1).T  # crba may fill only the upper triangle
    C = pin.computeCoriolisMatrix(pm, data, q_pin, V).copy()
    Mdot = C + C.T

    R = state.R_WB
    w, qd = state.w_B, state.qdot
    r_b = np.array([M[1, 5], M[2, 3], M[0, 4]]) / m  # M_vw = -m hat(r_b)
    J_b = M[0:3, 6:] / m
    Jdot_b = Mdot[0:3, 6:] / m
    rdot_b = J_b @ qd

    A = M[6:, 6:] - m * (J_b.T @ J_b)  # Z M Z^T
    B = M[6:, 3:6] - J_b.T @ M[0:3, 3:6]
    A_inv = np.linalg.inv(A)
    N1 = A_inv @ B
    Adot = Mdot[6:, 6:] - m * (Jdot_b.T @ J_b + J_b.T @ Jdot_b)
    Bdot = Mdot[6:, 3:6] - Jdot_b.T @ M[0:3, 3:6] - J_b.T @ Mdot[0:3, 3:6]
    N1dot = A_inv @ (Bdot - Adot @ N1)

    nv = n + 6
    hr = hat(r_b)
    Rhr = R @ hr
    RJ = R @ J_b
    T = np.zeros((nv, nv))
    T[0:3, 0:3] = R
    T[0:3, 3:6] = -Rhr
    T[0:3, 6:] = RJ
    T[3:6, 3:6] = np.eye(3)
    T[6:, 3:6] = N1
    T[6:, 6:] = np.eye(n)

    T_inv = np.zeros((nv, nv))
    T_inv[0:3, 0:3] = R.T
    T_inv[0:3, 3:6] = hr + J_b @ N1
    T_inv[0:3, 6:] = -J_b
    T_inv[3:6, 3:6] = np.eye(3)
    T_inv[6:, 3:6] = -N1
    T_inv[6:, 6:] = np.eye(n)

    hw = hat(w)
    Rhw = R @ hw
    v_b = V[0:3]
    # d/dt of the first block row R [I, -hat(r_b), J_b], applied to V
    Tdot_V = np.zeros(nv)
    Tdot_V[0:3] = Rhw @ (v_b - hr @ w + J_b @ qd) + R @ (-hat(rdot_b) @ w + Jdot_b @ qd)
    Tdot_V[6:] = N1dot @ w

    xi = T @ V
    Lambda_xi = T_inv.T @ M @ T_inv
    Lambda_xi_inv = T @ np.linalg.solve(M, T.T)
    Gamma_xi_xi = T_inv.T @ (C @ V - M @ (T_inv @ Tdot_V))

    terms = DecoupledTerms(
        M=M, C=C, V=V, R_WB=R, r_c=state.p_WB + R @ r_b, r_b=r_b, J_b=J_b, N1=N1,
        T=T, T_inv=T_inv, Tdot_V=Tdot_V, xi=xi, Lambda_xi=Lambda_xi,
        Lambda_xi_inv=Lambda_xi_inv, Gamma_xi_xi=Gamma_xi_xi, Mdot=Mdot,
    )
    if full:
        Tdot = np.zeros((nv, nv))
        Tdot[0:3, 0:3] = Rhw
        Tdot[0:3, 3:6] = -Rhw @ hr - R @ hat(rdot_b)
        Tdot[0:3, 6:] = Rhw @ J_b + R @ Jdot_b
        Tdot[6:, 3:6] = N1dot
        terms.Tdot = Tdot
        terms.Gamma_xi = T_inv.T @ (C - M @ T_inv @ Tdot) @ T_inv
    return terms


def generalized_gravity(model: AmModel, data: pin.Data, state: AmState) -> np.ndarray:
    """g(R_b, q) of eq. dynamics (pinocchio's generalized gravity)."""
    return pin.computeGeneralizedGravity(model.pin_model, data, state.pin_q()).copy()
