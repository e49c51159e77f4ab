"""Typed configuration: frozen dataclasses loaded from TOML.

Unknown keys, wrong types and impossible values raise `ConfigError` naming the file and
the key. Values that follow from others (total mass, hover thrust, the task frame of
each AM, the nominal CoM offset) are computed, never entered; see `amcore.mission`.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import os
import re
import tomllib
import types
import typing
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal

import msgspec
from msgspec import Meta

from .allocation import Allocation
from .rotors import Rotor, RotorParams, table_problem


# Declarations beside the fields (msgspec validates them, amcore.config_schema writes them as a JSON
# Schema): a range as Annotated[float, Meta(...)], an enum as Literal[...]; a unit ends a description
Positive = Annotated[float, Meta(gt=0.0)]
NonNegative = Annotated[float, Meta(ge=0.0)]
Probability = Annotated[float, Meta(ge=0.0, le=1.0)]


class ConfigError(ValueError):
    """A configuration file is malformed; the message names the file and the key."""


class ConfigWarning(UserWarning):
    """A configuration loads but may not do what its author meant; the message names the file and the key."""


_format_warning = warnings.formatwarning


def _config_warning_format(message, category, filename, lineno, line=None):
    """A ConfigWarning reads as one line, `warning: <file>: <key>: <reason>` (not the loader's
    source line: the user's file is the place to look)."""
    if isinstance(category, type) and issubclass(category, ConfigWarning):
        return f"warning: {message}\n"
    return _format_warning(message, category, filename, lineno, line)


warnings.formatwarning = _config_warning_format


# the scenario every process main runs when none is given: the paper's two-AM grasp through the
# design card's interface (attitude-thrust setpoints at 250 Hz to an emulated PX4); the paper's
# idealized torque interface is configs/scenarios/two_am_comp.toml
def _configs_dir() -> Path:
    """The shipped configs/: a source tree's own (a clone, an editable install), else the copy a
    wheel carries inside amcore (`pip install .`; build_backend/amstack_build.py puts it there)."""
    here = Path(__file__).resolve().parent
    tree = here.parent / "configs"
    return tree if (here.parent / "pyproject.toml").is_file() and tree.is_dir() else here / "configs"


CONFIGS_DIR = _configs_dir()
SCENARIOS_DIR = CONFIGS_DIR / "scenarios"
DEFAULT_SCENARIO = SCENARIOS_DIR / "two_am_comp_attitude.toml"


# ----------------------------------------------------------------------------- vehicle
TaskComponent = Literal["x", "y", "z", "roll", "pitch", "yaw"]


@dataclass(frozen=True)
class TaskSpec:
    """Components of the task variable y, in the AM's task frame (eq. jacobian_xi).

    Position components: "x", "y", "z". Angle components: "roll", "pitch", "yaw", the
    planar angle of the end-effector about that task axis (see `amcore.task`).
    """

    components: tuple[TaskComponent, ...]


# The grasp mission (amcore.mission.am_mission) approaches and squeezes along the task's x (towards
# the object) and lifts along its z; every other component holds its nominal value.
GRASP_COMPONENTS = ("x", "z")


@dataclass(frozen=True)
class Gains:
    """Gains of eq. Com_controller, eq. ori_controller and eq. u3 (diagonal entries).

    K_t [N/m], D_t [N s/m]; k_R [N m / rad-ish], k_w [N m s]; Lambda_wb_d [kg m^2] is the
    desired rotational inertia of eq. ori_controller; K_y, D_y are per task component.
    """

    K_t: tuple[Positive, Positive, Positive]
    D_t: tuple[Positive, Positive, Positive]
    k_R: Positive
    k_w: Positive
    Lambda_wb_d: tuple[Positive, Positive, Positive]
    K_y: tuple[Positive, ...]
    D_y: tuple[Positive, ...]


@dataclass(frozen=True)
class Safety:
    """Guards beyond the paper against the arm's singularity (see `amcore.control`).

    - com_err_max_m: the CoM error entering the PD term is saturated at this norm.
    - y_err_max: per task component, |y~| entering the spring is saturated (the spring
      becomes the gradient of a convex, Huber-like potential, so passivity is kept).
    - sigma_damping: below this smallest singular value of Jbar_3 the inverse in eq. u3
      becomes a damped least-squares inverse with damping up to damping_max.
    - failsafe_joint_damping: per arm joint [N m s/rad], the flight controller's failsafe
      (simulator.failsafe) damps the limp arm with it; empty: derived from the arm
      (simulator.failsafe.joint_damping).
    """

    com_err_max_m: Annotated[float, Meta(gt=0.0, description="saturation of the CoM error [m]")] = 0.5
    y_err_max: tuple[Positive, ...] = ()
    sigma_damping: Positive = 0.02
    damping_max: Positive = 0.05
    failsafe_joint_damping: tuple[Annotated[float, Meta(gt=0.0, description="[N m s/rad]")], ...] = ()


Controller = Literal["passivity", "baseline"]  # amcore.control (the paper's law), amcore.baseline
CONTROLLERS = typing.get_args(Controller)
BASELINE_COMPONENTS = ("x", "z", "pitch")  # amcore.baseline's inverse kinematics: the arm's plane in {b}
BaselineArm = Literal["joint", "cartesian"]  # [baseline].arm: joint PD on the IK's q_d, or impedance at the pad
BASELINE_ARMS = typing.get_args(BaselineArm)


@dataclass(frozen=True)
class BaselineGains:
    """[baseline] table: gains of the baseline controller (`amcore.baseline`), diagonal entries.

    Base, geometric SE(3) tracking (Lee, Leok and McClamroch, CDC 2010) with an integral term:
    k_x [N/m], k_v [N s/m], k_i [N/(m s)] on the base position error in {w}; the integral's
    force k_i * int(e_x) is clamped per axis at integral_limit_n [N] (anti-windup). Attitude:
    k_R [N m/rad], k_w [N m s/rad] per body axis. Arm, joint-space PD with gravity
    compensation: K_q [N m/rad], D_q [N m s/rad] per joint. The inverse kinematics behind
    q_d runs up to ik_iterations damped Newton steps per control step, damping ik_damping
    [rad-equivalent, squared into the normal equations].
    """

    k_x: tuple[Positive, Positive, Positive]
    k_v: tuple[Positive, Positive, Positive]
    k_i: tuple[NonNegative, NonNegative, NonNegative]  # 0: no integral
    integral_limit_n: tuple[Positive, Positive, Positive]
    k_R: tuple[Positive, Positive, Positive]
    k_w: tuple[Positive, Positive, Positive]
    k_iR: tuple[NonNegative, NonNegative, NonNegative]  # 0: no integral
    attitude_integral_limit_nm: tuple[Positive, Positive, Positive]
    K_q: tuple[Positive, ...]
    D_q: tuple[Positive, ...]
    ik_iterations: Annotated[int, Meta(ge=1)]
    ik_damping: NonNegative
    # Two additions a practitioner makes next (docs/baseline.md, "On the canted hexarotor"); the
    # defaults are the first write-up's law. arm: "joint", the joint PD above on the IK's q_d;
    # "cartesian", an impedance at the pad through the arm's Jacobian, tau_q = J^T (K_y e - D_y edot)
    # + g_q, e the pad's (x, z, pitch) error in the task frame from the measured state, K_y
    # [N/m, N/m, N m/rad] and D_y [N s/m, N s/m, N m s/rad] (needed only then).
    arm: BaselineArm = "joint"
    K_y: tuple[Positive, ...] = ()
    D_y: tuple[Positive, ...] = ()
    # true (arm = "cartesian" only): the base feeds forward the reaction of the pad wrench the arm
    # commanded at the last step (its spring part), force in F_d and moment about the base origin
    # in M: the squeeze's reaction and the load's share then need no integral to build up.
    reaction_feedforward: bool = False


OffboardInputs = Literal["sent", "reported"]  # [options].offboard_inputs
OFFBOARD_INPUTS = typing.get_args(OffboardInputs)
# [options].offboard_latency_s at most [s]: half of PX4's default COM_OF_LOSS_T (1 s), after which the
# autopilot leaves offboard; a longer delay is a lost link, not one to predict over
OFFBOARD_LATENCY_MAX_S = 0.5


@dataclass(frozen=True)
class ControllerOptions:
    controller: Controller = "passivity"  # which law flies the AM
    force_compensation: bool = True
    compensate_Lambda_y_dot: bool = False
    # cutoff of the 2nd-order low-pass on the measured wrench (why: am3dof.toml)
    force_filter_hz: Annotated[float, Meta(gt=0.0, description="cutoff of the wrench's low-pass [Hz]")] = 3.0
    force_filter_zeta: Positive = 1.0
    # Feed the filtered wrench's rates into f_d's derivatives (hence Omega_d, Omegadot_d).
    # Off by default: a real wrist sensor also measures the tool's inertial force, and the
    # filter's second derivative passes the raw reading straight through (gain w^2), which
    # closes a one-step loop sensor -> Omega_d -> body torque -> tool acceleration -> sensor
    # that PyBullet shows diverging at 2 steps per period. Off treats F_e as slowly varying.
    force_rate_feedforward: bool = False
    # Beyond the paper: false leaves the measured force's component along the face (the task
    # frame's y axis) out of F_rc in eq. Com_controller. Compensated, a sideways push between
    # two AMs that disagree on the object is cancelled by each, so nothing limits it but the
    # pads' grip; uncompensated it is met by K_t alone (docs/sensing.md). True: the paper's.
    compensate_along_face: bool = True
    # Beyond the paper (amcore.adapt): the heading follows the misalignment the wrist sensor
    # measures on a crowned pad, with this natural frequency [Hz]; 0: off (the paper's fixed heading).
    heading_admittance_hz: Annotated[float, Meta(ge=0.0, description="0: off [Hz]")] = 0.0
    heading_admittance_zeta: Positive = 1.0
    # Beyond the paper (amcore.adapt.LateralAdmittance): in contact, the CoM reference gives
    # way along the face to the lateral force the wrist sensor measures, with this natural
    # frequency [Hz]; 0: off (the paper's CoM reference).
    lateral_admittance_hz: Annotated[float, Meta(ge=0.0, description="0: off [Hz]")] = 0.0
    lateral_admittance_zeta: Positive = 1.0
    # Beyond the paper (amcore.adapt.Trim): in the approach's hover the CoM reference moves to
    # cancel a steady horizontal force (a tilted thrust), at this bandwidth [Hz]; held from the grasp on. 0: off.
    trim_hz: Annotated[float, Meta(ge=0.0, description="0: off [Hz]")] = 0.0
    # The next three keys sample the law for the interface: their defaults depend on
    # [flight_controller].mode (MODE_OPTION_DEFAULTS, applied by the loader to the keys the
    # vehicle and scenario files leave unset). Attitude mode: "reported", 40.0, true, what a
    # stock autopilot's link needs (docs/flight_controller.md, "A lossy link"). Torque mode, and
    # the values below: the law as first written; a scenario writes them to fly that in attitude mode.
    #
    # Attitude mode only (amcore.offboard): where the arm law's body-torque estimate takes the
    # last period's thrust and joint torques from. "sent": what the companion sent (the law
    # as first written); "reported": what the autopilot reports it flies (ATTITUDE_TARGET's
    # thrust) and what the servos measured (AM_JOINT_STATE's effort), right when a setpoint
    # was lost on the link.
    offboard_inputs: OffboardInputs = "sent"
    # Attitude mode only: bandwidth [Hz] of the body-torque estimate. 0: the gyro's backward
    # difference over one control period (as first written); > 0: that estimate through a
    # 2nd-order Butterworth low-pass at this cutoff (amcore.offboard); attitude mode's 40 Hz is
    # PX4's IMU_GYRO_CUTOFF default, not tuned.
    offboard_torque_cutoff_hz: Annotated[float, Meta(ge=0.0, description="0: backward difference [Hz]")] = 0.0
    # Beyond the paper (amcore.law.discrete_damping): eq. u3's task damping D_y as the damping
    # that, held over one control period, does what the continuous damper does in that time.
    # A mode with little task inertia (the pad's pitch, Lambda_y ~2.4e-4) and Lambda_y^-1 D_y dt
    # near 2 rings at half the control rate; a setpoint lost on the link (held two periods)
    # then makes it grow. false: D_y as the paper writes it (torque mode's default: its
    # scenarios run the companions at 1 kHz, where they hold; docs/flight_controller.md).
    discrete_damping: bool = False
    # Attitude mode only, beyond the paper (amcore.offboard): the link's one-way latency [s] from
    # a setpoint leaving the companion to the vehicle acting on it, as measured on that link; > 0:
    # eq. u3 acts on the task error predicted that far ahead from the commands in flight (a
    # Smith predictor). 0: off (the measured error).
    offboard_latency_s: Annotated[float, Meta(ge=0.0, le=OFFBOARD_LATENCY_MAX_S,
                                              description="0: no prediction [s]")] = 0.0


@dataclass(frozen=True)
class PadSpec:
    """[pad] table: the contact face of the end-effector's pad, as the simulator builds it
    (the controller never uses it).

    - shape "flat": the URDF's collision box, rigid; any angle between pad and face puts
      the contact on the pad's edge. "crowned": the face is a vertical cylinder of radius
      crown_radius_m through the face centre (rounded about the pad's z axis, straight along
      it), so a pad that meets the face at an angle rolls on it instead of standing on an edge.
    - contact_stiffness_n_per_m, contact_damping_n_s_per_m: a compliant facing (Bullet's
      soft contact on the pad); both 0: rigid.
    """

    shape: Literal["flat", "crowned"] = "flat"
    crown_radius_m: Annotated[float, Meta(gt=0.0, description="[m]")] = 0.1
    contact_stiffness_n_per_m: Annotated[float, Meta(ge=0.0, description="0: rigid [N/m]")] = 0.0
    contact_damping_n_s_per_m: Annotated[float, Meta(ge=0.0, description="0: rigid [N s/m]")] = 0.0
    # rolling resistance of the facing [m]: the moment resisting rolling (the object turning
    # between crowned pads) is at most this times the normal force (Bullet's rollingFriction)
    rolling_friction_m: Annotated[float, Meta(ge=0.0, description="[m]")] = 0.0


FcMode = Literal["torque", "attitude"]
FC_MODES = typing.get_args(FcMode)


@dataclass(frozen=True)
class FlightControllerParams:
    """[flight_controller]: what the companion's setpoints command (docs/flight_controller.md).

    - mode = "torque": the companion sends thrust, body torque and joint torques
      (AM_TORQUE_SETPOINT) and the flight controller mixes them as they are.
    - mode = "attitude": the companion sends what a stock autopilot takes in offboard mode,
      SET_ATTITUDE_TARGET (attitude, body-rate feed-forward, thrust normalized to [0, 1]),
      and the joint torques in their own message (AM_JOINT_TORQUE_SETPOINT); the emulated
      autopilot (`simulator.flight_controller`) closes attitude and rate loops at `rate_hz`.
      body_rate_feedforward: add the target's body rates to the rate setpoint (false: the
      attitude P loop alone makes it).
    - failsafe_after_rejected: K. A setpoint the flight controller refuses as implausible
      (non-finite, or beyond `amlink.types` of this vehicle) is answered at once: the flight
      controller keeps flying the last valid command and counts the refusal. After K refused
      setpoints in a row from one companion, that vehicle goes to its failsafe (hold, then
      land; `simulator.failsafe`) for the rest of the run: its companion's setpoints are
      ignored from then on. Both modes; the simulator's --failsafe-after-rejected overrides it.
    - actuation_delay_steps: d, physics steps between a control step's frames and the
      moment their answers act. 0 (default): the answer to the frames of step k acts from
      step k, as soon as it arrives (the lockstep waits for it). 1 <= d <= the control
      period in physics steps: it acts from step k + d, a flight controller whose link and
      scheduling add that latency; the simulator steps those d physics steps while the
      companions compute, so a lockstep on few cores runs faster (docs/flight_controller.md,
      "Actuation delay"). The first setpoint of a run acts at once, so that no vehicle
      starts unpowered. Both modes.

    The upper-case keys are PX4 parameters under their PX4 names and in PX4's units (rad/s
    per rad, normalized torque per rad/s, deg/s, Hz). They act in attitude mode only. The
    loader sets each one a vehicle file leaves out by amcore.px4_gains' rule for that vehicle
    (COM_OF_LOSS_T: PX4's default); the defaults below are PX4's, for this class built directly.
    """

    mode: FcMode = "torque"
    rate_hz: Annotated[float, Meta(gt=0.0, description="the autopilot's loops [Hz]")] = 1000.0
    body_rate_feedforward: bool = True
    failsafe_after_rejected: Annotated[int, Meta(ge=1)] = 10  # K refused setpoints in a row -> failsafe [control periods]
    actuation_delay_steps: Annotated[int, Meta(ge=0)] = 0  # d: a setpoint acts d physics steps after its frame (0: on arrival)
    MC_ROLL_P: Positive = 6.5
    MC_PITCH_P: Positive = 6.5
    MC_YAW_P: Positive = 2.8
    MC_YAW_WEIGHT: Probability = 0.4
    MC_ROLLRATE_MAX: Positive = 220.0
    MC_PITCHRATE_MAX: Positive = 220.0
    MC_YAWRATE_MAX: Positive = 200.0
    MC_ROLLRATE_P: NonNegative = 0.15
    MC_ROLLRATE_I: NonNegative = 0.2
    MC_ROLLRATE_D: NonNegative = 0.003
    MC_ROLLRATE_FF: NonNegative = 0.0
    MC_ROLLRATE_K: NonNegative = 1.0
    MC_RR_INT_LIM: NonNegative = 0.30
    MC_PITCHRATE_P: NonNegative = 0.15
    MC_PITCHRATE_I: NonNegative = 0.2
    MC_PITCHRATE_D: NonNegative = 0.003
    MC_PITCHRATE_FF: NonNegative = 0.0
    MC_PITCHRATE_K: NonNegative = 1.0
    MC_PR_INT_LIM: NonNegative = 0.30
    MC_YAWRATE_P: NonNegative = 0.2
    MC_YAWRATE_I: NonNegative = 0.1
    MC_YAWRATE_D: NonNegative = 0.0
    MC_YAWRATE_FF: NonNegative = 0.0
    MC_YAWRATE_K: NonNegative = 1.0
    MC_YR_INT_LIM: NonNegative = 0.30
    IMU_GYRO_CUTOFF: NonNegative = 40.0  # low-pass on the gyro the rate loop uses [Hz]; 0: none
    IMU_DGYRO_CUTOFF: NonNegative = 20.0  # low-pass on the angular acceleration of the D term [Hz]; 0: none
    # offboard loss: no setpoint for this long [s] and the autopilot leaves offboard for its
    # failsafe (hold, then land; PX4 v1.14 COM_OF_LOSS_T, default 1.0 s, action COM_OBL_RC_ACT)
    COM_OF_LOSS_T: Positive = 1.0


# [options] defaults that follow [flight_controller].mode (see ControllerOptions): a key the
# vehicle or scenario file sets wins; a mode not listed takes ControllerOptions' own defaults.
MODE_OPTION_DEFAULTS: dict[str, dict[str, object]] = {
    "attitude": {"offboard_inputs": "reported", "offboard_torque_cutoff_hz": 40.0, "discrete_damping": True},
}


@dataclass(frozen=True)
class VehicleParams:
    name: str
    urdf: Path
    base_link: str
    ee_frame: str
    ft_frame: str
    arm_joints: tuple[str, ...]
    q_nominal_rad: tuple[float, ...]
    joint_torque_max_nm: tuple[Annotated[float, Meta(gt=0.0, description="[N m]")], ...]
    rotors: RotorParams
    task: TaskSpec
    gains: Gains
    safety: Safety = Safety()
    options: ControllerOptions = ControllerOptions()
    pad: PadSpec = PadSpec()
    flight_controller: FlightControllerParams = FlightControllerParams()
    baseline: BaselineGains | None = None  # needed when options.controller = "baseline"
    gravity_mps2: Annotated[float, Meta(ge=0.1, le=100.0, description="[m/s^2]")] = 9.81

    @property
    def n_joints(self) -> int:
        return len(self.arm_joints)


# ----------------------------------------------------------------------------- scenario
@dataclass(frozen=True)
class ObjectSpec:
    shape: Literal["box", "cylinder"]
    mass_kg: Annotated[float, Meta(ge=OBJECT_MASS_RANGE_KG[0], le=OBJECT_MASS_RANGE_KG[1], description="the object's true mass [kg]")]
    position_m: tuple[float, float, float]  # centre at rest, world frame
    size_m: tuple[float, float, float] = (0.2, 0.2, 0.2)  # box edge lengths
    radius_m: float = 0.0  # cylinder
    height_m: float = 0.0  # cylinder
    lateral_friction: Positive = 1.0  # the object's own coefficient (Bullet multiplies a pair's two)
    # Coulomb coefficient of the pad-object pair itself. Bullet combines two bodies'
    # coefficients by multiplication, so the simulator sets the pad's own coefficient to
    # pad_friction / lateral_friction. 0: unset, the pad takes lateral_friction (the pair
    # then has lateral_friction ** 2).
    pad_friction: NonNegative = 0.0
    yaw_deg: Annotated[float, Meta(ge=-360.0, le=360.0, description="[deg]")] = 0.0  # the object's turn about the world's z axis at rest (a box's faces turn with it)

    @property
    def pad_object_friction(self) -> float:
        """Coulomb coefficient of the pad-object contact as the simulator sets it."""
        return self.pad_friction if self.pad_friction > 0.0 else self.lateral_friction ** 2

    @property
    def half_height_m(self) -> float:
        return 0.5 * (self.size_m[2] if self.shape == "box" else self.height_m)


@dataclass(frozen=True)
class MissionSpec:
    """Phase timing and geometry of the grasp, shared by all AMs (paper Sec. V).

    Times are simulation seconds. Distances are along each AM's own task x axis
    (pointing from the AM to the object centre) or vertical.
    """

    approach_end_s: float = 5.0
    grasp_end_s: float = 10.0
    hover_end_s: float = 20.0
    approach_move_s: Annotated[float, Meta(gt=0.0, description="[s]")] = 4.0  # approach motion takes this long, then holds
    grasp_move_s: Annotated[float, Meta(gt=0.0, description="[s]")] = 2.0
    lift_move_s: Annotated[float, Meta(gt=0.0, description="[s]")] = 4.0
    standoff_m: Annotated[float, Meta(ge=0.0, le=MISSION_DISTANCE_MAX_M, description="[m]")] = 0.25  # start: end-effector this far outside the surface
    start_height_m: Annotated[float, Meta(ge=0.0, le=MISSION_DISTANCE_MAX_M, description="[m]")] = 0.2  # start: end-effector this far above grasp height
    pre_gap_m: Annotated[float, Meta(ge=0.0, le=MISSION_DISTANCE_MAX_M, description="[m]")] = 0.02  # end of approach: pad this far from the surface
    squeeze_m: NonNegative = 0.04  # grasp: y_x,d this deep inside the object
    # Squeeze sizing (off: the fixed squeeze_m). On, each AM squeezes with the normal force
    # that holds its share of the planned object ([object].mass_kg) at the friction the
    # mission assumes, times a margin, within what its rotors can push (amcore.mission.squeeze_force):
    #     N = friction_margin * m_obj g / (n_AM * friction_assumed),  never below K_y,x squeeze_m
    squeeze_sizing: bool = False
    friction_assumed: Positive = 0.5  # the lowest pad-object friction coefficient planned for
    friction_margin: Positive = 1.5
    thrust_fraction_max: Annotated[float, Meta(gt=0.0, le=1.0)] = 0.8  # of the rotors' total maximum, for weight, load share and squeeze
    # the most normal force the AM may push with [N] (inf: only thrust_fraction_max bounds it): the
    # squeeze's and the load's moment on the base must leave its pitch authority room to fly
    squeeze_max_n: Positive = math.inf
    lift_m: Annotated[float, Meta(gt=0.0, le=MISSION_DISTANCE_MAX_M, description="[m]")] = 0.3
    join_blend_s: Annotated[float, Meta(gt=0.0, description="[s]")] = 3.0  # a companion started mid-run (a restart) blends into the references over this
    # a companion started mid-run whose wrist sensor reads a push resumes it (amcore.mission.join_blend);
    # false: it starts from zero squeeze and, restarted in the hover, lets the object fall
    resume_contact_force: bool = True
    # Touch, align, squeeze (0: off, the paper's one move to the squeeze): the grasp move first
    # presses with touch_force_n only (through K_y,x), holds it touch_hold_s while the heading
    # admittance turns the AM to the face, then moves on to the squeeze; both moves take
    # grasp_move_s. A pad pushing at an angle delta puts N sin(delta) sideways on the pad,
    # ~0.3 m ahead of the CoM: at 12 N and 5 deg that is 0.3 N m of yaw, this vehicle's whole
    # yaw authority (docs/robust_grasp.md).
    touch_force_n: NonNegative = 0.0
    touch_hold_s: NonNegative = 0.0
    # What the team knows of the object's mass (beyond the paper): the planned mass (0: the object's
    # [object].mass_kg, exactly) and how well it is known: the planned mass is within +/-mass_tolerance
    # of the true one, so the true mass is at most planned_mass_kg / (1 - mass_tolerance), the mass the
    # squeeze sizing and the envelope check plan for (`design_mass_kg`).
    planned_mass_kg: float = 0.0
    mass_tolerance: Annotated[float, Meta(ge=0.0, le=MASS_TOLERANCE_MAX, description="a fraction of the planned mass")] = 0.0
    # Pre-flight envelope check (amcore.preflight): a team asked to hold what it cannot (the squeeze the
    # design mass needs at friction_assumed with friction_margin, against what each AM pushes with its
    # margins kept) refuses before anything flies: exit 2, naming the limit and the smallest team.
    envelope_check: bool = False
    # Where each AM takes the object's pose from to plan its approach (amcore.mission.am_mission):
    # "config", [object].position_m and yaw_deg as written; "mocap", the motion capture's measurement of
    # the object before flight (simulator.object_mocap: [devices.mocap]'s noise and biases when
    # [devices] is on, exact otherwise), one measurement shared by the team. With "mocap", or a box
    # turned by a yaw, each AM approaches the face whose normal is nearest its azimuth.
    object_pose: ObjectPose = "config"


LinkJoints = Literal["servo_bus", "link"]  # [link].joints
LINK_JOINT_PATHS = typing.get_args(LinkJoints)


@dataclass(frozen=True)
class LinkSpec:
    """[link] table: the simulator <-> companion link (see `amlink.signing`, `amlink.impair`).

    - signing: MAVLink 2 signing of all lockstep traffic (default on). Keys, first match:
      [[am]].signing_key_hex; else derived from key_file (64 hex digits, path relative to
      the scenario); else a PUBLIC development key (integrity and anti-replay only).
    - loss, delay_s, jitter_s, reorder, duplicate: impairment of the companion -> flight
      controller path in simulation time (`amlink.impair.LinkImpairment`); all 0 = ideal.
    - joints: the path the arm's joint torques take. "servo_bus" (default): the companion's
      own servo bus, as on an AM whose arm hangs off the companion (Dynamixel over USB), so
      the impairment above delays and drops only the flight controller's setpoints; "link":
      the joint torques travel with them and share their loss and delay (an arm driven
      through the flight controller).
    """

    signing: bool = True
    key_file: str = ""
    loss: Probability = 0.0
    delay_s: Annotated[float, Meta(ge=0.0, description="[s]")] = 0.0
    jitter_s: Annotated[float, Meta(ge=0.0, description="[s]")] = 0.0
    reorder: Probability = 0.0
    duplicate: Probability = 0.0
    joints: LinkJoints = "servo_bus"

    def key_path(self, scenario_path: Path | None) -> Path | None:
        if not self.key_file:
            return None
        base = scenario_path.parent if scenario_path is not None else Path.cwd()
        return (base / self.key_file).resolve()


@dataclass(frozen=True)
class AmSpec:
    """One [[am]] entry.

    - azimuth_deg: direction from the object centre to the AM, about world z.
    - misalignment_deg: the AM's error in the object's face direction: it approaches, faces
      and squeezes along azimuth_deg + 180 + misalignment_deg about the object centre, so
      its flat pad meets the face at that angle. Part of its mission, unknown to the law.
    - start_offset_m, start_heading_deg: the vehicle starts this far from where its mission
      starts (world axes) and turned by this much about z; its references do not move.
    """

    sysid: Annotated[int, Meta(ge=2, le=255, description="MAVLink system id; 1 is the simulator")]
    azimuth_deg: float
    signing_key_hex: str = ""  # 64 hex digits; empty: see LinkSpec
    misalignment_deg: Annotated[float, Meta(gt=-45.0, lt=45.0, description="[deg]")] = 0.0
    start_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_heading_deg: float = 0.0
    # this AM's link impairment: [link] with this [[am]]'s `link = {loss = ..., ...}` on top
    link: LinkSpec | None = None


@dataclass(frozen=True)
class SensorSpec:
    """[sensors] table: how the flight controller's sensor frames differ from the truth.

    All zero (the default, and the paper's scenarios): exact frames. Noise entries are the
    standard deviation of white Gaussian noise on every frame, per axis; bias entries the
    standard deviation of a constant offset per axis, drawn once per AM from the scenario's
    seed. Odometry: position p_WB [m], attitude (a rotation vector applied to R_WB) [rad],
    linear velocity v_B [m/s], angular velocity w_B [rad/s]; wrist F/T: force [N], torque
    [N m] in the sensor's frame E. latency_s: every frame's measured values are this old
    (rounded to whole physics steps). Defaults with their sources: configs/randomize/default.toml.
    """

    position_noise_m: NonNegative = 0.0
    position_bias_m: NonNegative = 0.0
    attitude_noise_rad: NonNegative = 0.0
    attitude_bias_rad: NonNegative = 0.0
    velocity_noise_mps: NonNegative = 0.0
    velocity_bias_mps: NonNegative = 0.0
    angular_velocity_noise_radps: NonNegative = 0.0
    angular_velocity_bias_radps: NonNegative = 0.0
    force_noise_n: NonNegative = 0.0
    force_bias_n: NonNegative = 0.0
    torque_noise_nm: NonNegative = 0.0
    torque_bias_nm: NonNegative = 0.0
    latency_s: NonNegative = 0.0

    @property
    def exact(self) -> bool:
        return all(getattr(self, f.name) == 0.0 for f in dataclasses.fields(self))


@dataclass(frozen=True)
class ImuSpec:
    """[devices.imu]: the flight controller's IMU, sampled every physics step, with the
    parameters of PX4's Gazebo IMU plugin (gazebo_imu_plugin, after Nikolic's Kalibr noise
    model): white noise of density *_noise_density, a bias that is a first-order Gauss-Markov
    process of correlation time *_bias_correlation_time_s driven by *_random_walk, started at
    a turn-on bias drawn once with standard deviation *_turn_on_bias_sigma. Gyroscope in
    rad/s/sqrt(Hz), rad/s^2/sqrt(Hz), s, rad/s; accelerometer (specific force, body frame)
    in m/s^2/sqrt(Hz), m/s^3/sqrt(Hz), s, m/s^2. Values and sources:
    configs/randomize/default.toml."""

    gyroscope_noise_density: NonNegative = 0.0
    gyroscope_random_walk: NonNegative = 0.0
    gyroscope_bias_correlation_time_s: NonNegative = 1000.0
    gyroscope_turn_on_bias_sigma: NonNegative = 0.0
    accelerometer_noise_density: NonNegative = 0.0
    accelerometer_random_walk: NonNegative = 0.0
    accelerometer_bias_correlation_time_s: NonNegative = 300.0
    accelerometer_turn_on_bias_sigma: NonNegative = 0.0


@dataclass(frozen=True)
class MocapSpec:
    """[devices.mocap]: motion capture of the base pose. A frame every 1 / rate_hz s (a whole
    number of physics steps), latency_s old when it arrives (whole physics steps), with white
    noise per frame (position [m], attitude as a body-side rotation vector [rad]), a fixed
    body-frame attitude bias and a fixed position bias drawn once per AM (standard
    deviations), and each frame lost with probability drop_probability."""

    rate_hz: Annotated[float, Meta(ge=1.0, le=1000.0, description="[Hz]")] = 100.0
    latency_s: NonNegative = 0.0
    position_noise_m: NonNegative = 0.0
    attitude_noise_rad: NonNegative = 0.0
    position_bias_m: NonNegative = 0.0
    attitude_bias_rad: NonNegative = 0.0
    drop_probability: Annotated[float, Meta(ge=0.0, lt=1.0)] = 0.0


@dataclass(frozen=True)
class ForceTorqueSpec:
    """[devices.ft]: the wrist F/T sensor. White noise per sample (force [N], torque [N m]),
    an offset at power-on (standard deviation per axis) that drifts as a random walk
    (*_drift per sqrt(s)), and a tare (the driver's bias command) at tare_at_s: the mean of
    the readings over the tare_window_s before it is subtracted from then on (tare_at_s < 0:
    never tared)."""

    force_noise_n: NonNegative = 0.0
    torque_noise_nm: NonNegative = 0.0
    force_offset_n: NonNegative = 0.0
    torque_offset_nm: NonNegative = 0.0
    force_drift_n_per_sqrt_s: NonNegative = 0.0
    torque_drift_nm_per_sqrt_s: NonNegative = 0.0
    tare_at_s: float = -1.0
    tare_window_s: Annotated[float, Meta(gt=0.0, description="[s]")] = 0.2


@dataclass(frozen=True)
class EncoderSpec:
    """[devices.encoders]: the arm's joint encoders: position quantized to counts_per_rev
    counts per revolution (0: exact), velocity as the servo reports it, quantized to
    velocity_quantum_radps (0: exact)."""

    counts_per_rev: Annotated[int, Meta(ge=0)] = 0
    velocity_quantum_radps: NonNegative = 0.0


@dataclass(frozen=True)
class JointEffortSpec:
    """[devices.effort]: the joint torques the arm's servos report (AM_JOINT_STATE.effort_nm),
    as a Dynamixel-class servo reports its present current times its torque constant: a
    first-order lag of lag_s [s] behind the applied torque, white noise of noise_nm [N m] per
    sample and quantization to resolution_nm [N m] (one current unit; 0: exact)."""

    lag_s: NonNegative = 0.0
    noise_nm: NonNegative = 0.0
    resolution_nm: NonNegative = 0.0


@dataclass(frozen=True)
class EstimatorSpec:
    """[devices.estimator]: the flight controller's state estimator (amcore.estimator):
    bandwidths [rad/s] of its attitude and position loops, the gyro low-pass cutoff of its
    body-rate output (PX4's IMU_GYRO_CUTOFF, Hz; 0: none), and its history length
    (physics steps; at least the motion capture's latency)."""

    attitude_bandwidth_radps: Annotated[float, Meta(gt=0.0, description="[rad/s]")] = 4.0
    position_bandwidth_radps: Annotated[float, Meta(gt=0.0, description="[rad/s]")] = 8.0
    gyro_cutoff_hz: Annotated[float, Meta(ge=0.0, description="0: none [Hz]")] = 0.0
    history_steps: Annotated[int, Meta(ge=1, description="[physics steps]")] = 64


@dataclass(frozen=True)
class DevicesSpec:
    """[devices] table: sensors as devices produce them (simulator.devices) and the flight
    controller's estimator between them and the sensor frames (amcore.estimator). Off by
    default: the frames are then exact, or follow [sensors] (white noise on the states, kept
    as a stress option). scale multiplies every noise, random walk, bias, offset and drift."""

    enabled: bool = False
    scale: NonNegative = 1.0
    imu: ImuSpec = ImuSpec()
    mocap: MocapSpec = MocapSpec()
    ft: ForceTorqueSpec = ForceTorqueSpec()
    encoders: EncoderSpec = EncoderSpec()
    estimator: EstimatorSpec = EstimatorSpec()
    effort: JointEffortSpec = JointEffortSpec()


def devices_from_table(table: dict, where: str) -> DevicesSpec:
    """A [devices] table as a DevicesSpec; errors name `where` and the key."""
    parts = {"imu": ImuSpec, "mocap": MocapSpec, "ft": ForceTorqueSpec, "encoders": EncoderSpec,
             "estimator": EstimatorSpec, "effort": JointEffortSpec}
    kw = _build(DevicesSpec, {k: v for k, v in table.items() if k not in parts}, f"{where}: [devices]",
                skip=tuple(parts))
    for name, cls in parts.items():
        sub = table.get(name, {})
        if not isinstance(sub, dict):
            raise ConfigError(f"{where}: [devices.{name}] must be a table")
        kw[name] = cls(**_build(cls, sub, f"{where}: [devices.{name}]"))
    return DevicesSpec(**kw)


@dataclass(frozen=True)
class SuccessCriteria:
    """[success] table: what a successful mission is, judged from the simulator's ground
    truth (`simulator.verdict`). The mission fails on the first criterion it misses:

    - a base (multirotor body) touches anything, or a base leaves the arena (farther than
      max_distance_m from the object's rest position) or the state turns non-finite;
    - the object is not at least min_lift_m above its rest height throughout the hover
      window, or it touches the table or ground there;
    - any pad slips more than max_slip_m relative to the object (end of grasp on);
    - a vehicle is in failsafe at the end;
    - the simulator rejected any setpoint as implausible;
    - an AM's actuators saturate on more than max_saturated_fraction of the run's steps.
    """

    min_lift_m: float = 0.2
    max_slip_m: Annotated[float, Meta(ge=0.0, description="[m]")] = 0.002
    max_saturated_fraction: Probability = 0.05
    max_distance_m: Annotated[float, Meta(ge=0.0, description="[m]")] = 3.0


@dataclass(frozen=True)
class ScenarioSpec:
    name: str
    vehicle: VehicleParams
    object: ObjectSpec
    mission: MissionSpec
    ams: tuple[AmSpec, ...]
    duration_s: float = 20.0
    rate_hz: Annotated[float, Meta(ge=RATE_HZ_RANGE[0], le=RATE_HZ_RANGE[1], description="[Hz]")] = 1000.0  # physics: the world's step, the devices and the emulated autopilot
    # PyBullet's substeps per physics step (PHYSICS_SUBSTEPS): its contacts and joints integrate at
    # rate_hz * physics_substeps, with each step's forces held across its substeps; 1: none
    physics_substeps: PhysicsSubsteps = 1
    # PyBullet's constraint solver (numSolverIterations): at most this many sweeps a step, fewer
    # once its residual is below 1e-7 (SOLVER_ITERATIONS_RANGE); 50 is PyBullet's own default
    solver_iterations: Annotated[int, Meta(ge=SOLVER_ITERATIONS_RANGE[0], le=SOLVER_ITERATIONS_RANGE[1])] = 50
    # the companions' rate; the lockstep exchanges every rate_hz / control_rate_hz physics
    # steps (a whole number). None: every physics step
    control_rate_hz: Annotated[float, Meta(gt=0.0, description="[Hz]")] | None = None
    seed: Annotated[int, Meta(ge=0, le=SEED_MAX)] = 0
    link: LinkSpec = LinkSpec()
    sensors: SensorSpec = SensorSpec()
    devices: DevicesSpec = DevicesSpec()
    success: SuccessCriteria = SuccessCriteria()
    path: Path | None = None

    @property
    def dt_s(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def control_every(self) -> int:
        """Physics steps per control step (1 when the companions run at the physics rate)."""
        return 1 if self.control_rate_hz is None else round(self.rate_hz / self.control_rate_hz)

    @property
    def control_dt_s(self) -> float:
        return self.control_every * self.dt_s

    def am(self, sysid: int) -> AmSpec:
        for a in self.ams:
            if a.sysid == sysid:
                return a
        known = ", ".join(str(a.sysid) for a in self.ams)
        raise ConfigError(f"{self.path}: no [[am]] with sysid {sysid} (scenario has {known})")


# ----------------------------------------------------------------------------- loading
# How a type reads in a message (msgspec names JSON's types; TOML has no null)
_TYPE_WORDS = {"float": "a number", "int": "an integer", "bool": "true or false", "str": "a string",
               "array": "a list", "object": "a table", "float | null": "a number"}
_DECLARED = re.compile(r"^(?P<what>.*?)(?: - at `\$(?P<at>.*)`)?$")


def _not_finite(value, where: str) -> None:
    """TOML's nan and inf are refused everywhere: no key takes them."""
    for i, v in enumerate(value if isinstance(value, list) else (value,)):
        if isinstance(v, float) and not math.isfinite(v):
            raise ConfigError(f"{where}: must be finite, got {v!r}" + (f" (entry {i})" if isinstance(value, list) else ""))


def _meta_at(tp, index: int | None):
    """The element type of `tp` at list `index` (None: `tp` itself), its Annotated metadata stripped,
    and its msgspec.Meta (or None)."""
    if index is not None and typing.get_origin(typing.get_args(tp)[0] if typing.get_origin(tp) is Annotated else tp) is tuple:
        args = typing.get_args(tp)
        tp = args[0] if len(args) == 2 and args[1] is Ellipsis else args[min(index, len(args) - 1)]
    if typing.get_origin(tp) in (types.UnionType, typing.Union):
        tp = next(a for a in typing.get_args(tp) if a is not type(None))
    if typing.get_origin(tp) is Annotated:
        base, *extras = typing.get_args(tp)
        return base, next((m for m in extras if isinstance(m, msgspec.Meta)), None)
    return tp, None


def _bounds(meta: msgspec.Meta, integer: bool) -> str:
    """A declared range in words: "must be > 0", "must be in [0, 1] s", "must be in 2..255"."""
    lo, hi = (meta.ge, "[") if meta.ge is not None else (meta.gt, "("), (meta.le, "]") if meta.le is not None else (meta.lt, ")")
    unit = re.search(r"\[([^\]]+)\]$", meta.description or "")
    unit = f" {unit.group(1)}" if unit and unit.group(1) not in ("1", "-") else ""
    if lo[0] is not None and hi[0] is not None:
        if integer and lo[1] == "[" and hi[1] == "]":
            return f"must be in {lo[0]}..{hi[0]}"
        return f"must be in {lo[1]}{lo[0]:g}, {hi[0]:g}{hi[1]}{unit}"
    if lo[0] is not None:
        return f"must be {'>=' if lo[1] == '[' else '>'} {lo[0]:g}"
    return f"must be {'<=' if hi[1] == ']' else '<'} {hi[0]:g}"


def _declared_problem(exc: msgspec.ValidationError, value, tp) -> str:
    """msgspec's ValidationError for `value` against the declared type `tp`, in the loader's words:
    "must be in [0, 1] s, got 1.5 (entry 2)", "expected one of box, cylinder, got 'ball'"."""
    m = _DECLARED.match(str(exc))
    what, at = m.group("what"), m.group("at") or ""
    index = int(at[1:-1]) if re.fullmatch(r"\[\d+\]", at) else None
    bad = value[index] if index is not None and isinstance(value, list) and index < len(value) else value
    entry = f" (entry {index})" if index is not None else ""
    base, meta = _meta_at(tp, index)
    if what.startswith(("Expected `float` ", "Expected `int` ")) and meta is not None:
        return f"{_bounds(meta, base is int)}, got {bad!r}{entry}"
    if what.startswith("Invalid enum value"):
        return f"expected one of {', '.join(map(str, typing.get_args(base)))}, got {bad!r}{entry}"
    n = re.fullmatch(r"Expected `array` of length (\d+), got (\d+)", what)
    if n:
        return f"expected {n.group(1)} entries, got {n.group(2)}"
    t = re.fullmatch(r"Expected `([^`]+)`, got `[^`]+`", what)
    if t:
        return f"expected {_TYPE_WORDS.get(t.group(1), t.group(1))}, got {bad!r}{entry}"
    return f"{what[:1].lower()}{what[1:]}{' at ' + at if at else ''}, got {bad!r}"  # pragma: no cover


def _check_type(value, tp, where: str):
    """`value` as the declared type `tp` (its Annotated msgspec.Meta ranges and Literal enums
    included), validated by msgspec; errors name `where`."""
    if typing.get_origin(tp) is Annotated and dataclasses.is_dataclass(typing.get_args(tp)[0]):
        tp = typing.get_args(tp)[0]
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a table, got {value!r}")
        return _build(tp, value, where)
    if tp is Path:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a path string, got {value!r}")
        return value
    _not_finite(value, where)
    try:
        return msgspec.convert(value, tp)
    except msgspec.ValidationError as exc:
        raise ConfigError(f"{where}: {_declared_problem(exc, value, tp)}") from None


def _hints(cls) -> dict:
    return typing.get_type_hints(cls, include_extras=True)


def _build(cls, table: dict, where: str, skip: tuple[str, ...] = ()):
    """Keyword arguments of dataclass `cls` from a TOML table: unknown and missing keys refused
    here (msgspec ignores unknown keys), each value checked against its declaration by msgspec."""
    hints = _hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    for key in table:
        if key not in names or key in skip:
            raise ConfigError(f"{where}: unknown key '{key}' (known: {', '.join(sorted(names - set(skip)))})")
    kwargs = {}
    for f in dataclasses.fields(cls):
        if f.name in skip or not f.init:
            continue
        if f.name in table:
            kwargs[f.name] = _check_type(table[f.name], hints[f.name], f"{where}.{f.name}")
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{where}: missing key '{f.name}'")
    return kwargs


def _read_toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a directory, not a TOML file") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot be read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}); TOML files are UTF-8") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None


def _in_range(where: str, value, lo: float, hi: float, unit: str = "") -> None:
    """lo <= value <= hi (both finite)."""
    if not lo <= value <= hi:
        raise ConfigError(f"{where}: must be in [{lo:g}, {hi:g}]{unit}, got {value!r}")


# physics rates a scenario may ask for [Hz]: below, the contact and the control laws cannot hold
# (PyBullet's own default is 240 Hz); above, a second of flight takes hours
RATE_HZ_RANGE = (100.0, 100_000.0)
# [scenario].physics_substeps. 2 divides the step exactly (Bullet counts substeps from an
# accumulator), and tests/simulator/test_world_sensors.py checks its contact forces. 4 is left
# out: at 1 kHz (0.25 ms contact steps) a friction-held object read 6.7 N carried for 4 N, as a
# world stepped at 4 kHz in one step does (docs/benchmarks.md, "A lower physics rate")
PhysicsSubsteps = Literal[1, 2]
PHYSICS_SUBSTEPS = typing.get_args(PhysicsSubsteps)
# [scenario].solver_iterations. A squeezed object's contacts never reach PyBullet's residual of
# 1e-7, so the solver sweeps the most it may every step of a grasp. Against a 1000-sweep solve
# of the same step, 25 sweeps read the contact forces as closely as 50 do (within ~0.1 N); 10 are
# off by ~0.2 N, 5 by up to ~1 N (docs/benchmarks.md, "PyBullet's solver sweeps"): hence at least 10
SOLVER_ITERATIONS_RANGE = (10, 1000)
SEED_MAX = 2**32 - 1  # the seed is a uint32 (numpy's SeedSequence entropy; AM_SCENARIO.seed)
SCENARIO_NAME_MAX_BYTES = 32  # AM_SCENARIO.name is char[32]
# Plausible objects for this stack's AMs, tables and arena ([object], [mission], [[am]]):
# - mass: below 10 g the weight (0.1 N) is within two steps of the wrist sensor's resolution
#   (1/16 N) and Bullet's contact solver loses it against the AMs' 1.8 kg; above 100 kg no
#   team of these vehicles lifts it (the lift check names the team's own limit, lower still);
# - each edge, radius and height: below 5 cm the pad's 8 cm face and the 3-4 cm squeeze are
#   as large as the object; above 3 m the AMs around it start outside the arena
#   ([success].max_distance_m, 3 m by default);
# - the object stands over the ground plane's drawn 10 m square, its bottom (the table's
#   top) at most 5 m up;
# - mission distances (standoff, start height, pre-grasp gap, lift) are at most 2 m.
OBJECT_MASS_RANGE_KG = (0.01, 100.0)
OBJECT_SIZE_RANGE_M = (0.05, 3.0)
OBJECT_XY_MAX_M = 10.0
OBJECT_BOTTOM_MAX_M = 5.0
MISSION_DISTANCE_MAX_M = 2.0
ObjectPose = Literal["config", "mocap"]  # [mission].object_pose
OBJECT_POSE_SOURCES = typing.get_args(ObjectPose)
MASS_TOLERANCE_MAX = 0.5  # a mass known to worse than +/-50 % is not a plan: weigh the object


def _is_key_hex(text: str) -> bool:
    try:
        return len(bytes.fromhex(text.strip())) == 32
    except ValueError:
        return False


def vehicle_from_dict(data: dict, path: Path) -> VehicleParams:
    where = str(path)
    kw = _build(VehicleParams, data.get("vehicle", {}), f"{where}: [vehicle]",
                skip=("rotors", "task", "gains", "safety", "options", "pad", "baseline", "flight_controller"))
    extra = set(data) - {"vehicle", "rotors", "task", "gains", "safety", "options", "pad", "baseline",
                         "flight_controller"}
    if extra:
        raise ConfigError(f"{where}: unknown table [{sorted(extra)[0]}]")
    sub = {}
    if "rotors" in data:
        sub["rotors"] = _rotors(data["rotors"], f"{where}: [rotors]")
    for name, cls in (("task", TaskSpec), ("gains", Gains),
                      ("safety", Safety), ("pad", PadSpec),
                      ("baseline", BaselineGains), ("flight_controller", FlightControllerParams)):
        if name in data:
            sub[name] = cls(**_build(cls, data[name], f"{where}: [{name}]"))
        elif name in ("rotors", "task", "gains"):
            raise ConfigError(f"{where}: missing table [{name}]")
    mode = sub.get("flight_controller", FlightControllerParams()).mode
    options = data.get("options", {})
    if not isinstance(options, dict):
        raise ConfigError(f"{where}: [options] must be a table")
    # the mode's defaults under the keys the files set (MODE_OPTION_DEFAULTS): resolved here only
    sub["options"] = ControllerOptions(**_build(ControllerOptions, {**MODE_OPTION_DEFAULTS.get(mode, {}), **options},
                                                f"{where}: [options]"))
    urdf = (path.parent / kw.pop("urdf")).resolve()
    if not urdf.is_file():
        raise ConfigError(f"{where}: [vehicle].urdf: file not found: {urdf}")
    v = VehicleParams(urdf=urdf, **kw, **sub)
    n = v.n_joints
    g = v.gains
    _check_urdf(v, where)
    _check_rotors(v.rotors, f"{where}: [rotors]")
    for key, seq in (("q_nominal_rad", v.q_nominal_rad), ("joint_torque_max_nm", v.joint_torque_max_nm)):
        if len(seq) != n:
            raise ConfigError(f"{where}: [vehicle].{key}: expected {n} entries (one per arm joint), got {len(seq)}")
    if len(v.task.components) != n:
        raise ConfigError(f"{where}: [task].components: a non-redundant arm needs {n} task components, got {len(v.task.components)}")
    if len(set(v.task.components)) != n:
        raise ConfigError(f"{where}: [task].components: a component is named twice in {list(v.task.components)}")
    missing = [c for c in GRASP_COMPONENTS if c not in v.task.components]
    if missing:
        raise ConfigError(f"{where}: [task].components: the grasp mission needs {' and '.join(map(repr, missing))} "
                          f"('x' approaches and squeezes towards the object, 'z' lifts it), got "
                          f"{list(v.task.components)}")
    for key in ("K_y", "D_y"):
        if len(getattr(g, key)) != n:
            raise ConfigError(f"{where}: [gains].{key}: expected {n} entries, got {len(getattr(g, key))}")
    if v.safety.y_err_max and len(v.safety.y_err_max) != n:
        raise ConfigError(f"{where}: [safety].y_err_max: expected {n} entries, got {len(v.safety.y_err_max)}")
    _check_urdf_physics(v, where)
    if v.safety.failsafe_joint_damping:
        if len(v.safety.failsafe_joint_damping) != n:
            raise ConfigError(f"{where}: [safety].failsafe_joint_damping: expected {n} entries (one per arm joint), "
                              f"got {len(v.safety.failsafe_joint_damping)}")
    if v.options.heading_admittance_hz > 0.0 and v.pad.shape != "crowned":
        raise ConfigError(f"{where}: [options].heading_admittance_hz needs [pad].shape = 'crowned' (it reads the "
                          f"misalignment off the crown)")
    if (v.pad.contact_stiffness_n_per_m > 0.0) != (v.pad.contact_damping_n_s_per_m > 0.0):
        raise ConfigError(f"{where}: [pad]: contact_stiffness_n_per_m and contact_damping_n_s_per_m go together "
                          f"(both 0: rigid)")
    if v.options.controller == "baseline" and v.flight_controller.mode == "attitude":
        raise ConfigError(f"{where}: [options].controller = 'baseline' flies in [flight_controller].mode = 'torque' "
                          f"only (its attitude loop is its own torque law)")
    if v.options.controller == "baseline" and v.baseline is None:
        raise ConfigError(f"{where}: [options].controller = 'baseline' needs a [baseline] table")
    if v.options.controller == "baseline" and tuple(v.task.components) != BASELINE_COMPONENTS:
        raise ConfigError(f"{where}: [options].controller = 'baseline': its inverse kinematics is for the planar "
                          f"task {list(BASELINE_COMPONENTS)} (joints about the body y axis); [task].components is "
                          f"{list(v.task.components)}")
    if v.baseline is not None:
        _check_baseline(v.baseline, n, f"{where}: [baseline]")
    return _derive_px4_gains(v, set(data.get("flight_controller", {})))


def _derive_px4_gains(v: VehicleParams, given: set[str]) -> VehicleParams:
    """The [flight_controller] gains the file does not give, by amcore.px4_gains' rule."""
    from . import px4_gains

    missing = [k for k in px4_gains.REFERENCE if k not in given]
    if not missing:
        return v
    derived = px4_gains.derived_gains(*px4_units(v))
    return dataclasses.replace(v, flight_controller=dataclasses.replace(v.flight_controller,
                                                                       **{k: derived[k] for k in missing}))


def px4_units(v: VehicleParams) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(J, S): the whole AM's rotational inertia about the base's origin, body axes, arm at
    q_nominal_rad (roll, pitch, yaw) [kg m^2], and PX4's torque units on those axes [N m per unit
    of normalized torque] (amcore.px4_gains)."""
    from .vehicle_checks import whole_am_inertia

    J = whole_am_inertia(v.urdf, v.q_nominal_rad)
    return tuple(float(x) for x in J.diagonal()), tuple(Allocation(v.rotors).torque_scale_nm)


def _rotors(table, where: str) -> RotorParams:
    """[rotors] with its [[rotors.rotor]] rows (see `Rotor`, `RotorParams`)."""
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: expected a table, got {table!r}")
    old = sorted({"arm_length_m", "layout", "yaw_moment_coeff_m"} & set(table))
    hint = (" (the rotors are now one [[rotors.rotor]] row each, as PX4's CA_ROTORn_*, yaw_moment_coeff_m "
            "being each row's moment_ratio_m: see configs/vehicles/am3dof.toml)") if old else ""
    if "rotor" not in table:
        raise ConfigError(f"{where}: missing key 'rotor'{hint}")
    if old:  # beside rows: an old key left in, or set by an override (am-trials --set rotors.<key>=...)
        raise ConfigError(f"{where}: unknown key '{old[0]}'{hint}")
    rows = table["rotor"]
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise ConfigError(f"{where}.rotor: expected an array of tables ([[rotors.rotor]]), got {rows!r}")
    kw = _build(RotorParams, {k: v for k, v in table.items() if k != "rotor"}, where, skip=("rotor",))
    rotors = tuple(Rotor(**_build(Rotor, row, f"{where}.rotor[{i}]")) for i, row in enumerate(rows))
    for i, r in enumerate(rotors):
        for key in ("thrust_min_n", "thrust_max_n", "time_constant_s", "moment_ratio_m"):
            val = getattr(r, key)
            if val is not None and (isinstance(val, bool) or not isinstance(val, (int, float))):
                raise ConfigError(f"{where}.rotor[{i}].{key}: expected a number, got {val!r}")
    return RotorParams(rotor=rotors, **kw)


def _check_rotors(r: RotorParams, where: str) -> None:
    """amcore.rotors.table_problem, as a ConfigError naming the file, table and key."""
    problem = table_problem(r)
    if problem is not None:
        raise ConfigError(f"{where}{problem[0]}: {problem[1]}")


def _urdf_tree(urdf: Path, where: str) -> ET.Element:
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{where}: [vehicle].urdf: {urdf} is not a readable URDF: {exc}") from None
    if root.tag != "robot":
        raise ConfigError(f"{where}: [vehicle].urdf: {urdf}: the root element is <{root.tag}>, not <robot>")
    return root


def _check_urdf(v: VehicleParams, where: str) -> None:
    """The names the vehicle file gives exist in its URDF, and the URDF's movable joints are
    exactly arm_joints, in the order of the chain from base_link (as pinocchio numbers them)."""
    root = _urdf_tree(v.urdf, where)
    links = [e.get("name") for e in root.findall("link")]
    joints = root.findall("joint")
    names = {j.get("name") for j in joints}
    if v.base_link not in links:
        raise ConfigError(f"{where}: [vehicle].base_link: no link '{v.base_link}' in {v.urdf} (links: "
                          f"{', '.join(map(str, links)) or 'none'})")
    for key in ("ee_frame", "ft_frame"):
        if getattr(v, key) not in set(links) | names:
            raise ConfigError(f"{where}: [vehicle].{key}: no link or joint '{getattr(v, key)}' in {v.urdf}")
    children: dict[str, list] = {}
    for j in joints:
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise ConfigError(f"{where}: [vehicle].urdf: joint '{j.get('name')}' of {v.urdf} lacks <parent> or <child>")
        children.setdefault(parent.get("link"), []).append(j)
    stack, seen = [v.base_link], set()
    while stack:  # a tree (no link reached twice), so that _chain_joints ends
        link = stack.pop()
        if link in seen:
            raise ConfigError(f"{where}: [vehicle].urdf: {v.urdf} has a loop at link '{link}'")
        seen.add(link)
        stack += [j.find("child").get("link") for j in children.get(link, [])]
    movable = _chain_joints(v.base_link, children)  # depth first from the base, children in file order
    if tuple(movable) != tuple(v.arm_joints):
        missing = [q for q in v.arm_joints if q not in names]
        what = f"no joint {', '.join(map(repr, missing))} in {v.urdf}" if missing else \
            f"the movable joints of {v.urdf} from '{v.base_link}' are {movable}"
        raise ConfigError(f"{where}: [vehicle].arm_joints: {what}; the vehicle file lists {list(v.arm_joints)}")
    if not urdf_mass_kg(v.urdf, where) > 0.0:
        raise ConfigError(f"{where}: [vehicle].urdf: {v.urdf}: the links' <inertial> masses sum to 0")


def _check_urdf_physics(v: VehicleParams, where: str) -> None:
    """amcore.vehicle_checks: inertials, q_nominal_rad in the limits, static torques; warns of task
    components the arm cannot move."""
    from . import vehicle_checks as vc

    root = _urdf_tree(v.urdf, where)
    try:
        vc.check_inertials(root, v.base_link)
    except vc.UrdfCheckError as exc:
        raise ConfigError(f"{where}: [vehicle].urdf: {v.urdf}: {exc}") from None
    why = vc.check_nominal_in_limits(root, v.arm_joints, v.q_nominal_rad)
    if why:
        raise ConfigError(f"{where}: [vehicle].q_nominal_rad: {why}")
    why = vc.check_static_torques(v.urdf, v.arm_joints, v.q_nominal_rad, v.joint_torque_max_nm, v.gravity_mps2)
    if why:
        raise ConfigError(f"{where}: [vehicle].joint_torque_max_nm: {why}")
    for text in vc.task_warnings(v.urdf, v.ee_frame, v.q_nominal_rad, tuple(v.task.components)):
        warnings.warn(f"{where}: {text}", ConfigWarning, stacklevel=2)


def _chain_joints(link: str, children: dict[str, list]) -> list[str]:
    out = []
    for j in children.get(link, []):
        if j.get("type") != "fixed":
            out.append(j.get("name"))
        out += _chain_joints(j.find("child").get("link"), children)
    return out


def urdf_mass_kg(urdf: Path, where: str = "") -> float:
    """The sum of the URDF's link masses [kg] (pinocchio's total mass of the model)."""
    total = 0.0
    for m in _urdf_tree(urdf, where or str(urdf)).findall("link/inertial/mass"):
        try:
            value = float(m.get("value", "nan"))
        except ValueError:
            value = math.nan
        if not (value >= 0.0 and math.isfinite(value)):
            raise ConfigError(f"{where or urdf}: [vehicle].urdf: {urdf}: a link mass is {m.get('value')!r}")
        total += value
    return total


def _check_baseline(b: BaselineGains, n: int, where: str) -> None:
    for key in ("K_q", "D_q"):
        if len(getattr(b, key)) != n:
            raise ConfigError(f"{where}.{key}: expected {n} entries (one per arm joint), got {len(getattr(b, key))}")
    if b.arm == "cartesian":  # the task gains' count is the arm's (and needed only then)
        for key in ("K_y", "D_y"):
            if len(getattr(b, key)) != n:
                raise ConfigError(f"{where}.{key}: arm = 'cartesian' needs {n} entries (one per task component), "
                                  f"got {len(getattr(b, key))}")
    if b.reaction_feedforward and b.arm != "cartesian":
        raise ConfigError(f"{where}.reaction_feedforward: needs arm = 'cartesian' (fed forward, the joint PD's "
                          f"wrench closes a loop through the base's desired attitude)")


def load_vehicle(path: str | Path) -> VehicleParams:
    path = Path(path).resolve()
    return vehicle_from_dict(_read_toml(path), path)


def load_scenario(path: str | Path) -> ScenarioSpec:
    """Load a scenario TOML; its [scenario].vehicle names a vehicle TOML relative to it.

    A scenario may override controller options with an [options] table (e.g. to turn
    force compensation off), safety settings with [safety], the pad with [pad], the flight
    controller with [flight_controller] (e.g. attitude mode) and rotor settings with [rotors]
    (e.g. the rotors' time constant); each is merged key by key onto the vehicle's table.
    A scenario with a top-level `base` is an overlay of that scenario (`resolve_base`).
    """
    path = Path(path).resolve()
    return scenario_from_dict(_read_toml(path), path)


# ----------------------------------------------------------------------------- overlays
# Keys of scenario data that hold a path, (table, key): a relative one is read from the folder of
# the file that wrote it, so a base's is rewritten when it is laid under a file in another folder.
SCENARIO_PATH_KEYS = (("scenario", "vehicle"), ("link", "key_file"))


def merge_tables(base: dict, overlay: dict) -> dict:
    """`overlay` laid on `base`: a table merges key by key, recursively; any other value (a number,
    a string, a boolean, an array, an array of tables such as [[am]]) replaces the base's whole.
    Neither argument is changed."""
    out = {k: copy.deepcopy(v) for k, v in base.items()}
    for key, value in overlay.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge_tables(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def read_scenario(path: str | Path) -> dict:
    """A scenario file's TOML data as the loader flies it: its `base` resolved (`resolve_base`),
    self-contained, relative paths taken from `path`'s folder. A file without `base` reads as it is."""
    path = Path(path).resolve()
    return resolve_base(_read_toml(path), path)


def resolve_base(data: dict, path: Path) -> dict:
    """Scenario `data`, read from `path`, with its top-level `base` resolved.

    `base = "other.toml"` (relative to `path`'s folder) makes `data` an overlay: the base is read
    (and its own base, and so on), then `data`'s keys are laid on it by `merge_tables`. A top-level
    `unset = ["rotors", "mission.squeeze_max_n"]` first removes those keys or tables from the base
    (what `merge_tables` alone cannot: an overlay sets keys, never deletes them). Paths in the base
    ([scenario].vehicle, [link].key_file) keep pointing where its file meant them. Raises
    ConfigError naming the file and the key (and both files for a base that cannot be read)."""
    return _resolved(data, Path(path), ())[0]


def _resolved(data: dict, path: Path, chain: tuple[Path, ...]) -> tuple[dict, tuple[Path, ...]]:
    """(`resolve_base`'s data, the bases laid under it, nearest first); `chain`: the files whose
    bases led here, to name a cycle."""
    if "base" not in data and "unset" not in data:
        return data, ()
    where = str(path)
    data = dict(data)
    text, unset = data.pop("base", None), data.pop("unset", None)
    if text is None:
        raise ConfigError(f"{where}: unset: needs a base (the keys it removes are the base's)")
    if not isinstance(text, str) or not text:
        raise ConfigError(f"{where}: base: expected the path of a scenario TOML (relative to this file's folder), "
                          f"got {text!r}")
    here = path.resolve()
    bpath = (here.parent / text).resolve()
    chain = (*chain, here)
    if bpath in chain:
        cycle = " -> ".join(str(p) for p in (*chain[chain.index(bpath):], bpath))
        raise ConfigError(f"{where}: base = {text!r}: a cycle of bases: {cycle}")
    try:
        bdata, bases = _resolved(_read_toml(bpath), bpath, chain)
    except ConfigError as exc:
        raise ConfigError(f"{where}: base = {text!r}: {exc}") from None
    bdata = _rebased(bdata, bpath.parent, here.parent)
    if unset is not None:
        bdata = _unset(bdata, unset, f"{where}: unset", bpath)
    return merge_tables(bdata, data), (bpath, *bases)


def _rebased(data: dict, src_dir: Path, dst_dir: Path) -> dict:
    """Scenario data read in `src_dir` with its relative paths (SCENARIO_PATH_KEYS) rewritten
    for a file in `dst_dir`; unchanged when the two are one folder."""
    if src_dir == dst_dir:
        return data
    out = dict(data)
    for table, key in SCENARIO_PATH_KEYS:
        t = out.get(table)
        rel = t.get(key) if isinstance(t, dict) else None
        if isinstance(rel, str) and rel and not Path(rel).is_absolute():
            target = (src_dir / rel).resolve()
            try:
                moved = os.path.relpath(target, dst_dir)
            except ValueError:  # another drive: no relative path reaches it
                moved = str(target)
            out[table] = {**t, key: Path(moved).as_posix()}
    return out


def _unset(data: dict, keys, where: str, bpath: Path) -> dict:
    """`data` without each dotted key (a key of a table, or a whole table) in `keys`."""
    if not isinstance(keys, list) or not all(isinstance(k, str) and k for k in keys):
        raise ConfigError(f"{where}: expected a list of dotted keys of the base, e.g. [\"rotors\"], got {keys!r}")
    out = copy.deepcopy(data)
    for key in keys:
        *tables, last = key.split(".")
        t = out
        for name in tables:
            t = t.get(name) if isinstance(t, dict) else None
        if not isinstance(t, dict) or last not in t:
            raise ConfigError(f"{where}: {key!r} is not in the base ({bpath})")
        del t[last]
    return out


SCENARIO_TABLES = ("scenario", "object", "mission", "am", "options", "safety", "pad", "flight_controller",
                   "rotors", "link", "sensors", "devices", "success", "randomize")


def scenario_from_dict(data: dict, path: Path) -> ScenarioSpec:
    """`load_scenario` on TOML data already read; relative paths in it are taken from
    `path`'s folder and errors name `path` (and the bases under it, `resolve_base`). A
    [randomize] table is left to `trials`."""
    data, bases = _resolved(data, Path(path), ())
    where = str(path) if not bases else f"{path} (over {', '.join(b.name for b in bases)})"
    extra = set(data) - set(SCENARIO_TABLES)
    if extra:
        raise ConfigError(f"{where}: unknown table [{sorted(extra)[0]}]")
    if "scenario" not in data:
        raise ConfigError(f"{where}: missing table [scenario]")
    if not isinstance(data["scenario"], dict):
        raise ConfigError(f"{where}: [scenario] must be a table")
    sc = dict(data["scenario"])
    if "vehicle" not in sc:
        raise ConfigError(f"{where}: [scenario]: missing key 'vehicle'")
    if not isinstance(sc["vehicle"], str) or not sc["vehicle"]:
        raise ConfigError(f"{where}: [scenario].vehicle: expected the path of a vehicle TOML, got {sc['vehicle']!r}")
    vtext = sc.pop("vehicle")
    vpath = (path.parent / vtext).resolve()
    if not vpath.is_file():  # a scenario copied away from configs/scenarios/: name the key that points there
        raise ConfigError(f"{where}: [scenario].vehicle = {vtext!r}: {vpath}: "
                          f"{'is a directory, not a TOML file' if vpath.is_dir() else 'file not found'} "
                          f"(a relative path is read from the scenario's folder, {path.parent})")
    vdata = _read_toml(vpath)
    for tbl in _VEHICLE_OVERRIDES:
        if tbl in data:
            merged = dict(vdata.get(tbl, {}))
            merged.update(data[tbl])
            vdata[tbl] = merged
    try:
        vehicle = vehicle_from_dict(vdata, vpath)
    except ConfigError as exc:  # a value the scenario set: name the scenario too
        named = [t for t in _VEHICLE_OVERRIDES if t in data and f"[{t}]" in str(exc)]
        if named:
            raise ConfigError(f"{where}: [{named[0]}] (merged onto the vehicle's): {exc}") from None
        raise
    kw = _build(ScenarioSpec, sc, f"{where}: [scenario]",
                skip=("vehicle", "object", "mission", "ams", "path", "link", "sensors", "devices", "success"))
    if "object" not in data:
        raise ConfigError(f"{where}: missing table [object]")
    obj = ObjectSpec(**_build(ObjectSpec, data["object"], f"{where}: [object]"))
    if obj.shape == "cylinder":
        _in_range(f"{where}: [object].radius_m", obj.radius_m, *OBJECT_SIZE_RANGE_M, " m")
        _in_range(f"{where}: [object].height_m", obj.height_m, *OBJECT_SIZE_RANGE_M, " m")
    else:
        for i, edge in enumerate(obj.size_m):
            _in_range(f"{where}: [object].size_m (entry {i})", edge, *OBJECT_SIZE_RANGE_M, " m")
    for i in (0, 1):
        _in_range(f"{where}: [object].position_m (entry {i})", obj.position_m[i], -OBJECT_XY_MAX_M, OBJECT_XY_MAX_M,
                  " m (over the ground's drawn square)")
    if obj.position_m[2] - obj.half_height_m > OBJECT_BOTTOM_MAX_M:
        raise ConfigError(f"{where}: [object].position_m: the object's bottom (the table's top) is "
                          f"{obj.position_m[2] - obj.half_height_m:.3g} m up, must be in [0, {OBJECT_BOTTOM_MAX_M:g}] m")
    if obj.position_m[2] - obj.half_height_m < -1e-9:
        raise ConfigError(f"{where}: [object].position_m: the object's bottom is {obj.position_m[2] - obj.half_height_m:.3g} m, "
                          f"below the ground (z = 0)")
    mission = MissionSpec(**_build(MissionSpec, data.get("mission", {}), f"{where}: [mission]"))
    if not (0 < mission.approach_end_s < mission.grasp_end_s < mission.hover_end_s):
        raise ConfigError(f"{where}: [mission]: need 0 < approach_end_s < grasp_end_s < hover_end_s")
    if mission.planned_mass_kg != 0.0:
        _in_range(f"{where}: [mission].planned_mass_kg", mission.planned_mass_kg, *OBJECT_MASS_RANGE_KG,
                  " kg (0: the object's mass_kg)")
    if (mission.touch_force_n > 0.0) != (mission.touch_hold_s > 0.0):
        raise ConfigError(f"{where}: [mission]: touch_force_n and touch_hold_s go together (both 0: off)")
    if mission.touch_hold_s > 0.0 and (mission.approach_end_s + 2.0 * mission.grasp_move_s + mission.touch_hold_s
                                       > mission.grasp_end_s + 1e-9):
        raise ConfigError(f"{where}: [mission]: touch, hold and squeeze (2 grasp_move_s + touch_hold_s = "
                          f"{2.0 * mission.grasp_move_s + mission.touch_hold_s:g} s) must fit in the grasp phase "
                          f"({mission.grasp_end_s - mission.approach_end_s:g} s)")
    am_tables = data.get("am", [])
    if not isinstance(am_tables, list) or not am_tables:
        raise ConfigError(f"{where}: needs at least one [[am]] entry")
    link_table = data.get("link", {})
    if not isinstance(link_table, dict):
        raise ConfigError(f"{where}: [link] must be a table")
    link = _link_spec(link_table, f"{where}: [link]")
    ams = []
    for i, t in enumerate(am_tables):
        w = f"{where}: [[am]] #{i + 1}"
        if not isinstance(t, dict):
            raise ConfigError(f"{w}: expected a table")
        am_link = None
        if "link" in t:
            own = t["link"]
            allowed = {"loss", "delay_s", "jitter_s", "reorder", "duplicate", "joints"}
            if not isinstance(own, dict) or set(own) - allowed:
                raise ConfigError(f"{w}.link: expected a table of {', '.join(sorted(allowed))}")
            am_link = _link_spec({**link_table, **own}, f"{w}.link")
        plain = {k: v for k, v in t.items() if k != "link"}
        ams.append(AmSpec(**_build(AmSpec, plain, w, skip=("link",)), link=am_link))
    ams = tuple(ams)
    seen = set()
    for i, a in enumerate(ams):
        if a.sysid in seen:
            raise ConfigError(f"{where}: [[am]] #{i + 1}.sysid: duplicate sysid {a.sysid}")
        seen.add(a.sysid)
    for i, a in enumerate(ams):
        if a.signing_key_hex and not _is_key_hex(a.signing_key_hex):
            raise ConfigError(f"{where}: [[am]] #{i + 1}.signing_key_hex: need 64 hex digits (32 bytes)")
    key_path = link.key_path(path)
    if key_path is not None and not key_path.is_file():
        raise ConfigError(f"{where}: [link].key_file: file not found: {key_path}")
    sensors = SensorSpec(**_build(SensorSpec, _table(data, "sensors", where), f"{where}: [sensors]"))
    devices = devices_from_table(_table(data, "devices", where), where)
    if devices.enabled and not sensors.exact:
        raise ConfigError(f"{where}: [devices].enabled: the device models replace [sensors]; use one or the other")
    success = SuccessCriteria(**_build(SuccessCriteria, _table(data, "success", where), f"{where}: [success]"))
    spec = ScenarioSpec(vehicle=vehicle, object=obj, mission=mission, ams=ams, path=path, link=link,
                        sensors=sensors, devices=devices, success=success, **kw)
    _check_name(spec.name, f"{where}: [scenario].name")
    if spec.rate_hz * spec.physics_substeps > RATE_HZ_RANGE[1]:
        raise ConfigError(f"{where}: [scenario].physics_substeps: rate_hz x physics_substeps = "
                          f"{spec.rate_hz * spec.physics_substeps:g} Hz, above {RATE_HZ_RANGE[1]:g} Hz")
    if spec.control_rate_hz is not None:  # a whole number of physics steps per control step
        _check_divides(spec.rate_hz, spec.control_rate_hz, f"{where}: [scenario].control_rate_hz")
    _check_divides(spec.rate_hz, vehicle.flight_controller.rate_hz, f"{where}: [flight_controller].rate_hz")
    if vehicle.flight_controller.actuation_delay_steps > spec.control_every:
        n = spec.control_every
        raise ConfigError(f"{where}: [flight_controller].actuation_delay_steps: at most the control period, "
                          f"{n} physics step{'s' if n > 1 else ''} here, got {vehicle.flight_controller.actuation_delay_steps}")
    check_duration(spec, spec.duration_s, f"{where}: [scenario].duration_s")
    _check_lift(spec, where)
    _check_grasp_geometry(spec, where)
    return spec


def check_duration(spec: ScenarioSpec, duration_s: float, where: str) -> None:
    """A run of `duration_s` [s] is finite and holds at least one control period of `spec`."""
    if not (math.isfinite(duration_s) and duration_s >= spec.control_dt_s * (1.0 - 1e-9)):
        raise ConfigError(f"{where}: must be finite and at least one control period ({spec.control_dt_s:g} s), "
                          f"got {duration_s!r}")


_NAME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.")


def _check_name(name: str, where: str) -> None:
    """A scenario name fits AM_SCENARIO.name and is one plain folder name: runs are written
    to runs/<name>-<time>, so a name with a path in it would write elsewhere."""
    if (not name or len(name) > SCENARIO_NAME_MAX_BYTES or not set(name) <= _NAME_CHARS
            or name[0] in ".-"):
        raise ConfigError(f"{where}: must be 1 to {SCENARIO_NAME_MAX_BYTES} letters, digits, '_', '-' or '.', "
                          f"not starting with '.' or '-' (AM_SCENARIO.name, and the run folder's name), got {name!r}")


def _check_lift(spec: ScenarioSpec, where: str) -> None:
    """The team's rotors can carry the team and the object within [mission].thrust_fraction_max
    of their maximum (the margin the mission plans with), as a whole."""
    v, m = spec.vehicle, spec.mission
    n = len(spec.ams)
    m_am = urdf_mass_kg(v.urdf, where)
    need_n = (n * m_am + spec.object.mass_kg) * v.gravity_mps2
    have_n = m.thrust_fraction_max * n * v.rotors.thrust_max_z_n
    if need_n > have_n:
        most = have_n / v.gravity_mps2 - n * m_am
        raise ConfigError(f"{where}: [object].mass_kg: {spec.object.mass_kg:g} kg is more than {n} AMs can lift with "
                          f"margin: they and the object weigh {need_n:.1f} N, {m.thrust_fraction_max:g} of their rotors' "
                          f"{n * v.rotors.thrust_max_z_n:g} N is {have_n:.1f} N (at most "
                          f"{max(0.0, most):.2f} kg)")


def design_mass_kg(spec: ScenarioSpec) -> float:
    """The heaviest the object can be for the team's plan [kg]: the planned mass ([mission].planned_mass_kg,
    else [object].mass_kg) over 1 - [mission].mass_tolerance (the planned mass is within that fraction of
    the true one). With neither set, exactly [object].mass_kg."""
    m = spec.mission
    planned = m.planned_mass_kg if m.planned_mass_kg > 0.0 else spec.object.mass_kg
    return planned if m.mass_tolerance == 0.0 else planned / (1.0 - m.mass_tolerance)


def surface_distance(obj: ObjectSpec, azimuth_rad: float, yaw_rad: float | None = None) -> float:
    """Distance [m] from the object's vertical axis to its side along the horizontal direction
    azimuth (W), the object turned by yaw_rad about z (None: its [object].yaw_deg)."""
    if obj.shape == "cylinder":
        return obj.radius_m
    yaw = math.radians(obj.yaw_deg) if yaw_rad is None else yaw_rad
    a = azimuth_rad - yaw if yaw != 0.0 else azimuth_rad
    hx, hy = 0.5 * obj.size_m[0], 0.5 * obj.size_m[1]
    c, s = abs(math.cos(a)), abs(math.sin(a))
    return min(hx / c if c > 1e-12 else math.inf, hy / s if s > 1e-12 else math.inf)


def faces_from_pose(spec: ScenarioSpec) -> bool:
    """Whether the AMs pick a box's face from the object's pose ([mission].object_pose = "mocap", or a
    box turned by [object].yaw_deg) rather than approach along their azimuths (the paper's)."""
    return spec.object.shape == "box" and (spec.mission.object_pose == "mocap" or spec.object.yaw_deg != 0.0)


def face_azimuth(azimuth_rad: float, yaw_rad: float) -> float:
    """The normal of a box's face nearest the direction azimuth_rad [rad, W], the box turned by yaw_rad:
    yaw + k pi/2 with k the nearest whole number to (azimuth - yaw) / (pi/2). Two AMs at opposite
    azimuths get opposite faces (k and k + 2), ties included."""
    return yaw_rad + math.floor((azimuth_rad - yaw_rad) / (0.5 * math.pi) + 0.5) * (0.5 * math.pi)


def grasped_face(spec: ScenarioSpec, am: AmSpec, yaw_rad: float | None = None) -> tuple[float, float]:
    """The face AM `am` grasps, the object turned by yaw_rad (None: its [object].yaw_deg): the
    azimuth of its outward normal [rad, W] (the box's face nearest the AM's azimuth with
    `faces_from_pose`, else the azimuth itself) and its distance from the object's axis [m]."""
    yaw = math.radians(spec.object.yaw_deg) if yaw_rad is None else yaw_rad
    az = math.radians(am.azimuth_deg)
    if faces_from_pose(spec):
        az = face_azimuth(az, yaw)
    return az, surface_distance(spec.object, az, yaw)


def _pad_start_W(spec: ScenarioSpec, am: AmSpec) -> tuple[float, float, float]:
    """Where AM `am`'s pad starts [m, W]: [mission].standoff_m outside the face on its azimuth (the
    face nearest it, `faces_from_pose`), start_height_m above the grasp height, moved by its
    start_offset_m (amcore.mission)."""
    az, half = grasped_face(spec, am)
    r = half + spec.mission.standoff_m
    c = spec.object.position_m
    return (c[0] + r * math.cos(az) + am.start_offset_m[0], c[1] + r * math.sin(az) + am.start_offset_m[1],
            c[2] + spec.mission.start_height_m + am.start_offset_m[2])


def _base_width_m(v: VehicleParams, where: str) -> float:
    """The widest horizontal edge of the base link's collision boxes in the URDF [m]; if it has
    none, the farthest rotor's distance from the base's z axis (its arm)."""
    link = next((l for l in _urdf_tree(v.urdf, where).iter("link") if l.get("name") == v.base_link), None)
    edges = []
    for box in ([] if link is None else link.findall("collision/geometry/box")):
        try:
            edges += [float(e) for e in box.get("size", "").split()[:2]]
        except ValueError:
            pass
    return max(edges) if edges else max(math.hypot(r.position_m[0], r.position_m[1]) for r in v.rotors.rotor)


def _check_grasp_geometry(spec: ScenarioSpec, where: str) -> None:
    """The AMs can start and grasp where the scenario puts them: the squeeze stays inside the
    object, no two AMs start with their bases overlapping (closer than the base's width; their
    pads' start points are a lower bound of their bases' distance, each base being behind its
    pad, away from the object), and the lift reaches the success criterion's height."""
    m, obj = spec.mission, spec.object
    half_min = obj.radius_m if obj.shape == "cylinder" else 0.5 * min(obj.size_m[0], obj.size_m[1])
    if m.squeeze_m >= half_min:
        raise ConfigError(f"{where}: [mission].squeeze_m: {m.squeeze_m:g} m reaches the object's centre; it must be "
                          f"less than its half width, {half_min:g} m")
    if m.lift_m < spec.success.min_lift_m:
        raise ConfigError(f"{where}: [mission].lift_m: {m.lift_m:g} m never reaches [success].min_lift_m "
                          f"({spec.success.min_lift_m:g} m); must be in [{spec.success.min_lift_m:g}, "
                          f"{MISSION_DISTANCE_MAX_M:g}] m")
    starts = [_pad_start_W(spec, a) for a in spec.ams]
    gap = _base_width_m(spec.vehicle, where)
    for i in range(len(spec.ams)):
        for j in range(i + 1, len(spec.ams)):
            d = math.dist(starts[i], starts[j])
            if d < gap:
                a, b = spec.ams[i], spec.ams[j]
                r = min(surface_distance(obj, math.radians(x.azimuth_deg)) for x in (a, b)) + m.standoff_m
                least = math.degrees(2.0 * math.asin(min(1.0, gap / (2.0 * r))))
                raise ConfigError(
                    f"{where}: [[am]] #{j + 1}.azimuth_deg: sysid {b.sysid} (azimuth_deg {b.azimuth_deg:g}, "
                    f"start_offset_m {list(b.start_offset_m)}) starts {d:.3g} m from [[am]] #{i + 1}, sysid {a.sysid} "
                    f"(azimuth_deg {a.azimuth_deg:g}, start_offset_m {list(a.start_offset_m)}); AMs must start at least "
                    f"a base's width ({gap:g} m) apart: azimuths about {least:.0f} deg or more apart at this object and "
                    f"standoff")


def _table(data: dict, name: str, where: str) -> dict:
    t = data.get(name, {})
    if not isinstance(t, dict):
        raise ConfigError(f"{where}: [{name}] must be a table")
    return t
def _check_divides(physics_hz: float, rate_hz: float, where: str) -> None:
    """A rate that runs every whole number of physics steps, and not faster than physics."""
    ratio = physics_hz / rate_hz
    if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-9:
        raise ConfigError(f"{where}: {rate_hz:g} Hz must divide the physics rate {physics_hz:g} Hz "
                          f"(a whole number of physics steps per period)")


# vehicle tables a scenario may override key by key (see load_scenario)
_VEHICLE_OVERRIDES = ("options", "safety", "pad", "flight_controller", "rotors")


def _link_spec(table: dict, where: str) -> LinkSpec:
    return LinkSpec(**_build(LinkSpec, table, where))


def scenario_id(spec: ScenarioSpec) -> int:
    """A 32-bit fingerprint of everything that defines a run (AM_SCENARIO.scenario_id).

    Computed from the parsed scenario and vehicle (not file paths, formatting, or whether the
    file is an overlay of another: the resolved data only) plus the URDF's bytes, so a simulator
    and a companion on different hosts agree exactly when they load the same scenario, and a
    companion started with another one is told so.
    """
    import hashlib
    import json
    import zlib

    secret = {"path", "signing_key_hex", "key_file"}  # AM_SCENARIO is public: no key material in it

    def plain(x):
        if dataclasses.is_dataclass(x):
            return {f.name: plain(getattr(x, f.name)) for f in dataclasses.fields(x) if f.name not in secret}
        if isinstance(x, Path):
            return hashlib.sha256(x.read_bytes()).hexdigest() if x.is_file() else str(x)
        if isinstance(x, (tuple, list)):
            return [plain(v) for v in x]
        return x

    text = json.dumps(plain(spec), sort_keys=True, separators=(",", ":"))
    return zlib.crc32(text.encode("utf-8"))
