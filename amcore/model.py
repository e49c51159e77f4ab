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
from functools import cached_property, lru_cache
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from . import law
from .config import VehicleParams
from .so3 import hat, quat_wxyz_to_R, quat_xyzw_of_R


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


class AmState(NamedTuple):
    """Measured state of one AM.

    p_WB: base position in {w} [m]; R_WB: base orientation ({w} <- {b});
    v_B, w_B: body-frame linear [m/s] and angular [rad/s] velocity; q [rad], qdot [rad/s].
    quat_xyzw: optionally, the unit quaternion (x, y, z, w) that R_WB was built from (a
    sensor frame carries one); pin_q() then uses it instead of recovering it from R_WB.
    """

    p_WB: np.ndarray
    R_WB: np.ndarray
    v_B: np.ndarray
    w_B: np.ndarray
    q: np.ndarray
    qdot: np.ndarray
    quat_xyzw: tuple[float, float, float, float] | None = None

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
        """[p_WB, quaternion (x, y, z, w) of R_WB, q]: pinocchio's free-flyer configuration."""
        quat = self.quat_xyzw
        if quat is None:
            quat = quat_xyzw_of_R(self.R_WB)
        return np.array(self.p_WB.tolist() + list(quat) + self.q.tolist())

    def pin_v(self) -> np.ndarray:
        """V = [v_b, w_b, qdot] of eq. dynamics."""
        return np.concatenate((self.v_B, self.w_B, self.qdot))


@dataclass
class DecoupledTerms:
    """Model terms at one state (eq. dynamics, eq. new_coord, eq. new_dynamics).

    All arrays are in the paper's coordinates; `xi` = [rdot_c, w_b, rho]. The controller
    needs M, xi, Lambda_xi and Mdot only through products, one block or pinocchio's M^-1 and
    CoM Jacobian, so those four are formed on first access (tests read them; the step does not).
    """

    q_pin: np.ndarray  # pinocchio's configuration [p_WB, quat_xyzw, q]
    pin_model: pin.Model = field(repr=False)
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
    rdot_c: np.ndarray  # CoM velocity in {w} [m/s], xi's first block
    Lambda_w: np.ndarray  # (3, 3) Lambda_xi's middle block (eq. new_dynamics)
    M_inv: np.ndarray  # M^-1
    Gamma_xi_xi: np.ndarray  # Gamma_xi @ xi
    Tdot: np.ndarray | None = None  # only with full=True
    Gamma_xi: np.ndarray | None = None  # only with full=True

    @cached_property
    def M(self) -> np.ndarray:
        """(n+6, n+6) joint-space inertia (eq. dynamics)."""
        M = pin.crba(self.pin_model, self.pin_model.createData(), self.q_pin)
        return M if _crba_returns_symmetric() else np.triu(M) + np.triu(M, 1).T

    @cached_property
    def xi(self) -> np.ndarray:
        return self.T @ self.V

    @cached_property
    def Lambda_xi(self) -> np.ndarray:
        """T^-T M T^-1 (eq. new_dynamics), block diagonal: m I, Lambda_w, Lambda_rho."""
        return self.T_inv.T @ self.M @ self.T_inv

    @cached_property
    def Lambda_xi_inv(self) -> np.ndarray:
        """T M^-1 T^T: blockdiag(I / m, Lambda_w^-1, A^-1)."""
        return self.T @ self.M_inv @ self.T.T

    @cached_property
    def Mdot(self) -> np.ndarray:
        """dM/dt = C + C^T (pinocchio's C is skew-consistent)."""
        return self.C + self.C.T

    @property
    def rho(self) -> np.ndarray:
        return self.xi[6:]


def decoupled_terms(model: AmModel, data: pin.Data, state: AmState, full: bool = False) -> DecoupledTerms:
    """Evaluate M^-1, C, T, T^-1, Tdot V, Lambda_w, Gamma_xi xi at `state` (M, xi, Lambda_xi,
    Lambda_xi^-1 and Mdot on first access): pinocchio's CoM Jacobian, M^-1 and C, then the
    compiled amcore.law.decoupled (eq. new_coord, new_dynamics; derivation there).

    Also runs pinocchio's forward kinematics, Jacobians and their time variation into
    `data`, which `amcore.task` then reads (computeCoriolisMatrix fills data.J and data.dJ
    as computeJointJacobiansTimeVariation does; tests/amcore/test_task.py checks it). With
    full=True the matrices Tdot and Gamma_xi (= T^-T (C - M T^-1 Tdot) T^-1) are formed
    too, with numpy; the control law only needs products.
    """
    pm = model.pin_model
    q_pin, V = pin_configuration(state)
    Jcom = pin.jacobianCenterOfMass(pm, data, q_pin, False)  # R [I, -hat(r_b), J_b], T's first block row
    M_inv = pin.computeMinverse(pm, data, q_pin)
    C = pin.computeCoriolisMatrix(pm, data, q_pin, V)
    pin.updateFramePlacements(pm, data)
    R = state.R_WB
    T, T_inv, Tdot_V, Lambda_w, Gamma_xi_xi, r_c, rdot_c, r_b, J_b, N1 = law.decoupled(
        model.mass_kg, R, state.p_WB, state.w_B, V, Jcom, M_inv, C)
    terms = DecoupledTerms(q_pin=q_pin, pin_model=pm, C=C, V=V, R_WB=R, r_c=r_c, r_b=r_b, J_b=J_b, N1=N1, T=T,
                           T_inv=T_inv, Tdot_V=Tdot_V, rdot_c=rdot_c, Lambda_w=Lambda_w, M_inv=M_inv,
                           Gamma_xi_xi=Gamma_xi_xi)
    if full:
        m, w = model.mass_kg, state.w_B
        Mdot = C + C.T
        Jdot_b = Mdot[0:3, 6:] / m
        hr = hat(r_b)
        rdot_b = J_b @ state.qdot
        Rhw = R @ hat(w)
        B = R.T @ Jcom  # [I, -hat(r_b), J_b]
        ZMdot = Mdot[6:] - Mdot[0:3, 6:].T @ B - J_b.T @ Mdot[0:3]  # d/dt (Z M)
        M = terms.M
        A_inv = np.linalg.inv(M[6:, 6:] - J_b.T @ M[0:3, 6:])  # A = Z M Z^T
        N1dot = A_inv @ (ZMdot[:, 3:6] - ZMdot[:, 6:] @ N1)
        nv = model.nv
        Tdot = np.zeros((nv, nv))
        Tdot[0:3, 0:3] = Rhw
        Tdot[0:3, 3:6] = -Rhw @ hr - R @ hat(rdot_b)
        Tdot[0:3, 6:] = Rhw @ J_b + R @ Jdot_b
        Tdot[6:, 3:6] = N1dot
        terms.Tdot = Tdot
        terms.Gamma_xi = T_inv.T @ (C - M @ T_inv @ Tdot) @ T_inv
    return terms


@lru_cache(maxsize=None)
def _crba_returns_symmetric() -> bool:
    """Whether pin.crba returns the whole M. Its C++ fills the upper triangle only; the Python
    binding has long copied it to the lower one. Checked once, on pinocchio's sample arm."""
    pm = pin.buildSampleModelManipulator()
    M = pin.crba(pm, pm.createData(), pin.randomConfiguration(pm))
    return bool(np.array_equal(M, M.T))


def pin_configuration(state: AmState) -> tuple[np.ndarray, np.ndarray]:
    """(state.pin_q(), state.pin_v()) as two views of one new array: joined by numpy when the
    state carries its quaternion, else by amcore.law (which recovers it from R_WB)."""
    if state.quat_xyzw is None:
        return law.free_flyer_configuration_of_R(state.p_WB, state.R_WB, state.q, state.v_B, state.w_B, state.qdot)
    qv = np.concatenate((state.p_WB, state.quat_xyzw, state.q, state.v_B, state.w_B, state.qdot))
    nq = 7 + state.q.shape[0]
    return qv[:nq], qv[nq:]


def generalized_gravity(model: AmModel, data: pin.Data, state: AmState) -> np.ndarray:
    """g(R_b, q) of eq. dynamics (pinocchio's generalized gravity)."""
    return pin.computeGeneralizedGravity(model.pin_model, data, state.pin_q()).copy()
