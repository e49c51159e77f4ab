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

import numpy as np
import pinocchio as pin

from . import linalg3
from .config import VehicleParams
from .so3 import hat, quat_wxyz_to_R, quat_xyzw_of_R, quat_xyzw_of_rows


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
    Lambda_xi^-1 and Mdot on first access). T's first block row is pinocchio's CoM Jacobian.

    Also runs pinocchio's forward kinematics, Jacobians and their time variation into
    `data`, which `amcore.task` then reads (computeCoriolisMatrix fills data.J and data.dJ
    as computeJointJacobiansTimeVariation does; tests/amcore/test_task.py checks it). With
    full=True the matrices Tdot and Gamma_xi (= T^-T (C - M T^-1 Tdot) T^-1) are formed
    too; the controller only needs products.

    Lambda_xi = T^-T M T^-1 is block diagonal (eq. new_dynamics) with blocks m I, Lambda_w
    and Lambda_rho = (N M^-1 N^T)^-1 = Z M Z^T = A. Its inverse T M^-1 T^T is read off
    pinocchio's M^-1 (computeMinverse): the step needs Lambda_w, N_1 and products with
    Lambda_xi^-1, all of which follow from M^-1 with one 3x3 inverse (not two: A^-1 is never
    formed). At these sizes numpy's cost is per call, not per flop, so the code below keeps the
    number of calls low: whole block rows at once, ndarray.dot (half the cost of `@`), and
    3-vectors on Python floats.
    """
    pm = model.pin_model
    n, m = model.n, model.mass_kg
    nv = n + 6
    R = state.R_WB
    Rl = R.tolist()
    p_l, w_l = state.p_WB.tolist(), state.w_B.tolist()
    q_pin, V = _pin_qv(state, Rl, p_l, w_l)
    Jcom = pin.jacobianCenterOfMass(pm, data, q_pin, False)  # R [I, -hat(r_b), J_b], T's first block row
    M_inv = pin.computeMinverse(pm, data, q_pin)  # one C++ pass: replaces forming M, Z M, A and A^-1
    C = pin.computeCoriolisMatrix(pm, data, q_pin, V)
    pin.updateFramePlacements(pm, data)
    Mdot = C.T.copy()  # Mdot = C + C^T; `C + C.T` (mixed memory layouts) measured ~2 us slower in the step
    Mdot += C

    w = state.w_B
    Mv_T = Jcom.T.dot(R)  # [I, -hat(r_b), J_b]^T (eq. new_coord, in {b}), transposed: its blocks are row blocks
    (_, _, y), (z, _, _), (_, x, _) = Mv_T[3:6].tolist()  # hat(r_b)
    rb = (x, y, z)
    J_b = Mv_T[6:].T

    # Lambda_xi^-1 = T M^-1 T^T is block diagonal (eq. new_dynamics) and T's middle block row is
    # [0, I, 0], so Lambda_w^-1 is M^-1's middle block. T^-1 is stored transposed (T^-T: the
    # products below then read contiguous rows, which numpy does not copy first). Its middle block
    # row, T^-1's middle block column [hat(r_b) + J_b N_1; I; -N_1], is Lambda_w (M^-1)_(w,:): from
    # T M^-1 = Lambda_xi^-1 T^-T, whose middle block row is (M^-1)_(w,:) = Lambda_w^-1 (T^-T)_(w,:).
    # (Negations act on whole contiguous arrays, then a block is taken: a ufunc on a strided
    # block takes numpy's slow path, ~1 us more at this size.)
    Lambda_w = linalg3.inv_sym(M_inv[3:6, 3:6])
    K = Lambda_w.dot(M_inv[3:6])
    T_invT = _eye(nv)
    T_invT[0:3, 0:3] = R
    T_invT[3:6] = K
    T_invT[6:, 0:3] = -Mv_T[6:]  # -J_b^T
    T_inv = T_invT.T  # [[R^T, hat(r_b) + J_b N_1, -J_b], [0, I, 0], [0, -N_1, I]]
    N1 = (-K)[:, 6:].T

    T = _eye(nv)
    T[0:3] = Jcom
    T[6:, 3:6] = N1

    # Tdot V. First block row R [I, -hat(r_b), J_b]: its rate applied to V is, with
    # s = R^T rdot_c = [I, -hat(r_b), J_b] V, R (hat(w) s + [0, -hat(rdot_b), Jdot_b] V), and
    # m [0, -hat(rdot_b), Jdot_b] is Mdot's first block row (its first block, d(m I)/dt, is zero).
    # Last block row: N1dot w = A^-1 (Bdot w - Adot N_1 w) = A^-1 d/dt(Z M) c with
    # c = T^-1 [0; w; 0] = [(hat(r_b) + J_b N_1) w; w; -N_1 w]. d/dt(Z M) = Zdot M + Z Mdot
    # and M c has a zero first block row (M T^-1's (0, w) block, eq. new_dynamics), which is
    # all Zdot = [-Jdot_b^T, 0, 0] sees; so N1dot w = A^-1 Z Mdot c, with Z = (T^-1[:, 6:])^T.
    (R00, R01, R02), (R10, R11, R12), (R20, R21, R22) = Rl
    s0, s1, s2 = V.dot(Mv_T).tolist()
    d0, d1, d2 = Mdot.dot(V).tolist()[0:3]
    w0, w1, w2 = w_l
    a0, a1, a2 = w1 * s2 - w2 * s1 + d0 / m, w2 * s0 - w0 * s2 + d1 / m, w0 * s1 - w1 * s0 + d2 / m
    aW = (R00 * a0 + R01 * a1 + R02 * a2, R10 * a0 + R11 * a1 + R12 * a2, R20 * a0 + R21 * a1 + R22 * a2)
    Mdot_c = Mdot.dot(w.dot(K))  # c = T^-1 [0; w; 0] = K^T w
    ZMdot_c = T_invT[6:].dot(Mdot_c)  # = A N1dot w
    # A^-1 is Lambda_xi^-1's last block, and Lambda_xi^-1 T^-T = T M^-1, so A^-1 Z Mdot c = (T M^-1 Mdot c)'s
    # last block = [0, N_1, I] M^-1 Mdot c
    N1dot_w = T[6:].dot(M_inv.dot(Mdot_c)).tolist()
    # Lambda_xi Tdot V = [m R a; 0; A N1dot w] (Lambda_xi is blockdiag(m I, Lambda_w, A) and
    # Tdot V's middle block is zero); r_c = p_WB + R r_b; rdot_c = R s. All of them, and Tdot V,
    # as views of one array (numpy's cost is per call)
    p0, p1, p2 = p_l
    rb0, rb1, rb2 = rb
    out = np.array([*aW, 0.0, 0.0, 0.0, *N1dot_w, m * aW[0], m * aW[1], m * aW[2], 0.0, 0.0, 0.0, *ZMdot_c.tolist(),
                    rb0, rb1, rb2, p0 + (R00 * rb0 + R01 * rb1 + R02 * rb2), p1 + (R10 * rb0 + R11 * rb1 + R12 * rb2),
                    p2 + (R20 * rb0 + R21 * rb1 + R22 * rb2), R00 * s0 + R01 * s1 + R02 * s2,
                    R10 * s0 + R11 * s1 + R12 * s2, R20 * s0 + R21 * s1 + R22 * s2])
    Tdot_V = out[0:nv]

    Gamma_xi_xi = T_invT.dot(C.dot(V)) - out[nv:2 * nv]  # T^-T (C V - M T^-1 Tdot V)

    terms = DecoupledTerms(  # positional, in field order (matching 16 keywords costs more)
        q_pin, pm, C, V, R,  # q_pin, pin_model, C, V, R_WB
        out[2 * nv + 3:2 * nv + 6], out[2 * nv:2 * nv + 3], J_b, N1,  # r_c, r_b, J_b, N1
        T, T_inv, Tdot_V, out[2 * nv + 6:], Lambda_w,  # T, T_inv, Tdot_V, rdot_c, Lambda_w
        M_inv, Gamma_xi_xi,  # M_inv, Gamma_xi_xi
    )
    if full:
        r_b = terms.r_b
        Jdot_b = Mdot[0:3, 6:] / m
        hr = hat(r_b)
        rdot_b = J_b @ state.qdot
        Rhw = R @ hat(w)
        ZMdot = Mdot[6:] - Mdot[0:3, 6:].T @ Mv_T.T - J_b.T @ Mdot[0:3]  # d/dt (Z M)
        M = terms.M
        A_inv = np.linalg.inv(M[6:, 6:] - J_b.T @ M[0:3, 6:])  # A = Z M Z^T
        N1dot = A_inv @ (ZMdot[:, 3:6] - ZMdot[:, 6:] @ N1)
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


def _pin_qv(state: AmState, R_rows: list, p: list, w: list) -> tuple[np.ndarray, np.ndarray]:
    """(state.pin_q(), state.pin_v()) as two views of one new array (one numpy call, not three);
    R_rows, p, w: state.R_WB, p_WB, w_B as lists."""
    quat = state.quat_xyzw
    if quat is None:
        quat = quat_xyzw_of_rows(R_rows)
    q = state.q.tolist()
    nq = 7 + len(q)
    qv = np.fromiter([*p, *quat, *q, *state.v_B.tolist(), *w, *state.qdot.tolist()],
                     float, nq + 6 + len(q))  # fromiter with a count: cheaper than np.array for long lists
    return qv[0:nq], qv[nq:]


@lru_cache(maxsize=None)
def _identity(nv: int) -> np.ndarray:
    out = np.eye(nv)
    out.flags.writeable = False
    return out


def _eye(nv: int) -> np.ndarray:
    """A fresh identity (copying a cached one costs a sixth of np.eye)."""
    return _identity(nv).copy()


def generalized_gravity(model: AmModel, data: pin.Data, state: AmState) -> np.ndarray:
    """g(R_b, q) of eq. dynamics (pinocchio's generalized gravity)."""
    return pin.computeGeneralizedGravity(model.pin_model, data, state.pin_q()).copy()
