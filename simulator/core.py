"""The simulator's per-step work, independent of how setpoints travel (no sockets).

`SitlCore` owns the PyBullet world, each AM's flight-controller emulation (the link as the
flight controller sees it, `amlink.impair`; in attitude mode the emulated autopilot,
`simulator.flight_controller`; the failsafe after companion loss, `simulator.failsafe`),
the ground-truth outcome and a digest of every state sent. One schedule drives it for the UDP
simulator main and the in-process runner (`sitl.inprocess`) alike, `simulator.lockstep`, once per
physics step k:

    if core.is_control_step(k):              # every step, or every rate_hz / control_rate_hz
        frames = core.frames(k)              # sensor frames of step k, one per AM
        <send them>; core.observe()          # bookkeeping while the companions compute
        setpoints = <the companions answer>  # dict sysid -> TorqueSetpoint (torque mode) or
                                             # AttitudeSetpoint (attitude mode); some may miss
                                             # (core.on_setpoint(sysid, sp) as each arrives)
        core.actuate(k, setpoints, lost)     # flight controllers apply them (or failsafe)
    else:
        core.hold(k, lost)                   # flight controllers fly on what they hold
    core.step()

With [flight_controller].actuation_delay_steps = d > 0 a setpoint acts d physics steps after
its frame (the first control step's at once), and a runner steps those d steps while the
companions compute:

    if core.is_control_step(k):
        frames = core.frames(k)
        if k == 0 or d == 0: <as above>
        else:
            core.actuate(k, <the answers to step k - d's frames if core.due(k), else {}>, lost)
            <send frames>                      # their answers act at step k + d
    elif core.due(k):
        core.hold(k, lost, <the answers to step k - d's frames>)
    else:
        core.hold(k, lost)

A setpoint refused as implausible is answered at once, by one policy for every runner:
the caller reports it with `core.note_rejected(sysid, why)` before `actuate`, and leaves it
out of `setpoints`; the flight controller keeps flying its last valid command (zero-order
hold), and after K refusals in a row ([flight_controller].failsafe_after_rejected) the
vehicle goes to its failsafe for the rest of the run (its companion is no longer trusted).

Beyond the companions, a GCS can command each flight controller between steps (`arm`,
`disarm`, `land`; `simulator.commands`), and `snapshot` says what each one reports. Once a
GCS command rules a vehicle (landing, disarmed), its companion's setpoints are ignored and
counted (`ignored_setpoints`), never judged: one that would be implausible is not a refusal.
The verdict names the command as the run's cause (`commanded`).
"""
from __future__ import annotations

import dataclasses
import hashlib
from array import array
from collections.abc import Callable, Collection, Iterator, Mapping

import numpy as np

from amcore.config import AmSpec, DevicesSpec, JointEffortSpec, ScenarioSpec
from amcore.mission import ObjectPose, am_mission
from amcore.model import AmState, build_model
from amcore.so3 import Rz
from amlink.impair import ImpairedLink, LinkImpairment
from amlink.types import (AttitudeSetpoint, AttitudeTarget, SensorFrame, TorqueSetpoint, sensor_frame_from_wire,
                          with_autopilot_reports)

from .failsafe import Failsafe, FailsafeGains
from .fcstate import FcMode, FleetSnapshot, VehicleSnapshot
from .flight_controller import FlightController
from .object_mocap import measure_object
from .outcome import RunOutcome
from .devices import DeviceSuite
from .effort import JointEffortSensor
from .sensors import SensorModel
from .verdict import judge
from .world import World

Setpoint = TorqueSetpoint | AttitudeSetpoint

TRUTH_PERIOD_S = 0.01  # ground-truth sample period for the outcome and telemetry [s]: every 10 steps at 1 kHz


def truth_every(rate_hz: float) -> int:
    """Physics steps between two ground-truth samples at `rate_hz` (every TRUTH_PERIOD_S)."""
    return max(1, round(TRUTH_PERIOD_S * rate_hz))


LAND_NOW = FailsafeGains(hold_s=0.0)  # a commanded landing: the failsafe's landing, without the hold
_FAILSAFE_MODE = {"hold": FcMode.HOLD, "land": FcMode.LAND, "landed": FcMode.LANDED}


def initial_state(spec: ScenarioSpec, am: AmSpec, model, object_pose: ObjectPose | None = None) -> AmState:
    """Where a vehicle starts: its mission's start (at rest, level, nominal arm pose; planned from
    `object_pose`, None: the config's), moved by its [[am]] start_offset_m and turned by
    start_heading_deg about z (references unchanged)."""
    x = am_mission(spec, am, model, object_pose).initial_state()
    if am.start_offset_m == (0.0, 0.0, 0.0) and am.start_heading_deg == 0.0:
        return x
    return x._replace(p_WB=x.p_WB + np.array(am.start_offset_m),
                      R_WB=Rz(np.deg2rad(am.start_heading_deg)) @ x.R_WB)


def warm_up_kernels(spec: ScenarioSpec) -> None:
    """One call of each of the simulator's compiled kernels (the autopilot's loops and
    allocation, the devices) with a run's argument types, so that numba compiles them (once
    per machine, a few seconds) or loads them from its cache here, before a lockstep starts,
    not at a run's first steps."""
    v = spec.vehicle
    n = v.n_joints
    target = AttitudeTarget(0, quat_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), rates_rad_s=np.zeros(3),
                            thrust_normalized=0.5)
    FlightController(v.flight_controller, v.rotors, spec.dt_s).step((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), target)
    values = [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0] + [0.0] * (6 + 2 * n + 6)
    dev = DeviceSuite(DevicesSpec(enabled=True), n, spec.dt_s, v.gravity_mps2, 0, 2, values)
    dev.step(values, 0.0)
    if not dev.needs_reading(spec.dt_s):
        dev.step(values[:13], spec.dt_s)


def kernel_group(spec: ScenarioSpec):
    """`warm_up_kernels(spec)` as a group of `amruntime.jitcache.warm_groups`: under a lock
    of its own, so that a process can compile these while another compiles the control law."""
    from amcore import allocation_kernels, estimator
    from amruntime.jitcache import SIMULATOR_LOCK, Group

    from . import device_kernels, fc_kernels
    return Group(SIMULATOR_LOCK, (fc_kernels, allocation_kernels, device_kernels, estimator),
                 lambda: warm_up_kernels(spec))


class SitlCore:
    def __init__(self, spec: ScenarioSpec, log: Callable[[str], None] = lambda _msg: None,
                 on_truth: Callable[[object], None] | None = None,
                 failsafe_after_rejected: int | None = None,
                 initial: Mapping[int, AmState] | None = None) -> None:
        """failsafe_after_rejected: K of the rejection policy (module docstring); None: the
        scenario's [flight_controller].failsafe_after_rejected. initial: each vehicle's start
        (sysid -> state; None: `initial_state`, the mission's start; the free-running
        simulator starts them on the ground, simulator.freerun)."""
        self.spec, self.log, self.on_truth = spec, log, on_truth
        self._truth_every = truth_every(spec.rate_hz)
        K = spec.vehicle.flight_controller.failsafe_after_rejected if failsafe_after_rejected is None \
            else failsafe_after_rejected
        if not (isinstance(K, int) and K >= 1):
            raise ValueError(f"failsafe_after_rejected must be an integer >= 1, got {K!r}")
        self.failsafe_after_rejected = K
        self.model = build_model(spec.vehicle)
        self.sysids = [am.sysid for am in spec.ams]
        # [mission].object_pose = "mocap": the team plans from the motion capture's first frame of the
        # object, and each vehicle starts where its plan starts (it has flown there before the run)
        self.object_pose = measure_object(spec) if spec.mission.object_pose == "mocap" else None
        self.world = World(spec, dict(initial) if initial is not None else
                           {am.sysid: initial_state(spec, am, self.model, self.object_pose) for am in spec.ams})
        self._phase = am_mission(spec, spec.ams[0], self.model).phase  # the phases are timed alike for every AM
        ms = spec.mission
        self.outcome = RunOutcome(self.sysids, (ms.grasp_end_s + ms.lift_move_s + 1.0, ms.hover_end_s),
                                  slip_from_s=ms.grasp_end_s)
        self.fc_links = {am.sysid: ImpairedLink(LinkImpairment.for_scenario(
            dataclasses.replace(spec, link=am.link or spec.link)), stream=am.sysid) for am in spec.ams}
        # [link].joints = "servo_bus": the arm's torques reach its servos on the companion's own bus,
        # untouched by the link's impairment: the last ones computed act (zero-order hold)
        self._joints_on_bus = {am.sysid for am in spec.ams if (am.link or spec.link).joints == "servo_bus"}
        self._bus_torques: dict[int, np.ndarray] = {}
        self.sensors = {} if spec.sensors.exact else {
            am.sysid: SensorModel(spec.sensors, self.model.n, spec.control_dt_s, spec.seed, am.sysid) for am in spec.ams}
        # [devices]: each AM's sensors and estimator, sampled every physics step (made at the first)
        self.devices: dict[int, DeviceSuite] = {}
        self._odometry: dict[int, list[float]] = {}  # the estimator's last values, per AM (odometry first)
        self._reported: dict[int, list[float]] = {}  # the last frame's base state, per AM (telemetry)
        self.failsafes: dict[int, Failsafe] = {}  # companion lost
        self.landing: dict[int, Failsafe] = {}  # landing on a GCS command (companion ignored)
        self.disarmed: set[int] = set()  # disarmed by a GCS command: motors off, joints limp
        self._overridden: set[int] = set()  # landing or disarmed: setpoints are not applied
        self.ignored_setpoints: dict[int, int] = {s: 0 for s in self.sysids}  # arrived while a GCS command ruled
        self.commanded: list[tuple[float, int, str]] = []  # (t, sysid, what) of GCS commands that took the vehicle
        v = spec.vehicle
        self.mode = v.flight_controller.mode
        self._kind = AttitudeSetpoint if self.mode == "attitude" else TorqueSetpoint  # what the autopilot takes
        self.fcs: dict[int, FlightController] = {}  # attitude mode: each AM's emulated autopilot
        self.efforts: dict[int, JointEffortSensor] = {}  # attitude mode: the servos' measured joint torques
        if self.mode == "attitude":
            self.fcs = {s: FlightController(v.flight_controller, v.rotors, spec.dt_s) for s in self.sysids}
            dv = spec.devices  # without [devices] the servos report the applied torques exactly
            effort, scale = (dv.effort, dv.scale) if dv.enabled else (JointEffortSpec(), 0.0)
            self.efforts = {s: JointEffortSensor(effort, scale, self.model.n, spec.dt_s, spec.seed, s)
                            for s in self.sysids}
        # offboard loss (PX4's COM_OF_LOSS_T): no setpoint for more than this many physics steps
        self.offboard_loss_steps = round(v.flight_controller.COM_OF_LOSS_T * spec.rate_hz)
        self.offboard_lost: set[int] = set()  # in failsafe after the setpoint stream stopped, for good
        self.control_every = spec.control_every
        # [flight_controller].actuation_delay_steps: the answer to step k's frames acts from step
        # k + d (the first control step's at once); the runners step physics meanwhile
        self.actuation_delay = v.flight_controller.actuation_delay_steps
        self.wrong_kind: dict[int, int] = {s: 0 for s in self.sysids}  # setpoints of the other mode, ignored
        self.events: list[dict] = []
        self.rejected: list[tuple[float, int, str]] = []  # (t, sysid, why) of setpoints refused as implausible
        self.rejected_in_a_row: dict[int, int] = {s: 0 for s in self.sysids}
        self.distrusted: set[int] = set()  # in failsafe after K rejected setpoints in a row, for good
        self.controller_errors: list[tuple[float, int, str]] = []  # (t, sysid, what): controllers that raised
        self.digest = hashlib.sha256()
        self._unobserved: tuple | None = None  # (k, values, frames) of `frames` awaiting `observe`
        self._k, self._actuated = -1, set()  # step of the last frames; AMs actuated on arrival
        self._values: dict[int, list[float]] = {}  # the last frames' values and time (`snapshot`)
        self._values_t = 0.0

    def connect(self) -> None:
        warm_up_kernels(self.spec)
        self.world.connect()

    def close(self) -> None:
        self.world.close()

    @property
    def time_s(self) -> float:
        return self.world.time_s

    def is_control_step(self, k: int) -> bool:
        """Whether physics step k exchanges frames and setpoints with the companions."""
        return k % self.control_every == 0

    def due(self, k: int) -> bool:
        """Whether the answers to an earlier control step's frames act at physics step k
        (actuation_delay_steps d > 0: step k - d's, unless that was step 0, whose acted at once)."""
        d = self.actuation_delay
        return d > 0 and k - d > 0 and (k - d) % self.control_every == 0

    def frames(self, k: int) -> dict[int, SensorFrame]:
        """Step k's sensor frames (exact state, wrist F/T reading). Their bookkeeping (the
        digest, ground truth every TRUTH_PERIOD_S) is left to `observe`, so that a caller
        can send the frames first; `actuate` runs it if the caller did not."""
        return dict(self.iter_frames(k))

    def iter_frames(self, k: int) -> Iterator[tuple[int, SensorFrame]]:
        """`frames` one AM at a time, so that a caller can send each frame as soon as it is
        read (that companion computes while the next frame is read). Consume it whole."""
        w, t = self.world, self.world.time_s
        n = self.model.n
        values, out = {}, {}
        self._k, self._actuated = k, set()
        for s in self.sysids:
            values[s] = v = w.sensor_values(s)
            if self.spec.devices.enabled:
                reported = self._sense(s, v, t)
            else:
                sensor = self.sensors.get(s)  # none: exact frames
                reported = v if sensor is None else sensor(v)
            f = sensor_frame_from_wire(k, t, reported, n, 0)
            if self.efforts:  # attitude mode: what the autopilot flies and the servos measure
                f = with_autopilot_reports(f, self.efforts[s].last, self.flown_target(s))
            out[s] = f
            self._reported[s] = reported
            yield s, f
        self._unobserved = (k, values, out)
        self._values, self._values_t = values, t

    @property
    def exact_values(self) -> dict[int, list[float]]:
        """The exact values (`World.sensor_values`) behind the last frames, per sysid."""
        return self._values

    def _sense(self, s: int, values: list[float], t: float) -> list[float]:
        """One physics step of AM s's devices and estimator ([devices]): the frame's values."""
        dev = self.devices.get(s)
        if dev is None:
            sp = self.spec
            dev = self.devices[s] = DeviceSuite(sp.devices, self.model.n, sp.dt_s, sp.vehicle.gravity_mps2,
                                                sp.seed, s, values)
        self._odometry[s] = out = dev.step(values, t)
        return out

    def flown_target(self, s: int):
        """The attitude target AM s's autopilot is flying (its ATTITUDE_TARGET report), or None:
        none yet, or its failsafe (or a GCS command) flies the vehicle."""
        if s in self.failsafes or s in self._overridden or s in self.distrusted or s in self.offboard_lost:
            return None
        sp = self.fc_links[s].hold.command
        return None if sp is None else sp.attitude

    def observe(self) -> None:
        """Bookkeeping of the last `frames` call (once): every frame into the state digest, and
        every TRUTH_PERIOD_S a ground-truth sample for the outcome and `on_truth`."""
        if self._unobserved is None:
            return
        k, values, frames = self._unobserved
        self._unobserved = None
        for s in self.sysids:
            self.digest.update(array("d", values[s]).tobytes())
        if k % self._truth_every == 0:
            self._truth({s: f.wrench_E for s, f in frames.items()})

    def _truth(self, wrench_E: dict) -> None:
        gt = self.world.ground_truth()
        self.outcome.add(gt, wrench_E)
        if self.on_truth is not None:
            if self._reported:  # the reported base state beside the truth (telemetry)
                gt = dataclasses.replace(gt, ams={s: dataclasses.replace(a, estimate=tuple(self._reported[s][:13]))
                                                  if s in self._reported else a for s, a in gt.ams.items()})
            self.on_truth(gt)

    def hold(self, k: int, lost: Collection[int] = (), setpoints: Mapping[int, Setpoint] | None = None) -> None:
        """Physics step k between control steps: no frames; each flight controller flies on
        what it holds (its failsafe while its companion is lost), or on `setpoints` that act
        now (an actuation delay, `due`), and ground truth is sampled as on control steps."""
        self.observe()
        if self.spec.devices.enabled:  # the devices and the estimator run at the IMU rate
            t, w = self.world.time_s, self.world
            for s in self.sysids:  # no frame: the base alone, unless the F/T tare reads the wrist
                dev = self.devices.get(s)
                self._sense(s, w.sensor_values(s) if dev is None or dev.needs_reading(t) else w.base_values(s), t)
        if k % self._truth_every == 0:
            self._truth({s: self.world.wrench_ee(s) for s in self.sysids})
        self.actuate(k, setpoints or {}, lost)

    def on_setpoint(self, sysid: int, setpoint: Setpoint) -> None:
        """A setpoint answering the last frames, as it arrives: its flight controller applies
        it now, while the other companions still compute (`actuate` then skips this AM).
        One of a vehicle in failsafe is left to `actuate`, which ends the failsafe."""
        if sysid in self.failsafes or sysid in self._actuated or sysid in self._overridden or sysid in self.distrusted:
            return
        self._actuated.add(sysid)
        self._apply(self._k, sysid, setpoint)

    def actuate(self, k: int, setpoints: Mapping[int, Setpoint], lost: Collection[int] = ()) -> None:
        """Each flight controller applies what reached it (zero-order hold), or its failsafe
        while its companion is lost; a companion that answers again takes over again."""
        self.observe()
        w, t = self.world, self.world.time_s
        done, self._actuated = (self._actuated if self._k == k else set()), set()
        for s in self.sysids:
            if s in done:  # applied on arrival (on_setpoint)
                continue
            if s in self._overridden:  # a GCS command rules this flight controller
                if s in setpoints:
                    self.ignored_setpoints[s] += 1
                if s in self.disarmed:
                    w.apply(s, 0.0, np.zeros(3), np.zeros(self.model.n))
                else:
                    c = self.landing[s].command(t, w.state(s))
                    w.apply(s, c.thrust_n, c.tau_B_nm, c.tau_q_nm)
                continue
            if s in lost or s in self.distrusted or s in self.offboard_lost or (s in self.failsafes and s not in setpoints):
                if s not in self.failsafes:
                    self.failsafes[s] = Failsafe(self.model, w.state(s), t)
                    if s not in self.distrusted:  # distrusted: said by note_rejected
                        self.events.append({"t": t, "sysid": s, "event": "lost", "failsafe": "hold, then land"})
                        self.log(f"t={t:.3f} s sysid {s}: companion silent; flight controller failsafe: hold, then land")
                c = self.failsafes[s].command(t, w.state(s))
                w.apply(s, c.thrust_n, c.tau_B_nm, c.tau_q_nm)
                continue
            if s in self.failsafes:
                del self.failsafes[s]
                if s in self.fcs:  # the autopilot's loops start afresh from the failsafe's flight
                    v = self.spec.vehicle
                    self.fcs[s] = FlightController(v.flight_controller, v.rotors, self.spec.dt_s)
                self.events.append({"t": t, "sysid": s, "event": "rejoined"})
                self.log(f"t={t:.3f} s sysid {s}: companion back, failsafe ended")
            self._apply(k, s, setpoints.get(s))

    def _apply(self, k: int, s: int, setpoint: Setpoint | None) -> None:
        """The flight controller of `s` at step k: what its link delivers (zero-order hold);
        in attitude mode the emulated autopilot flies the held target. A setpoint of the other
        mode is ignored (a stock autopilot takes no body torques), counted and logged once."""
        if setpoint is not None and not isinstance(setpoint, self._kind):
            self.wrong_kind[s] += 1
            if self.wrong_kind[s] == 1:
                self.log(f"t={self.world.time_s:.3f} s sysid {s}: ignored a {type(setpoint).__name__} in "
                         f"{self.mode} mode; counted in outcome.json, further ones not printed")
            setpoint = None
        if setpoint is not None:
            self.rejected_in_a_row[s] = 0
            if s in self._joints_on_bus:
                self._bus_torques[s] = setpoint.tau_q_nm
        link = self.fc_links[s]
        sp = link.step(k, setpoint)
        if sp is None:  # nothing has reached this flight controller yet: keep the last command
            return
        tau_q = self._bus_torques.get(s, sp.tau_q_nm)  # the servo bus's (or, [link].joints = "link", the link's)
        if link.silent_for(k) > self.offboard_loss_steps:
            self._offboard_lost(s, link.silent_for(k))
            return
        if self.fcs:
            odo = self._odometry.get(s)  # [devices]: the autopilot flies on its estimator's attitude
            quat, w_B = self.world.attitude_and_rate(s) if odo is None else (odo[3:7],
                                                                             self.devices[s].autopilot_rate.tolist())
            out = self.fcs[s].step(quat, w_B, sp.attitude)
            axes = out.allocation.saturated_axes
            joints = self.world.apply_rotors(s, out.rotor_thrusts_n, tau_q, axes)
            rotors_saturated, joints_saturated = out.allocation.saturated, joints.saturated
        else:
            rep = self.world.apply(s, sp.thrust_n, sp.tau_B_nm, tau_q)
            axes = rep.mix.allocation.saturated_axes
            rotors_saturated, joints_saturated = rep.mix.saturated, rep.joints.saturated
        if rotors_saturated or joints_saturated:
            t = self.world.time_s
            if self.outcome.saturation(s, t, rotors_saturated, joints_saturated, axes):
                self.log(f"t={t:.3f} s sysid {s}: command saturated ({_describe(sp)}); counted in outcome.json, "
                         f"further ones not printed")

    def note_rejected(self, sysid: int, why: str) -> None:
        """A setpoint of `sysid` answering the current step was refused as implausible: counted;
        its flight controller holds the last valid command (the caller leaves the setpoint out
        of `actuate`), or, the K-th refusal in a row, goes to failsafe for the rest of the run."""
        if sysid in self._overridden:  # a GCS command rules: ignored, as every setpoint now
            self.ignored_setpoints[sysid] += 1
            return
        t = self.time_s
        if len(self.rejected) < 1000:
            self.rejected.append((t, sysid, why))
        else:  # keep the count, not every reason
            self.rejected.append(self.rejected[-1])
        self.rejected_in_a_row[sysid] += 1
        if self.rejected_in_a_row[sysid] < self.failsafe_after_rejected or sysid in self.distrusted:
            return
        self.distrusted.add(sysid)  # `actuate` engages the failsafe (unless a GCS command rules)
        K = self.failsafe_after_rejected
        self.events.append({"t": t, "sysid": sysid, "event": "rejected", "in_a_row": K,
                            "failsafe": "hold, then land"})
        self.log(f"t={t:.3f} s sysid {sysid}: {K} setpoints in a row rejected as implausible (last: {why}); "
                 f"flight controller failsafe: hold, then land, for the rest of the run")

    def _offboard_lost(self, s: int, steps: int) -> None:
        """No setpoint reached AM s's flight controller for more than COM_OF_LOSS_T: it leaves
        offboard for its failsafe (hold, then land), as PX4 does, for the rest of the run."""
        t = self.world.time_s
        self.offboard_lost.add(s)
        self.failsafes[s] = Failsafe(self.model, self.world.state(s), t)
        c = self.failsafes[s].command(t, self.world.state(s))
        self.world.apply(s, c.thrust_n, c.tau_B_nm, c.tau_q_nm)
        self.events.append({"t": t, "sysid": s, "event": "offboard lost", "silent_s": steps * self.spec.dt_s,
                            "failsafe": "hold, then land"})
        self.log(f"t={t:.3f} s sysid {s}: no setpoint for {steps * self.spec.dt_s:.3f} s (COM_OF_LOSS_T); "
                 f"flight controller failsafe: hold, then land, for the rest of the run")

    def note_controller_error(self, sysid: int, what: str) -> None:
        """The controller of `sysid` raised instead of answering (in-process runs)."""
        self.controller_errors.append((self.time_s, sysid, what))

    def step(self) -> None:
        for s, sensor in self.efforts.items():  # the torque acting over this step, as the servo reads it
            sensor.advance(self.world.joint_torques(s))  # its reading formed when a frame reads it
        self.world.step()

    # -- flight-controller commands (from the GCS) and state ---------------------------
    def land(self, s: int, by: str = "GCS") -> None:
        """Land vehicle `s` with the failsafe's landing, without its hold (arm compliant, motors
        off on the ground); its companion's setpoints are ignored from now on."""
        if s in self.landing:
            return
        t = self.world.time_s
        self.landing[s] = Failsafe(self.model, self.world.state(s), t, LAND_NOW)
        self.failsafes.pop(s, None)
        self._overridden.add(s)
        self.commanded.append((t, s, "abort" if by == "mission abort" else "land"))
        self.events.append({"t": t, "sysid": s, "event": "land", "by": by})
        self.log(f"t={t:.3f} s sysid {s}: landing ({by} command)")

    def disarm(self, s: int, force: bool = False, by: str = "GCS") -> bool:
        """Motors off and joints limp; refused (False) in the air unless `force`."""
        if s in self.disarmed:
            return True
        if not force and self.fc_mode(s) != FcMode.LANDED:
            return False
        t = self.world.time_s
        if force and self.fc_mode(s) != FcMode.LANDED:
            self.commanded.append((t, s, "disarm"))
        self.disarmed.add(s)
        self._overridden.add(s)
        self.events.append({"t": t, "sysid": s, "event": "disarmed", "by": by, "forced": force})
        self.log(f"t={t:.3f} s sysid {s}: disarmed ({by} command{', forced' if force else ''})")
        return True

    def arm(self, s: int, by: str = "GCS") -> None:
        """Undo a disarm; the flight controller applies its companion's setpoints (or keeps landing)."""
        if s not in self.disarmed:
            return
        t = self.world.time_s
        self.disarmed.discard(s)
        if s not in self.landing:
            self._overridden.discard(s)
        self.events.append({"t": t, "sysid": s, "event": "armed", "by": by})
        self.log(f"t={t:.3f} s sysid {s}: armed ({by} command)")

    def fc_mode(self, s: int) -> FcMode:
        fs = self.landing.get(s) or self.failsafes.get(s)
        if fs is not None:
            return _FAILSAFE_MODE[fs.mode]
        return FcMode.OFFBOARD if self._k >= 0 else FcMode.STANDBY

    def snapshot(self, armed: Mapping[int, bool]) -> FleetSnapshot:
        """What every flight controller reports now (`armed`: who its companion has armed).
        Reads the last frames' values; before the first frame, the world's."""
        t = self._values_t if self._values else self.world.time_s
        vehicles = []
        for s in self.sysids:
            v = self._values.get(s) or self.world.sensor_values(s)
            mode = self.fc_mode(s)
            vehicles.append(VehicleSnapshot(
                sysid=s, p_WB=tuple(v[0:3]), quat_WB_wxyz=tuple(v[3:7]), v_B=tuple(v[7:10]), w_B=tuple(v[10:13]),
                mode=mode, armed=armed.get(s, False) and s not in self.disarmed and mode != FcMode.LANDED,
                failsafe=s in self.failsafes and s not in self.landing))
        return FleetSnapshot(time_s=t, phase=self._phase(t) if self._k >= 0 else "", vehicles=tuple(vehicles))

    def finish(self) -> dict:
        """Final ground-truth sample; the outcome as a dict."""
        self.observe()
        w = self.world
        self.outcome.add(w.ground_truth(), {s: w.wrench_ee(s) for s in self.sysids})
        v = judge(self.outcome, self.spec.success, w.step_index, self.failsafes, self.rejected, self.controller_errors,
                  self.commanded)
        return {"state_digest": self.digest.hexdigest(), "verdict": v.to_dict(), "events": self.events,
                "rejected_setpoints": len(self.rejected), "failsafe_after_rejected": self.failsafe_after_rejected,
                "ignored_setpoints": {str(s): n for s, n in self.ignored_setpoints.items()},
                "distrusted": sorted(self.distrusted), "offboard_lost": sorted(self.offboard_lost),
                "flight_controller": self.mode, "control_every": self.control_every,
                "failsafe_at_end": sorted(self.failsafes),
                "fc_link": {str(s): {**vars(link.channel.stats), "stale": link.hold.stale,
                                     "other_mode": self.wrong_kind[s]}
                            for s, link in self.fc_links.items()},
                **self.outcome.to_dict()}


def _describe(sp: Setpoint) -> str:
    if isinstance(sp, AttitudeSetpoint):
        a = sp.attitude
        return (f"thrust {a.thrust_normalized:.3f} of full, q_d {np.round(a.quat_wxyz, 3)}, rates "
                f"{np.round(a.rates_rad_s, 3)}, tau_q {np.round(sp.tau_q_nm, 3)}")
    return f"thrust {sp.thrust_n:.2f} N, tau_B {np.round(sp.tau_B_nm, 3)}, tau_q {np.round(sp.tau_q_nm, 3)}"
