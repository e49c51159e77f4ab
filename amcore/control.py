"""Decentralized passivity-based controller of one AM (paper Sec. III-B).

One call of `step` evaluates, at one measured state:
- the CoM law with force compensation (eq. Com_controller): f_d, u_1 = f_d . R_b e_3;
- the desired attitude (eq. Rd) with Omega_d and Omegadot_d from f_d's derivatives;
- the orientation law (eq. ori_controller) with e_R, e_w (eq. ori_error, ori_vel_error);
- the end-effector impedance law (eq. u3), which makes the task error obey
      Lambda_y y~dd + D_y y~d + K_y y~ = F_y          (eq. desired_task_behavior);
- tau = T^T u, whose first two entries vanish (thrust acts along body z only).

The equations are in amcore.law, one compiled function each. `step` asks pinocchio for the
rigid-body terms, calls law.control_law once and names what it returns (Command,
Diagnostics, ControllerMemory).

Details the paper leaves implicit, as implemented here:
- Gamma_xi uses pinocchio's skew-consistent C (see amcore.model).
- w_b,d = R_b^T R_d Omega_d, so d/dt w_b,d = -hat(w_b) w_b,d + R_b^T R_d Omegadot_d.
- f_d's derivatives use the model's CoM acceleration r_c_dd = (u_1 b_3 + F_rc)/m - g e_3
  and the measured wrench after a 2nd-order low-pass whose derivatives are exact.
- Without force compensation (options.force_compensation = false) the controller needs
  no F/T sensor: F_rc leaves f_d, F_wb leaves u_2, and the measured wrench does not
  influence the command at all. The CoM acceleration is then unknown under contact (the
  free-flight model's prediction is off by F_e/m; in PyBullet that made Omega_d spurious
  by D_t F_e / (m |f_d|) ~ 6 rad/s and the grasp fell), so f_d's derivatives keep only
  what is measured or known: f_d' = m r_d^(3) - K_t e', f_d'' = m r_d^(4).
- Singularity guard (beyond the paper): the CoM error entering f_d's spring is saturated at
  safety.com_err_max_m, each task error at safety.y_err_max, and Jbar_3 is inverted by
  damped least squares once its smallest singular value drops below safety.sigma_damping.
  Away from those limits the law is exactly the paper's.
- Option compensate_Lambda_y_dot adds 1/2 dLambda_y/dt y~d to the damping, which the
  paper's storage argument (Theorem 2) drops; with it the storage balance is exact. That
  term is evaluated with the numpy model terms (amcore.model and amcore.task with
  full=True), outside the compiled law; no shipped scenario turns it on.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from . import law
from .config import VehicleParams
from .filters import FilterState, LowPass2
from .model import AmModel, AmState, decoupled_terms, pin_configuration
from .task import TaskFrame, component_axes, task_terms


class Reference(NamedTuple):
    """Desired trajectories at one instant.

    r_c: CoM position in {w} [m] with derivatives up to snap (r_c_d4); the heading psi of
    b_1d = [cos psi, sin psi, 0] [rad] with two derivatives; y_d in the task frame with two.
    The fields are in law.control_law's order (`step` passes them on as `*ref`).
    """

    r_c: np.ndarray
    r_c_d1: np.ndarray
    r_c_d2: np.ndarray
    r_c_d3: np.ndarray
    r_c_d4: np.ndarray
    psi: float
    psi_d1: float
    psi_d2: float
    y: np.ndarray
    y_d1: np.ndarray
    y_d2: np.ndarray


@dataclass(frozen=True)
class ControllerParams:
    """Everything constant about one AM's controller."""

    gains_K_t: np.ndarray
    gains_D_t: np.ndarray
    k_R: float
    k_w: float
    Lambda_wb_d_inv: np.ndarray
    K_y: np.ndarray
    D_y: np.ndarray
    com_err_max: float
    y_err_max: np.ndarray
    sigma_damping: float
    damping_max: float
    force_compensation: bool
    compensate_Lambda_y_dot: bool
    force_rate_feedforward: bool
    compensate_along_face: bool
    wrench_filter: LowPass2
    task_frame: TaskFrame
    components: tuple[str, ...]
    damping_dt: float = 0.0  # [options].discrete_damping: the control period [s] (law.discrete_damping); 0: D_y

    @staticmethod
    def from_vehicle(v: VehicleParams, task_frame: TaskFrame) -> "ControllerParams":
        g, s, o = v.gains, v.safety, v.options
        n = v.n_joints
        return ControllerParams(
            gains_K_t=np.diag(g.K_t), gains_D_t=np.diag(g.D_t), k_R=g.k_R, k_w=g.k_w,
            Lambda_wb_d_inv=np.diag(1.0 / np.array(g.Lambda_wb_d)),
            K_y=np.diag(g.K_y), D_y=np.diag(g.D_y),
            com_err_max=s.com_err_max_m,
            y_err_max=np.array(s.y_err_max) if s.y_err_max else np.full(n, np.inf),
            sigma_damping=s.sigma_damping, damping_max=s.damping_max,
            force_compensation=o.force_compensation, compensate_Lambda_y_dot=o.compensate_Lambda_y_dot,
            force_rate_feedforward=o.force_rate_feedforward, compensate_along_face=o.compensate_along_face,
            wrench_filter=LowPass2(o.force_filter_hz, o.force_filter_zeta),
            task_frame=task_frame, components=v.task.components,
        )

    @cached_property
    def axes(self) -> np.ndarray:
        """The task components as law.task reads them (amcore.task.component_axes)."""
        return component_axes(tuple(self.components))

    @cached_property
    def zero_task(self) -> np.ndarray:
        return np.zeros(len(self.components))

    @cached_property
    def law_constants(self) -> tuple:
        """law.control_law's constant arguments from filter_omega to force_rate_feedforward, in
        its order (formed once; `step` passes them on as they are)."""
        wf = self.wrench_filter
        return (wf.omega, wf.zeta, self.gains_K_t, self.gains_D_t, self.k_R, self.k_w, self.Lambda_wb_d_inv,
                self.K_y, self.D_y, self.com_err_max, self.y_err_max, self.sigma_damping, self.damping_max,
                self.force_compensation, self.force_rate_feedforward)


class ControllerMemory(NamedTuple):
    """What the controller carries from one step to the next (passed back in)."""

    t_s: float | None = None
    wrench: FilterState | None = None  # filtered [f; m] of F_e, world-aligned at {e} [N, N m]


class Command(NamedTuple):
    """Torque-level setpoint: thrust along body z [N], body torque [N m], joint torques [N m]."""

    thrust_n: float
    tau_B_nm: np.ndarray
    tau_q_nm: np.ndarray


class StepTerms(NamedTuple):
    """The model and task terms a step evaluated, for laws built on it (amcore.offboard)."""

    M_inv: np.ndarray  # M^-1 (eq. dynamics)
    T_inv: np.ndarray  # T^-1 (eq. new_coord)
    Lambda_w: np.ndarray  # Lambda_xi's middle block (eq. new_dynamics)
    Gamma_xi_xi: np.ndarray  # Gamma_xi xi
    J_y: np.ndarray  # (n, n+6): ydot = J_y V
    J_e_xi: np.ndarray  # (6, n+6): J_e T^-1


_DIAGNOSTICS_REQUIRED = (
    "r_c",  # CoM in {w} [m]
    "r_c_d",  # its reference [m]
    "r_c_err",  # r~_c = r_c - r_c,d [m]
    "rdot_c",  # CoM velocity [m/s]
    "e_R", "e_w",  # eq. ori_error, ori_vel_error
    "R_WB", "R_d",  # measured and desired attitude (eq. Rd)
    "w_bd", "wdot_bd", "Omega_d",  # w_b,d and its rate, Omega_d [rad/s, rad/s^2]
    "f_d",  # eq. Com_controller [N]
    "y", "y_d", "y_err", "ydot",  # task variable, its reference, error and rate
    "F_y",  # task-space force of eq. desired_task_behavior
    "F_rc",  # filtered end-effector force in {w} [N]
    "wrench_E_filtered",  # filtered F/T reading [f; m] in {e} [N, N m]
    "sigma_min_J3", "damping",  # the singularity guard of eq. u3
    "com_err_saturated", "y_err_saturated",  # whether an error saturation acted
    "u", "tau", "Lambda_y",  # u (eq. new_dynamics), tau = T^T u, Lambda_y (eq. u3)
)
_DIAGNOSTICS_OPTIONAL = (
    "Lambda_y_dot",  # with options.compensate_Lambda_y_dot
    "wrench_W_filtered",  # filtered [f; m] of F_e in W axes, moment about {e} [N, N m]
    "q_d",  # R_d as a unit quaternion (w, x, y, z), w >= 0
    "terms",  # StepTerms: the model and task terms the step evaluated (also as .decoupled and .task)
)


class _FromPacked:
    """A Diagnostics field that `step` reads from the compiled law's array when first asked
    for, then keeps (a non-data descriptor: the instance's own value shadows it)."""

    def __set_name__(self, owner, name):
        self.name = name

    def __get__(self, d, owner=None):
        if d is None:
            return self
        value = d._readers[self.name](d._packed)
        d.__dict__[self.name] = value
        return value


class Diagnostics:
    """What one control step evaluated, by name: the fields listed in FIELDS (the optional
    ones are None unless given). Built with keywords, `Diagnostics(r_c=..., ...)`, or by
    `step` from the one array the compiled law returns; each field is then a view of that
    array, formed when first read. Fields can be reassigned (amcore.offboard does)."""

    FIELDS = _DIAGNOSTICS_REQUIRED + _DIAGNOSTICS_OPTIONAL

    def __init__(self, **fields):
        unknown = fields.keys() - set(self.FIELDS)
        missing = set(_DIAGNOSTICS_REQUIRED) - fields.keys()
        if unknown or missing:
            raise TypeError(f"Diagnostics: unknown fields {sorted(unknown)}, missing fields {sorted(missing)}")
        self.__dict__.update(dict.fromkeys(_DIAGNOSTICS_OPTIONAL))
        self.__dict__.update(fields)

    @classmethod
    def from_packed(cls, packed: np.ndarray, n: int, **given) -> "Diagnostics":
        """The diagnostics of law.control_law's array (PACKED, task dimension n), with the
        fields it does not hold given by name."""
        d = object.__new__(cls)
        d.__dict__.update(given, _packed=packed, _readers=_readers(n))
        return d

    @property
    def packed(self) -> np.ndarray | None:
        """law.control_law's result the fields are read from (None: built with keywords)."""
        return self.__dict__.get("_packed")

    @property
    def decoupled(self) -> StepTerms | None:
        """The model terms the step evaluated (M_inv, T_inv, Lambda_w, Gamma_xi_xi): `terms`."""
        return self.terms

    @property
    def task(self) -> StepTerms | None:
        """The task terms the step evaluated (J_y, J_e_xi): `terms`."""
        return self.terms

    def __repr__(self) -> str:
        return "Diagnostics(" + ", ".join(f"{k}={getattr(self, k)!r}" for k in self.FIELDS) + ")"


for _name in ("r_c", "rdot_c", "r_c_err", "e_R", "e_w", "R_d", "q_d", "w_bd", "wdot_bd", "Omega_d", "f_d", "y",
              "y_err", "ydot", "F_y", "F_rc", "wrench_E_filtered", "wrench_W_filtered", "sigma_min_J3", "damping",
              "com_err_saturated", "y_err_saturated", "u", "tau", "Lambda_y", "terms"):
    setattr(Diagnostics, _name, _FromPacked())
    Diagnostics.__dict__[_name].__set_name__(Diagnostics, _name)


class StepResult(NamedTuple):
    command: Command
    diagnostics: Diagnostics
    memory: ControllerMemory


# What law.control_law returns, in order: (name, shape), with "n" the task dimension and
# "nv" = n + 6. Diagnostics' fields, the command and the memory are views of it.
PACKED = (
    ("tau", ("nv",)), ("r_c", (3,)), ("rdot_c", (3,)), ("r_c_err", (3,)), ("e_R", (3,)), ("e_w", (3,)),
    ("R_d", (3, 3)), ("q_d", (4,)), ("w_bd", (3,)), ("wdot_bd", (3,)), ("Omega_d", (3,)), ("f_d", (3,)),
    ("y", ("n",)), ("y_err", ("n",)), ("ydot", ("n",)), ("F_y", ("n",)),
    ("wrench_W_filtered", (6,)), ("wrench_E_filtered", (6,)),
    ("memory_x", (6,)), ("memory_xdot", (6,)),  # the filter's new state (its own copy, for ControllerMemory)
    ("u", ("nv",)), ("Lambda_y", ("n", "n")),
    ("guard", (4,)),  # sigma_min(Jbar_3), damping, CoM error saturated, task error saturated
    ("Lambda_w", (3, 3)), ("Gamma_xi_xi", ("nv",)), ("T_inv", ("nv", "nv")), ("M_inv", ("nv", "nv")),
    ("J_y", ("n", "nv")), ("J_e_xi", (6, "nv")),
)


@lru_cache(maxsize=None)
def packed_slices(n: int) -> dict[str, tuple[slice, tuple[int, ...]]]:
    """name -> (slice, shape) of PACKED for a task dimension n."""
    size = {"n": n, "nv": n + 6}
    out, at = {}, 0
    for name, shape in PACKED:
        shape = tuple(size.get(d, d) for d in shape)
        k = int(np.prod(shape))
        out[name] = (slice(at, at + k), shape)
        at += k
    return out


@lru_cache(maxsize=None)
def packed_offsets(n: int, names: tuple[str, ...]) -> np.ndarray:
    """The offsets in PACKED, for a task dimension n, of the fields `names` (a compiled law
    that reads them from the packed result: law.attitude_mode_torques_of_packed)."""
    at = packed_slices(n)
    offsets = np.array([at[name][0].start for name in names], dtype=np.int64)
    offsets.setflags(write=False)
    return offsets


def _view(sl: slice, shape: tuple[int, ...]):
    if len(shape) == 1:
        return lambda a: a[sl]
    return lambda a: a[sl].reshape(shape)


@lru_cache(maxsize=None)
def _readers(n: int) -> dict:
    """Diagnostics' fields read from the packed array, for a task dimension n."""
    at = packed_slices(n)
    r = {name: _view(*at[name]) for name in (
        "tau", "r_c", "rdot_c", "r_c_err", "e_R", "e_w", "R_d", "q_d", "w_bd", "wdot_bd", "Omega_d", "f_d", "y", "y_err",
        "ydot", "F_y", "wrench_W_filtered", "wrench_E_filtered", "u", "Lambda_y")}
    g = at["guard"][0].start
    f = at["wrench_W_filtered"][0].start
    terms = tuple(_view(*at[k]) for k in StepTerms._fields)  # in StepTerms' order
    r.update(
        F_rc=lambda a: a[f:f + 3],
        sigma_min_J3=lambda a: float(a[g]),
        damping=lambda a: float(a[g + 1]),
        com_err_saturated=lambda a: bool(a[g + 2]),
        y_err_saturated=lambda a: bool(a[g + 3]),
        terms=lambda a: StepTerms(*[view(a) for view in terms]),
    )
    return r


_NO_FILTER_STATE = np.zeros(0)
_ZERO3 = np.zeros(3)  # no axis: F_rc is the whole measured force (the paper's)


def pinocchio_terms(pm: pin.Model, data: pin.Data, fid: int, q_pin: np.ndarray, V: np.ndarray) -> tuple:
    """(Jcom, M^-1, C, H_WE, J_e, Jdot_e): the model terms `step` takes from pinocchio at
    (q_pin, V), {e} being frame `fid`, its Jacobians in {e} (LOCAL).

    computeCoriolisMatrix's pass also fills the joint placements, data.J and data.dJ; the CoM
    Jacobian R [I, -hat(r_b), J_b] is read from those placements (pinocchio's overload without
    q), which skips a forward-kinematics pass and gives the same numbers bit for bit
    (tests/amcore/test_control.py)."""
    M_inv = pin.computeMinverse(pm, data, q_pin)
    C = pin.computeCoriolisMatrix(pm, data, q_pin, V)
    Jcom = pin.jacobianCenterOfMass(pm, data, False)
    return (Jcom, M_inv, C, pin.updateFramePlacement(pm, data, fid).homogeneous,
            pin.getFrameJacobian(pm, data, fid, pin.LOCAL), pin.getFrameJacobianTimeVariation(pm, data, fid, pin.LOCAL))


def step(model: AmModel, data: pin.Data, params: ControllerParams, state: AmState,
         ref: Reference, wrench_E: np.ndarray, memory: ControllerMemory, t_s: float,
         task_frame: TaskFrame | None = None) -> StepResult:
    """One evaluation of eqs. Com_controller, Rd, ori_controller and u3 at time t_s [s].

    wrench_E: the wrench [f_e; tau_e] the environment applies on the end-effector,
    expressed in {e} (an F/T sensor's reading) [N, N m]. task_frame: this step's task frame
    if it moves (amcore.adapt turns it with the heading), else params.task_frame.

    Pinocchio computes M^-1, C, the CoM Jacobian and {e}'s placement and Jacobians; the
    compiled law.control_law does the rest.
    """
    p = params
    frame = p.task_frame if task_frame is None else task_frame
    pm, fid = model.pin_model, model.ee_frame_id
    q_pin, V = pin_configuration(state)
    Jcom, M_inv, C, H_WE, J_e, Jdot_e = pinocchio_terms(pm, data, fid, q_pin, V)

    dt = 0.0 if memory.t_s is None else t_s - memory.t_s
    filt = memory.wrench
    x0, xdot0 = (_NO_FILTER_STATE, _NO_FILTER_STATE) if filt is None else (filt.x, filt.xdot)
    wf = p.wrench_filter
    Lambda_y_dot, r_extra = None, p.zero_task
    if p.compensate_Lambda_y_dot:
        Lambda_y_dot, ydot = _Lambda_y_dot_and_ydot(model, data, state, frame, p.components)
        r_extra = 0.5 * Lambda_y_dot.dot(ydot - ref.y_d1)
    try:
        packed = law.control_law(
            model.mass_kg, model.gravity_mps2, state.R_WB, state.p_WB, state.w_B, V, Jcom, M_inv, C, H_WE, J_e,
            Jdot_e, frame.H_TW, p.axes, *ref,  # the reference: r_c .. r_c_d4, psi .. psi_d2, y .. y_d2
            wrench_E, x0, xdot0, wf.transition(max(dt, 0.0)), *p.law_constants, r_extra,
            _ZERO3 if p.compensate_along_face else frame.e_y_W, p.damping_dt)
    except ZeroDivisionError as e:
        raise np.linalg.LinAlgError(f"eq. u3: {e}") from None
    n = model.n
    at = packed_slices(n)
    tau = packed[at["tau"][0]].copy()  # the command does not share memory with the diagnostics
    diag = Diagnostics.from_packed(packed, n, r_c_d=ref.r_c, y_d=ref.y, R_WB=state.R_WB, Lambda_y_dot=Lambda_y_dot)
    # the named tuples built positionally (keywords cost more than the rest of these lines)
    memory = ControllerMemory(t_s, FilterState(packed[at["memory_x"][0]], packed[at["memory_xdot"][0]]))
    return StepResult(Command(float(tau[2]), tau[3:6], tau[6:]), diag, memory)


def _Lambda_y_dot_and_ydot(model: AmModel, data: pin.Data, state: AmState, frame: TaskFrame,
                           components) -> tuple[np.ndarray, np.ndarray]:
    """dLambda_y/dt = -Lambda_y (Jdot Lambda_xi^-1 J^T + (.)^T - J Lambda_xi^-1 Lambda_xi' Lambda_xi^-1 J^T)
    Lambda_y with Lambda_xi' = Gamma_xi + Gamma_xi^T, and ydot (numpy model terms, full=True)."""
    tm = decoupled_terms(model, data, state, full=True)
    tk = task_terms(model, data, tm, frame, components, full=True)
    Lambda_y = np.linalg.inv(tk.J_y @ tm.M_inv @ tk.J_y.T)
    LiJt = tm.Lambda_xi_inv @ tk.J.T
    inner = tk.Jdot @ LiJt + LiJt.T @ tk.Jdot.T - LiJt.T @ (tm.Gamma_xi + tm.Gamma_xi.T) @ LiJt
    return -Lambda_y @ inner @ Lambda_y, tk.ydot
