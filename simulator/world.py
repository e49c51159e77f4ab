"""The PyBullet world of the paper's Sec. V: N aerial manipulators, a table and an object.

`World(spec, initial)` stores only; `connect()` builds the scene in its own DIRECT client.
Then, once per physics step (1 / spec.rate_hz):

    report = world.apply(sysid, thrust_n, tau_B_nm, tau_q_nm)   # for each AM (torque mode),
    joints = world.apply_rotors(sysid, rotor_thrusts_n, tau_q_nm)  # or rotor thrusts (attitude mode)
    world.step()
    state, wrench = world.state(sysid), world.wrench_ee(sysid)

Frames: W world (z up); B base link = quadrotor CoM; E end-effector (`ee` link: centre of
the pad's contact face, x = outward normal). Conventions verified by tests/simulator:

* PyBullet reports the base's inertial frame; `load_am` asserts it coincides with B.
* Rotors (amcore.allocation): the command is allocated to rotor thrusts, and what acts is
  the wrench those thrusts make, sum_i f_i (a_i; p_i x a_i - KM_i a_i): each rotor's force
  along its own axis at its own position, its drag torque included, summed about B's origin
  (for a rigid base the same as applying them one by one, in two PyBullet calls instead of
  2n). Force and torque are applied in B with LINK_FRAME on the base (for the base,
  LINK_FRAME torque is body-frame). No body wrench the rotors could not make reaches the base.
  PyBullet clears external forces and joint torques after every step, so `step()`
  re-applies the latest command: commands persist until replaced.
* Rotors: with [rotors].time_constant_s > 0 each rotor's thrust lags its command
  (`simulator.actuators`), advanced in `step()`; with 0 the commanded wrench acts at once.
* The wrist sensor on `ft_joint` reports the wrench the parent link exerts on the pad,
  in the pad's inertial (CoM) frame, moment about the pad's CoM. `wrench_ee` turns it
  into the wrench the environment applies on E (see there).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from .bullet import pb

from amcore.config import ScenarioSpec
from amcore.model import AmState

from . import scene
from amcore.allocation import Allocation, WrenchAllocation

from .actuators import JointTorqueResult, RotorLag, limit_joint_torques


class WorldNotConnected(RuntimeError):
    """A method that needs the physics client was called before `connect()` or after `close()`."""


@dataclass(frozen=True)
class ApplyReport:
    """What the flight controller and the joint drivers really applied for one command."""

    mix: WrenchAllocation
    joints: JointTorqueResult

    @property
    def saturated(self) -> bool:
        return self.mix.saturated or self.joints.saturated


@dataclass(frozen=True)
class PadContact:
    """Contact force the object applies ON the pad, summed over the contact points [N, W].

    normal_force_n >= 0 is the magnitude along normal_W (unit, from the object into the
    pad); tangential_force_W is the friction part (perpendicular to normal_W); point_W the
    normal-force-weighted mean contact point on the object [m]. n_points = 0: no contact.
    """

    normal_force_n: float
    normal_W: np.ndarray
    tangential_force_W: np.ndarray
    point_W: np.ndarray
    n_points: int

    @property
    def force_W(self) -> np.ndarray:
        return self.normal_force_n * self.normal_W + self.tangential_force_W


@dataclass(frozen=True)
class AmTruth:
    """Ground truth of one AM: base pose (p_WB [m], R_WB), end-effector pose (p_WE, R_WE),
    the pad-object contact, the names of other bodies the pad or the base touch, and the
    arm's joint origins."""

    p_WB: np.ndarray
    R_WB: np.ndarray
    p_WE: np.ndarray
    R_WE: np.ndarray
    pad_object_contact: PadContact
    pad_other_contacts: tuple[str, ...]
    base_contacts: tuple[str, ...]
    p_W_joints: tuple[np.ndarray, ...] = ()  # arm joint origins, base to wrist [m] (to draw the arm)
    rotor_saturated_steps: int = 0  # commands so far whose rotor mix saturated (cumulative)
    joint_saturated_steps: int = 0  # commands so far with a joint torque clipped (cumulative)
    # commands so far whose roll, pitch, yaw torque or thrust was not met (cumulative, per axis)
    axis_saturated_steps: tuple[int, int, int, int] = (0, 0, 0, 0)
    # the busiest rotor's thrust as a fraction of its range (0: at its least, 1: at its most), now
    rotor_fraction_max: float = 0.0
    rotor_fraction_min: float = 0.0  # the idlest rotor's, likewise
    # what the flight controller reports of the base (simulator.core): p_WB, quat_WB (w, x, y, z),
    # v_B, w_B, its estimator's odometry with [devices]; empty before its first frame
    estimate: tuple[float, ...] = ()


@dataclass(frozen=True)
class ObjectTruth:
    """Object pose and velocity: p_WO [m] (CoM), quat_WO_wxyz, v_WO [m/s] and w_WO [rad/s] in W;
    touching: names of the bodies in contact with it ("table", "ground", "am<sysid>")."""

    p_WO: np.ndarray
    quat_WO_wxyz: np.ndarray
    v_WO: np.ndarray
    w_WO: np.ndarray
    touching: tuple[str, ...]


@dataclass(frozen=True)
class GroundTruth:
    """Everything the simulator knows at one instant (for logging and tests, not controllers)."""

    time_s: float
    step_index: int
    ams: Mapping[int, AmTruth]
    object: ObjectTruth


_NO_CONTACT = PadContact(0.0, np.zeros(3), np.zeros(3), np.zeros(3), 0)


def _R(quat_xyzw) -> np.ndarray:
    """Rotation matrix of a PyBullet (x, y, z, w) quaternion."""
    return np.array(pb.getMatrixFromQuaternion(quat_xyzw)).reshape(3, 3)


def _mv(R, v) -> tuple[float, float, float]:
    """R v for R a row-major 9-sequence (PyBullet's getMatrixFromQuaternion) and a 3-sequence."""
    return (R[0] * v[0] + R[1] * v[1] + R[2] * v[2], R[3] * v[0] + R[4] * v[1] + R[5] * v[2],
            R[6] * v[0] + R[7] * v[1] + R[8] * v[2])


def _mtv(R, v) -> tuple[float, float, float]:
    """R^T v, as `_mv`."""
    return (R[0] * v[0] + R[3] * v[1] + R[6] * v[2], R[1] * v[0] + R[4] * v[1] + R[7] * v[2],
            R[2] * v[0] + R[5] * v[1] + R[8] * v[2])


class World:
    """Physics of one scenario; see the module docstring for the stepping protocol."""

    def __init__(self, spec: ScenarioSpec, initial: Mapping[int, AmState]):
        expected = sorted(a.sysid for a in spec.ams)
        if sorted(initial) != expected:
            raise ValueError(f"initial states given for sysids {sorted(initial)}, scenario has {expected}")
        self.spec = spec
        self._dt_s = spec.dt_s  # the physics step [s], read every step (time_s)
        # PyBullet reports a contact's forces as the last substep's impulse over the whole step
        # (dt_s): times the substeps, they are that substep's forces
        self._contact_scale = float(spec.physics_substeps)
        self._initial = dict(initial)
        self._alloc = Allocation(spec.vehicle.rotors)
        # each rotor's least thrust and range [N], for the busiest/idlest rotor's share in the truth
        self._rotor_ranges = tuple(zip(spec.vehicle.rotors.thrust_min(),
                                       (hi - lo for lo, hi in zip(spec.vehicle.rotors.thrust_min(),
                                                                  spec.vehicle.rotors.thrust_max()))))
        self._tau_q_max = np.array(spec.vehicle.joint_torque_max_nm, dtype=float)
        self._client: int | None = None
        self._ams: dict[int, scene.AmBody] = {}
        self._commands: dict[int, tuple[tuple, tuple, list[float]]] = {}  # applied F_B, tau_B, tau_q
        # saturated commands so far: rotors, joints, then per axis roll, pitch, yaw, thrust
        self._saturated = {a.sysid: [0, 0, 0, 0, 0, 0] for a in spec.ams}
        # lagging rotors (time_constant_s > 0): per AM the lag, the rotor thrust command
        # (None before the first) and the joint torques
        self._lags: dict[int, RotorLag] = {}
        self._rotor_commands: dict[int, list[float] | None] = {}
        self._rotors_now: dict[int, list[float]] = {}  # each AM's rotor thrusts acting now [N]
        self._joint_commands: dict[int, list[float]] = {}
        self._names: dict[int, str] = {}
        self._object_id = -1
        self._step_index = 0
        # per AM, for the per-step paths: link lists as PyBullet takes them, tool CoM weights
        self._arm_ids: dict[int, list[int]] = {}
        self._sensed_links: dict[int, list[int]] = {}
        self._sensed_joints: dict[int, list[int]] = {}  # the arm's joints, then the wrist sensor's
        # `_limited`'s last, per AM: the torques given, their result and its applied torques as a list
        self._last_limited: dict[int, tuple[np.ndarray, JointTorqueResult, list[float]]] = {}
        self._tool_weights: dict[int, tuple[tuple[float, int], ...]] = {}  # per tool link: its mass share, its row

    # ------------------------------------------------------------------ lifecycle
    def connect(self) -> None:
        if self._client is not None:
            raise RuntimeError("World.connect() called twice")
        c = pb.connect(pb.DIRECT)
        if c < 0:
            raise RuntimeError("PyBullet could not start a DIRECT client")
        self._client = c
        # [scenario].physics_substeps: each step's dt_s in n substeps of PyBullet, the forces held
        n_sub = self.spec.physics_substeps
        pb.setPhysicsEngineParameter(fixedTimeStep=self.spec.dt_s, numSubSteps=0 if n_sub == 1 else n_sub,
                                     numSolverIterations=self.spec.solver_iterations,  # [scenario]
                                     deterministicOverlappingPairs=1, physicsClientId=c)
        pb.setGravity(0.0, 0.0, -self.spec.vehicle.gravity_mps2, physicsClientId=c)
        self._names[scene.add_ground(c)] = "ground"
        self._names[scene.add_table(c, self.spec.object)] = "table"
        # The object must exist before the AMs: `_sum_contact` relies on it (friction sign).
        self._object_id = scene.add_object(c, self.spec.object)
        self._names[self._object_id] = "object"
        n = self.spec.vehicle.n_joints
        for a in self.spec.ams:
            am = scene.load_am(c, self.spec.vehicle, friction=scene.pad_lateral_friction(self.spec.object))
            scene.reset_am(c, am, self._initial[a.sysid])
            self._ams[a.sysid] = am
            self._names[am.body_id] = f"am{a.sysid}"
            self._commands[a.sysid] = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), [0.0] * n)
            r = self.spec.vehicle.rotors
            if r.lagging:
                self._lags[a.sysid] = RotorLag(r.time_constants(), self.spec.dt_s, r.count)
                self._rotor_commands[a.sysid] = None
                self._joint_commands[a.sysid] = [0.0] * n
            self._arm_ids[a.sysid] = list(am.arm_joint_ids)
            self._sensed_joints[a.sysid] = [*am.arm_joint_ids, am.ft_joint_id]
            # the pad and the ee marker, then the tool's other links (each link read once)
            links = [am.pad_link_id, am.ee_link_id]
            links += [i for i in am.tool_link_ids if i not in links]
            self._sensed_links[a.sysid] = links
            self._tool_weights[a.sysid] = tuple((m / am.tool_mass_kg, links.index(i))
                                                for i, m in zip(am.tool_link_ids, am.tool_link_masses_kg))
        self._step_index = 0

    def close(self) -> None:
        if self._client is not None:
            pb.disconnect(physicsClientId=self._client)
            self._client = None

    def __enter__(self) -> "World":
        self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _c(self) -> int:
        if self._client is None:
            raise WorldNotConnected("World is not connected: call connect() first")
        return self._client

    def _am(self, sysid: int) -> scene.AmBody:
        self._c()
        try:
            return self._ams[sysid]
        except KeyError:
            raise KeyError(f"no AM with sysid {sysid} (world has {sorted(self._ams)})") from None

    # ------------------------------------------------------------------ time
    @property
    def dt_s(self) -> float:
        return self.spec.dt_s

    @property
    def step_index(self) -> int:
        return self._step_index

    @property
    def time_s(self) -> float:
        return self._step_index * self._dt_s

    @property
    def sysids(self) -> tuple[int, ...]:
        return tuple(a.sysid for a in self.spec.ams)

    def total_mass_kg(self, sysid: int) -> float:
        """Mass of one AM as PyBullet loaded it [kg]."""
        return self._am(sysid).total_mass_kg

    def tool_mass_kg(self, sysid: int) -> float:
        """Mass beyond the wrist sensor (pad and ee marker) that `wrench_ee` compensates [kg]."""
        return self._am(sysid).tool_mass_kg

    # ------------------------------------------------------------------ actuation
    def apply(self, sysid: int, thrust_n: float, tau_B_nm, tau_q_nm) -> ApplyReport:
        """Command total thrust T [N] along +z_B, body torque tau_B [N m] (in B, about the
        base CoM) and joint torques tau_q [N m]. Allocated to the rotors and limited like the
        real vehicle (`amcore.allocation`); what the rotors make (see the report) acts from
        the next `step()` until replaced."""
        self._am(sysid)
        mix = self._alloc.allocate_wrench(float(thrust_n), tau_B_nm)
        joints = limit_joint_torques(tau_q_nm, self._tau_q_max)
        self._count_saturation(sysid, mix.allocation.saturated_axes, joints.saturated)
        if self._lags:  # the rotors go toward the allocated thrusts in step()
            self._rotor_commands[sysid] = list(mix.rotor_thrusts_n)
            self._joint_commands[sysid] = joints.applied_nm.tolist()
        else:
            self._commands[sysid] = (mix.force_B_n, mix.tau_B_nm, joints.applied_nm.tolist())
            self._rotors_now[sysid] = list(mix.rotor_thrusts_n)
        return ApplyReport(mix=mix, joints=joints)

    def apply_rotors(self, sysid: int, rotor_thrusts_n, tau_q_nm,
                     saturated_axes: tuple[bool, bool, bool, bool] = (False, False, False, False)) -> JointTorqueResult:
        """Command each rotor's thrust [N] (the rotor table's order, within the rotor limits: a
        flight controller that allocates itself, and says per axis (roll, pitch, yaw, thrust)
        whether its allocation fell short) and the joint torques [N m] (limited here); they act
        from the next `step()` until replaced. A list of Python floats is kept as given (the
        caller hands it over)."""
        self._am(sysid)
        joints, applied = self._limited(sysid, tau_q_nm)
        if joints.saturated or True in saturated_axes:
            self._count_saturation(sysid, saturated_axes, joints.saturated)
        if type(rotor_thrusts_n) is not list:  # e.g. an array's or a tuple's
            rotor_thrusts_n = [float(x) for x in rotor_thrusts_n]
        if self._lags:
            self._rotor_commands[sysid] = rotor_thrusts_n
            self._joint_commands[sysid] = applied
        else:
            force, tau_B = self._alloc.wrench(rotor_thrusts_n)
            self._commands[sysid] = (force, tau_B, applied)
            self._rotors_now[sysid] = rotor_thrusts_n
        return joints

    def _limited(self, sysid: int, tau_q_nm) -> tuple[JointTorqueResult, list[float]]:
        """`limit_joint_torques` of tau_q_nm and its applied torques as a list; the last again if
        given the same array object (a held setpoint's joint torques, re-applied every physics step)."""
        last = self._last_limited.get(sysid)
        if last is not None and last[0] is tau_q_nm:
            return last[1], last[2]
        joints = limit_joint_torques(tau_q_nm, self._tau_q_max)
        applied = joints.applied_nm.tolist()
        # a frozen setpoint's array (read-only, owning its data: amlink.types) cannot change under us
        if isinstance(tau_q_nm, np.ndarray) and not tau_q_nm.flags.writeable and tau_q_nm.base is None:
            self._last_limited[sysid] = (tau_q_nm, joints, applied)
        return joints, applied

    def _count_saturation(self, sysid: int, axes: tuple[bool, bool, bool, bool], joints: bool) -> None:
        rotors = any(axes)
        if rotors or joints:
            sat = self._saturated[sysid]
            sat[0] += rotors
            sat[1] += joints
            for k, a in enumerate(axes):
                sat[2 + k] += a  # Python bools (amcore.allocation)

    def joint_torques(self, sysid: int) -> list[float]:
        """The joint torques acting on the arm now [N m] (the last command, within the limits;
        zeros before the first)."""
        if self._lags:
            return self._joint_commands[sysid]
        c = self._commands.get(sysid)
        return [0.0] * len(self._tau_q_max) if c is None else c[2]

    def rotor_thrusts(self, sysid: int) -> list[float] | None:
        """The lagging rotors' thrusts [N] after the last step (None: ideal rotors, or no step yet)."""
        lag = self._lags.get(sysid)
        return None if lag is None or lag.thrusts_n is None else list(lag.thrusts_n)

    def step(self) -> None:
        """Apply every AM's latest command (through the rotors' lag) and advance one physics step."""
        c = self._c()
        for sysid, am in self._ams.items():
            if self._lags and self._rotor_commands[sysid] is not None:
                f = self._lags[sysid].step(self._rotor_commands[sysid])
                self._rotors_now[sysid] = f
                force, tau_B = self._alloc.wrench(f)
                tau_q = self._joint_commands[sysid]
            else:
                force, tau_B, tau_q = self._commands[sysid]
            pb.applyExternalForce(am.body_id, -1, force, (0.0, 0.0, 0.0), pb.LINK_FRAME, physicsClientId=c)
            pb.applyExternalTorque(am.body_id, -1, tau_B, pb.LINK_FRAME, physicsClientId=c)
            pb.setJointMotorControlArray(am.body_id, self._arm_ids[sysid], pb.TORQUE_CONTROL, forces=tau_q,
                                         physicsClientId=c)
        pb.stepSimulation(physicsClientId=c)
        self._step_index += 1

    # ------------------------------------------------------------------ sensing
    def state(self, sysid: int) -> AmState:
        """Exact state of one AM (velocities in B, see `amcore.model.AmState`)."""
        c, am = self._c(), self._am(sysid)
        p, _, R, v_B, w_B, q, qdot = self._base_and_joints(c, sysid, am)
        return AmState(p_WB=np.array(p), R_WB=np.array(R).reshape(3, 3), v_B=np.array(v_B), w_B=np.array(w_B),
                       q=np.array(q), qdot=np.array(qdot))

    def attitude_and_rate(self, sysid: int) -> tuple[tuple[float, ...], tuple[float, float, float]]:
        """(quat_WB (w, x, y, z; w >= 0), w_B [rad/s]) on Python floats: what a flight
        controller's attitude estimate and gyro give (here exact)."""
        c, am = self._c(), self._am(sysid)
        _, (x, y, z, w) = pb.getBasePositionAndOrientation(am.body_id, physicsClientId=c)
        _, w_W = pb.getBaseVelocity(am.body_id, physicsClientId=c)
        quat = (w, x, y, z) if w >= 0.0 else (-w, -x, -y, -z)
        return quat, _mtv(pb.getMatrixFromQuaternion((x, y, z, w)), w_W)

    def sensor_values(self, sysid: int) -> list[float]:
        """One sensor frame's values as Python floats: p_WB, quat_WB (w, x, y, z; w >= 0),
        v_B, w_B, q, qdot, wrench_E (the order of `amlink.types.sensor_frame_from_wire`).

        The same quantities as `state` and `wrench_ee` (tests/simulator check it); this is
        the per-step path, where numpy's per-call cost on 3-vectors would dominate.
        """
        c, am = self._c(), self._am(sysid)
        p, quat, R = self._base_pose(c, am)
        v_W, w_W = pb.getBaseVelocity(am.body_id, physicsClientId=c)
        if self._step_index == 0:  # nothing measured yet: no wrench (`wrench_ee`)
            joints = pb.getJointStates(am.body_id, self._arm_ids[sysid], physicsClientId=c)
            wrench = [0.0] * 6
        else:  # the arm's joints and the wrist sensor's joint in one call
            joints = pb.getJointStates(am.body_id, self._sensed_joints[sysid], physicsClientId=c)
            wrench = self._wrench_from(c, sysid, am, joints[-1][2])
            joints = joints[:-1]
        return [*p, *quat, *_mtv(R, v_W), *_mtv(R, w_W), *[j[0] for j in joints], *[j[1] for j in joints], *wrench]

    def flight_values(self, sysid: int) -> list[float]:
        """`sensor_values` without the wrist sensor's wrench: p_WB, quat_WB (w, x, y, z; w >= 0),
        v_B, w_B, q, qdot on Python floats (the free-running simulator's per-step read of the
        base and the joints, simulator.freerun; no F/T read)."""
        c, am = self._c(), self._am(sysid)
        p, quat, _, v_B, w_B, q, qdot = self._base_and_joints(c, sysid, am)
        return [*p, *quat, *v_B, *w_B, *q, *qdot]

    def base_values(self, sysid: int) -> list[float]:
        """The first 13 of `sensor_values` (p_WB, quat_WB, v_B, w_B), the base alone: what an
        IMU and a motion capture see, without the arm's and the wrist sensor's reads."""
        c, am = self._c(), self._am(sysid)
        p, quat, R = self._base_pose(c, am)
        v_W, w_W = pb.getBaseVelocity(am.body_id, physicsClientId=c)
        return [*p, *quat, *_mtv(R, v_W), *_mtv(R, w_W)]

    @staticmethod
    def _base_pose(c: int, am: scene.AmBody):
        """(p_WB, quat_WB (w, x, y, z; w >= 0), R_WB row-major as 9 floats) from PyBullet."""
        p, (x, y, z, w) = pb.getBasePositionAndOrientation(am.body_id, physicsClientId=c)
        R = pb.getMatrixFromQuaternion((x, y, z, w))  # row-major 3x3 as a 9-tuple
        return p, ((w, x, y, z) if w >= 0.0 else (-w, -x, -y, -z)), R

    def _base_and_joints(self, c: int, sysid: int, am: scene.AmBody):
        """(p_WB, quat_WB (w, x, y, z; w >= 0), R_WB row-major as 9 floats, v_B, w_B, q, qdot)
        read from PyBullet, on Python floats."""
        p, quat, R = self._base_pose(c, am)
        v_W, w_W = pb.getBaseVelocity(am.body_id, physicsClientId=c)
        joints = pb.getJointStates(am.body_id, self._arm_ids[sysid], physicsClientId=c)
        return (p, quat, R, _mtv(R, v_W), _mtv(R, w_W), [j[0] for j in joints], [j[1] for j in joints])

    def wrench_ee(self, sysid: int) -> np.ndarray:
        """(6,) [f_E [N]; m_E [N m]]: wrench the environment applies on the end-effector,
        expressed in E, moment about E's origin, as a wrist F/T sensor on ft_joint reports it.

        Like an F/T driver with a known tool, the weight of the tool (pad + ee marker,
        `tool_mass_kg`) is removed. The tool's inertial wrench (0.03 kg times its
        acceleration, plus its tiny rotational inertia terms) is not: it remains as
        sensor error, as on the real sensor (e.g. 0.03 N per 1 m/s^2 of pad acceleration).
        Before the first `step()` nothing has been measured and the result is zero.
        """
        c, am = self._c(), self._am(sysid)
        return np.array(self._wrench_E(c, sysid, am))

    def _wrench_E(self, c: int, sysid: int, am: scene.AmBody) -> list[float]:
        """`wrench_ee` on Python floats. The sensor reports (f_s, m_s), the wrench the wrist
        exerts on the pad, in the pad's inertial frame P, moment about the pad's CoM c_pad.
        Pad and marker quasi-static: f_s + f_env + F_grav = 0, so f_env = -R_WP f_s - F_grav
        with F_grav = (0, 0, -m_tool g) acting at the tool's CoM c_tool; about c_pad,
        m_env = -R_WP m_s - (c_tool - c_pad) x F_grav; then moved to E and turned into E."""
        if self._step_index == 0:
            return [0.0] * 6
        return self._wrench_from(c, sysid, am, pb.getJointState(am.body_id, am.ft_joint_id, physicsClientId=c)[2])

    def _wrench_from(self, c: int, sysid: int, am: scene.AmBody, f_s) -> list[float]:
        """`_wrench_E` from the wrist sensor's reading f_s (its joint's reaction forces)."""
        links = pb.getLinkStates(am.body_id, self._sensed_links[sysid], computeForwardKinematics=1, physicsClientId=c)
        pad, ee = links[0], links[1]
        RP = pb.getMatrixFromQuaternion(pad[1])  # pad's inertial frame: the sensor's frame
        RE = pb.getMatrixFromQuaternion(ee[5])  # ee URDF link frame {E}
        cx, cy, cz = pad[0]
        ex, ey, ez = ee[4]
        tx = ty = tz = 0.0  # tool CoM: mass-weighted mean of the tool links' CoMs
        for wgt, i in self._tool_weights[sysid]:
            lx, ly, lz = links[i][0]
            tx, ty, tz = tx + wgt * lx, ty + wgt * ly, tz + wgt * lz
        mg = am.tool_mass_kg * self.spec.vehicle.gravity_mps2  # F_grav = (0, 0, -mg)
        fx, fy, fz = _mv(RP, f_s[0:3])
        f_env = (-fx, -fy, mg - fz)
        mx, my, mz = _mv(RP, f_s[3:6])
        # -(c_tool - c_pad) x (0, 0, -mg) = mg ((ty - cy), -(tx - cx), 0)
        m_env = (-mx + mg * (ty - cy), -my - mg * (tx - cx), -mz)
        rx, ry, rz = cx - ex, cy - ey, cz - ez  # + (c_pad - p_WE) x f_env
        m_E = (m_env[0] + ry * f_env[2] - rz * f_env[1], m_env[1] + rz * f_env[0] - rx * f_env[2],
               m_env[2] + rx * f_env[1] - ry * f_env[0])
        return [*_mtv(RE, f_env), *_mtv(RE, m_E)]

    def object_pose(self) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """The object's pose now: p_W [m] and q_W (w, x, y, z)."""
        p, (x, y, z, w) = pb.getBasePositionAndOrientation(self._object_id, physicsClientId=self._c())
        return tuple(p), (w, x, y, z)

    def ground_truth(self) -> GroundTruth:
        c = self._c()
        ams = {sysid: self._am_truth(am, self._saturated[sysid], self._rotors_now.get(sysid))
               for sysid, am in self._ams.items()}
        p, quat = pb.getBasePositionAndOrientation(self._object_id, physicsClientId=c)
        v, w = pb.getBaseVelocity(self._object_id, physicsClientId=c)
        x, y, z, qw = quat
        touching = pb.getContactPoints(bodyA=self._object_id, physicsClientId=c)
        obj = ObjectTruth(p_WO=np.array(p), quat_WO_wxyz=np.array([qw, x, y, z]), v_WO=np.array(v), w_WO=np.array(w),
                          touching=self._names_of(pt[2] for pt in touching))
        return GroundTruth(time_s=self.time_s, step_index=self.step_index, ams=ams, object=obj)

    def _am_truth(self, am: scene.AmBody, saturated=(0, 0, 0, 0, 0, 0), rotors_n=None) -> AmTruth:
        c = self._c()
        p, quat = pb.getBasePositionAndOrientation(am.body_id, physicsClientId=c)
        ee = pb.getLinkState(am.body_id, am.ee_link_id, computeForwardKinematics=1, physicsClientId=c)
        joints = pb.getLinkStates(am.body_id, list(am.arm_joint_ids), computeForwardKinematics=1, physicsClientId=c)
        pad_points = pb.getContactPoints(bodyA=am.body_id, linkIndexA=am.pad_link_id, physicsClientId=c)
        base_points = pb.getContactPoints(bodyA=am.body_id, linkIndexA=-1, physicsClientId=c)
        on_object = pb.getContactPoints(bodyA=self._object_id, bodyB=am.body_id, linkIndexB=am.pad_link_id,
                                        physicsClientId=c)
        return AmTruth(p_WB=np.array(p), R_WB=_R(quat), p_WE=np.array(ee[4]), R_WE=_R(ee[5]),
                       pad_object_contact=_sum_contact(on_object, self._contact_scale),
                       pad_other_contacts=self._names_of(pt[2] for pt in pad_points if pt[2] != self._object_id),
                       base_contacts=self._names_of(pt[2] for pt in base_points),
                       p_W_joints=tuple(np.array(j[4]) for j in joints),
                       rotor_saturated_steps=saturated[0], joint_saturated_steps=saturated[1],
                       axis_saturated_steps=tuple(saturated[2:6]),
                       **self._rotor_fractions(rotors_n))

    def _rotor_fractions(self, rotors_n) -> dict[str, float]:
        """The busiest and the idlest rotor's thrust as a fraction of its range (0.0 before any command)."""
        if rotors_n is None:
            return {}
        x = [(f - lo) / span for f, (lo, span) in zip(rotors_n, self._rotor_ranges)]
        return {"rotor_fraction_max": max(x), "rotor_fraction_min": min(x)}

    def _names_of(self, body_ids) -> tuple[str, ...]:
        return tuple(sorted({self._names.get(b, f"body{b}") for b in body_ids}))


def _friction_sign_on_A(pt) -> float:
    """+1 if a contact point's friction pair is the force on the query's body A, -1 if on B
    (see `_sum_contact`): the sign of (dir1 x dir2) . contactNormalOnB."""
    (ax, ay, az), (bx, by, bz) = pt[11], pt[13]
    n_manifold = np.array((ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx))  # np.cross's products, on floats
    return 1.0 if float(n_manifold @ np.asarray(pt[7])) >= 0.0 else -1.0


def _sum_contact(points, scale: float = 1.0) -> PadContact:
    """Sum PyBullet contact points between the object (body A) and a pad (body B) into the
    force the object applies on the pad; each point's forces times `scale` (the physics
    substeps: PyBullet divides the last substep's impulse by the whole step).

    Verified conventions (tests/simulator/test_world_sensors.py, the squeeze tests with every
    pad shape): contactNormalOnB points from B into A and A receives +normalForce along it;
    PyBullet swaps the normal when the query names the bodies the other way round. The
    friction pair (lateralFriction_k, lateralFrictionDir_k) is the force on the FIRST body of
    Bullet's internal contact manifold, which PyBullet does not swap, and which body comes
    first depends on the shapes' collision algorithm (the object for a flat pad's box, the pad
    for a crowned pad's cylinder). The manifold's own normal tells: Bullet builds the friction
    directions with btPlaneSpace1(n), so dir2 = n x dir1 and n = dir1 x dir2. Where that n
    agrees with contactNormalOnB the manifold's first body is A (the object); where it is
    opposed, it is B (the pad). The pad gets the opposite of A's force.
    """
    if not points:
        return _NO_CONTACT
    # the sums element by element on Python floats (numpy's 3-vector operations would round
    # each element alike, at ~1 us a call); norms and dot products below stay numpy's (BLAS)
    F_n = [0.0, 0.0, 0.0]  # on the pad
    F_t = [0.0, 0.0, 0.0]
    weighted_point = [0.0, 0.0, 0.0]
    total_normal = 0.0
    for pt in points:
        f_n, n, f1, d1, f2, d2, p = scale * pt[9], pt[7], scale * pt[10], pt[11], scale * pt[12], pt[13], pt[5]
        sign = _friction_sign_on_A(pt)
        for i in range(3):
            F_n[i] -= f_n * n[i]
            F_t[i] -= sign * (f1 * d1[i] + f2 * d2[i])
            weighted_point[i] += f_n * p[i]
        total_normal += f_n
    F_n, F_t, weighted_point = np.array(F_n), np.array(F_t), np.array(weighted_point)
    magnitude = float(np.linalg.norm(F_n))
    normal = F_n / magnitude if magnitude > 0.0 else -np.array(points[0][7])
    F_t = F_t - (F_t @ normal) * normal
    point = weighted_point / total_normal if total_normal > 0.0 else np.mean([pt[5] for pt in points], axis=0)
    return PadContact(normal_force_n=magnitude, normal_W=normal, tangential_force_W=F_t, point_W=point,
                      n_points=len(points))
