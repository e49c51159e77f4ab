"""The simulator's per-step work, independent of how setpoints travel (no sockets).

`SitlCore` owns the PyBullet world, one `simulator.vehicle.Vehicle` per AM (its flight-controller
emulation: the link as the flight controller sees it, `amlink.impair`; in attitude mode the
emulated autopilot, `simulator.flight_controller`; the failsafe after companion loss,
`simulator.failsafe`; where its state machine stands), the ground-truth outcome and a digest of
every state sent. `simulator.lockstep` drives it for the UDP simulator and the in-process runner
(`sitl.inprocess`) alike, once per physics step k: on control steps (`is_control_step`: every
step, or every rate_hz / control_rate_hz) `frames` / `iter_frames` read step k's sensor frames,
`observe` keeps their digest and ground truth while the companions compute, and `actuate` has
each flight controller apply what answered (`on_setpoint` applies one as it arrives) or fly its
failsafe while its companion is lost; between them `hold` flies on what each holds; then `step`.
With [flight_controller].actuation_delay_steps = d > 0 a setpoint acts d physics steps after its
frame (the first control step's at once): `due(k)` says at which steps such answers act.

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
from amlink.types import AttitudeSetpoint, AttitudeTarget, SensorFrame, TorqueSetpoint, sensor_frame_of_array

from . import fleet_kernels
from .devices import DeviceArrays, DeviceSuite, JointEffortSensor
from .failsafe import Failsafe, FailsafeGains
from .fcstate import FcMode, FleetSnapshot, VehicleSnapshot
from .flight_controller import AutopilotArrays, FlightController
from .object_mocap import measure_object
from .outcome import RunOutcome
from .sensors import SensorModel
from .vehicle import Vehicle
from .verdict import judge
from .world import World

Setpoint = TorqueSetpoint | AttitudeSetpoint

_NO_AXES = (False, False, False, False)  # an allocation that met every axis
TRUTH_PERIOD_S = 0.01  # ground-truth sample period for the outcome and telemetry [s]: every 10 steps at 1 kHz


def truth_every(rate_hz: float) -> int:
    """Physics steps between two ground-truth samples at `rate_hz` (every TRUTH_PERIOD_S)."""
    return max(1, round(TRUTH_PERIOD_S * rate_hz))


LAND_NOW = FailsafeGains(hold_s=0.0)  # a commanded landing: the failsafe's landing, without the hold


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
    allocation, the devices; one AM alone and every AM at once, simulator.fleet_kernels) with
    a run's argument types, so that numba compiles them (once per machine, a few seconds) or
    loads them from its cache here, before a lockstep starts, not at a run's first steps."""
    v = spec.vehicle
    n = v.n_joints
    target = AttitudeTarget(0, quat_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), rates_rad_s=np.zeros(3),
                            thrust_normalized=0.5)
    fc = FlightController(v.flight_controller, v.rotors, spec.dt_s)
    fc.step((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), target)
    fc.allocation.allocate(0.0, 0.0, 0.0, 0.5)  # torque mode's allocation, from Python (simulator.world)
    values = [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0] + [0.0] * (6 + 2 * n + 6)
    dev = DeviceSuite(DevicesSpec(enabled=True), n, spec.dt_s, v.gravity_mps2, 0, 2, values)
    dev.step(values, 0.0)
    if not dev.needs_reading(spec.dt_s):
        dev.step(values[:13], spec.dt_s)
    one = np.zeros(1, np.int64)
    fleet_kernels.hold(one, 2 * spec.dt_s, *dev.arrays.sense_arrays(), one, *fc.arrays.fly_arrays())
    fleet_kernels.fly(one, dev.arrays.frames, dev.arrays.state, dev.arrays.est_x, *fc.arrays.fly_arrays())


def kernel_group(spec: ScenarioSpec):
    """`warm_up_kernels(spec)` as a group of `amruntime.jitcache.warm_groups`: under a lock
    of its own, so that a process can compile these while another compiles the control law."""
    from amcore import allocation_kernels, estimator, quat_kernels
    from amruntime.jitcache import SIMULATOR_LOCK, Group

    from . import device_kernels, fc_kernels
    return Group(SIMULATOR_LOCK, (fc_kernels, allocation_kernels, device_kernels, estimator, quat_kernels,
                                  fleet_kernels),
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
        v = spec.vehicle
        self.mode = v.flight_controller.mode
        self._kind = AttitudeSetpoint if self.mode == "attitude" else TorqueSetpoint  # what the autopilot takes
        dv = spec.devices  # without [devices] the servos report the applied torques exactly
        effort, scale = (dv.effort, dv.scale) if dv.enabled else (JointEffortSpec(), 0.0)
        # every AM's autopilot and devices as rows of stacked arrays (its slot): one compiled call
        # steps them all (simulator.fleet_kernels)
        count = len(spec.ams)
        self.autopilots = AutopilotArrays(count, v.rotors) if self.mode == "attitude" else None
        self.device_arrays = DeviceArrays(count, self.model.n, spec.devices.estimator.history_steps, spec.dt_s,
                                          v.gravity_mps2) if spec.devices.enabled else None
        self._every_slot = np.arange(count, dtype=np.int64)
        self._loaded = False  # `hold` has loaded the devices' values; `actuate` steps them
        self._flying: list[tuple[Vehicle, object]] = []  # (vehicle, joint torques) that `_fly` flies
        self.vehicles: dict[int, Vehicle] = {}  # each AM's flight controller: its link, autopilot, devices, state
        for slot, am in enumerate(spec.ams):
            s, link = am.sysid, am.link or spec.link
            self.vehicles[s] = Vehicle(
                s, slot, ImpairedLink(LinkImpairment.for_scenario(dataclasses.replace(spec, link=link)), stream=s),
                # [link].joints = "servo_bus": the arm's torques reach its servos on the companion's own bus,
                # untouched by the link's impairment: the last ones computed act (zero-order hold)
                joints_on_bus=link.joints == "servo_bus",
                sensor=None if spec.sensors.exact else SensorModel(spec.sensors, self.model.n, spec.control_dt_s,
                                                                    spec.seed, s),
                fc=FlightController(v.flight_controller, v.rotors, spec.dt_s, self.autopilots, slot)
                if self.mode == "attitude" else None,
                effort=JointEffortSensor(effort, scale, self.model.n, spec.dt_s, spec.seed, s)
                if self.mode == "attitude" else None)
        self.commanded: list[tuple[float, int, str]] = []  # (t, sysid, what) of GCS commands that took the vehicle
        # offboard loss (PX4's COM_OF_LOSS_T): no setpoint for more than this many physics steps
        self.offboard_loss_steps = round(v.flight_controller.COM_OF_LOSS_T * spec.rate_hz)
        self.control_every = spec.control_every
        # [flight_controller].actuation_delay_steps: the answer to step k's frames acts from step
        # k + d (the first control step's at once); the runners step physics meanwhile
        self.actuation_delay = v.flight_controller.actuation_delay_steps
        self.events: list[dict] = []
        self.rejected: list[tuple[float, int, str]] = []  # (t, sysid, why) of setpoints refused as implausible
        self.controller_errors: list[tuple[float, int, str]] = []  # (t, sysid, what): controllers that raised
        self.digest = hashlib.sha256()
        self._unobserved: tuple | None = None  # (k, values, frames) of `frames` awaiting `observe`
        self._k = -1  # step of the last frames
        self._values_t = 0.0  # time of the last frames (`snapshot`)

    # -- views of the vehicles' state, by sysid --------------------------------------------
    @property
    def failsafes(self) -> dict[int, Failsafe]:
        """Vehicles in failsafe (companion lost, distrusted, offboard lost), not landing on a command."""
        return {s: v.failsafe for s, v in self.vehicles.items() if v.failsafe is not None}

    @property
    def distrusted(self) -> set[int]:
        return {s for s, v in self.vehicles.items() if v.distrusted}

    @property
    def offboard_lost(self) -> set[int]:
        return {s for s, v in self.vehicles.items() if v.offboard_lost}

    @property
    def disarmed(self) -> set[int]:
        return {s for s, v in self.vehicles.items() if v.disarmed}

    @property
    def ignored_setpoints(self) -> dict[int, int]:
        return {s: v.ignored_setpoints for s, v in self.vehicles.items()}

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
        made (that companion computes while the next frame is made). With [devices] every AM's
        devices and estimator step first, in one call. Consume it whole."""
        w, t = self.world, self.world.time_s
        n = self.model.n
        values, out = {}, {}
        self._k = k
        for ve in self.vehicles.values():
            ve.actuated = False
        devices = self.device_arrays
        for s, ve in self.vehicles.items():
            values[s] = v = w.sensor_values(s)
            if devices is not None:
                self._load(ve, v)
        if devices is not None:
            devices.step(t)
            self._loaded = False
        for s, ve in self.vehicles.items():
            v = values[s]
            if devices is not None:
                row = devices.frames[ve.slot]
                ve.odometry = reported = row.tolist()
                a = row.copy()
            else:  # no sensor: exact frames
                reported = v if ve.sensor is None else ve.sensor(v)
                a = np.array(reported, dtype=np.float64)
            if ve.effort is not None:  # attitude mode: what the autopilot flies and the servos measure
                f = sensor_frame_of_array(k, t, a, n, 0, ve.effort.last, ve.flown_target())
            else:
                f = sensor_frame_of_array(k, t, a, n, 0)
            out[s] = f
            ve.reported = reported
            yield s, f
        self._unobserved = (k, values, out)
        for s, v in values.items():
            self.vehicles[s].values = v
        self._values_t = t

    @property
    def exact_values(self) -> dict[int, list[float]]:
        """The exact values (`World.sensor_values`) behind the last frames, per sysid."""
        return {s: v.values for s, v in self.vehicles.items() if v.values is not None}

    def _suite(self, ve: Vehicle, values: list[float]) -> DeviceSuite:
        """AM ve's devices, made at its first step from its values there (in its row of the
        stacked devices)."""
        if ve.devices is None:
            sp = self.spec
            ve.devices = DeviceSuite(sp.devices, self.model.n, sp.dt_s, sp.vehicle.gravity_mps2, sp.seed, ve.sysid,
                                     values, self.device_arrays, ve.slot)
        return ve.devices

    def _load(self, ve: Vehicle, values: list[float]) -> None:
        """AM ve's exact values of this step into the stacked devices, which step later, all in one call."""
        self._suite(ve, values)
        self.device_arrays.load(values, ve.slot)

    def _sense(self, s: int, values: list[float], t: float) -> list[float]:
        """One physics step of AM s's devices and estimator ([devices]) alone: the frame's values."""
        ve = self.vehicles[s]
        ve.odometry = out = self._suite(ve, values).step(values, t)
        return out

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
            reported = {s: v.reported for s, v in self.vehicles.items() if v.reported is not None}
            if reported:  # the reported base state beside the truth (telemetry)
                gt = dataclasses.replace(gt, ams={s: dataclasses.replace(a, estimate=tuple(reported[s][:13]))
                                                  if s in reported else a for s, a in gt.ams.items()})
            self.on_truth(gt)

    def hold(self, k: int, lost: Collection[int] = (), setpoints: Mapping[int, Setpoint] | None = None) -> None:
        """Physics step k between control steps: no frames; each flight controller flies on
        what it holds (its failsafe while its companion is lost), or on `setpoints` that act
        now (an actuation delay, `due`), and ground truth is sampled as on control steps.
        With [devices] the devices, the estimators and the autopilots of every AM step in one
        call, in `actuate`."""
        self.observe()
        if self.device_arrays is not None:  # the devices and the estimator run at the IMU rate
            t, w = self.world.time_s, self.world
            for s, ve in self.vehicles.items():  # no frame: the base alone, unless the F/T tare reads the wrist
                dev = ve.devices
                self._load(ve, w.sensor_values(s) if dev is None or dev.needs_reading(t) else w.base_values(s))
            self._loaded = True
        if k % self._truth_every == 0:
            self._truth({s: self.world.wrench_ee(s) for s in self.sysids})
        self.actuate(k, setpoints or {}, lost)

    def on_setpoint(self, sysid: int, setpoint: Setpoint) -> None:
        """A setpoint answering the last frames, as it arrives: its flight controller applies
        it now, while the other companions still compute (`actuate` then skips this AM).
        One of a vehicle in failsafe is left to `actuate`, which ends the failsafe."""
        ve = self.vehicles[sysid]
        if ve.failsafe is not None or ve.actuated or ve.overridden or ve.distrusted:
            return
        ve.actuated = True
        self._apply(self._k, sysid, setpoint)
        self._fly()

    def actuate(self, k: int, setpoints: Mapping[int, Setpoint], lost: Collection[int] = ()) -> None:
        """Each flight controller applies what reached it (zero-order hold), or its failsafe
        while its companion is lost; a companion that answers again takes over again."""
        self.observe()
        w, t = self.world, self.world.time_s
        self._flying = []
        done = {s for s, ve in self.vehicles.items() if ve.actuated} if self._k == k else set()
        for s, ve in self.vehicles.items():
            ve.actuated = False
            if s in done:  # applied on arrival (on_setpoint)
                continue
            if ve.overridden:  # a GCS command rules this flight controller
                if s in setpoints:
                    ve.ignored_setpoints += 1
                if ve.disarmed:
                    w.apply(s, 0.0, np.zeros(3), np.zeros(self.model.n))
                else:
                    c = ve.landing.command(t, w.state(s))
                    w.apply(s, c.thrust_n, c.tau_B_nm, c.tau_q_nm)
                continue
            if s in lost or ve.for_good or (ve.failsafe is not None and s not in setpoints):
                if ve.failsafe is None:
                    ve.failsafe = Failsafe(self.model, w.state(s), t)
                    if not ve.distrusted:  # distrusted: said by note_rejected
                        self.events.append({"t": t, "sysid": s, "event": "lost", "failsafe": "hold, then land"})
                        self.log(f"t={t:.3f} s sysid {s}: companion silent; flight controller failsafe: hold, then land")
                c = ve.failsafe.command(t, w.state(s))
                w.apply(s, c.thrust_n, c.tau_B_nm, c.tau_q_nm)
                continue
            if ve.failsafe is not None:
                ve.failsafe = None
                if ve.fc is not None:  # the autopilot's loops start afresh from the failsafe's flight
                    ve.fc.reset()
                self.events.append({"t": t, "sysid": s, "event": "rejoined"})
                self.log(f"t={t:.3f} s sysid {s}: companion back, failsafe ended")
            self._apply(k, s, setpoints.get(s))
        self._fly()

    def _apply(self, k: int, s: int, setpoint: Setpoint | None) -> None:
        """The flight controller of `s` at step k: what its link delivers (zero-order hold);
        in attitude mode the emulated autopilot flies the held target. A setpoint of the other
        mode is ignored (a stock autopilot takes no body torques), counted and logged once."""
        ve = self.vehicles[s]
        if setpoint is not None and not isinstance(setpoint, self._kind):
            ve.wrong_kind += 1
            if ve.wrong_kind == 1:
                self.log(f"t={self.world.time_s:.3f} s sysid {s}: ignored a {type(setpoint).__name__} in "
                         f"{self.mode} mode; counted in outcome.json, further ones not printed")
            setpoint = None
        if setpoint is not None:
            ve.rejected_in_a_row = 0
            if ve.joints_on_bus:
                ve.bus_torques = setpoint.tau_q_nm
        link = ve.link
        sp = link.step(k, setpoint)
        if sp is None:  # nothing has reached this flight controller yet: keep the last command
            return
        # the servo bus's (or, [link].joints = "link", the link's)
        tau_q = sp.tau_q_nm if ve.bus_torques is None else ve.bus_torques
        if link.silent_for(k) > self.offboard_loss_steps:
            self._offboard_lost(s, link.silent_for(k))
            return
        if ve.fc is not None:  # flown with the others' in one call (`_fly`)
            if self.device_arrays is None:  # [devices]: on its estimator's attitude, else the exact one
                ap = self.autopilots
                ap.attitude[ve.slot], ap.rate[ve.slot] = self.world.attitude_and_rate(s)
            if ve.target_set is not sp:  # the held setpoint's target into the arrays, once
                self.autopilots.set_target(ve.slot, sp.attitude)
                ve.target_set = sp
            self._flying.append((ve, tau_q))
            return
        rep = self.world.apply(s, sp.thrust_n, sp.tau_B_nm, tau_q)
        if rep.mix.saturated or rep.joints.saturated:
            self._saturated(s, sp, rep.mix.saturated, rep.joints.saturated, rep.mix.allocation.saturated_axes)

    def _fly(self) -> None:
        """The step's compiled call: the devices and estimators loaded by `hold`, and the
        autopilots of the vehicles `_apply` left to fly (`_flying`); then their rotor thrusts and
        joint torques into the world."""
        flying, self._flying = self._flying, []
        loaded, self._loaded = self._loaded, False
        if not flying:
            if loaded:
                self.device_arrays.step(self.world.time_s)
            return
        slots = self._every_slot if len(flying) == len(self._every_slot) else \
            np.array([ve.slot for ve, _ in flying], np.int64)
        ap, dev = self.autopilots, self.device_arrays
        if loaded:
            fleet_kernels.hold(self._every_slot, self.world.time_s, *dev.sense_arrays(), slots, *ap.fly_arrays())
        elif dev is not None:
            fleet_kernels.fly(slots, dev.frames, dev.state, dev.est_x, *ap.fly_arrays())
        else:
            fleet_kernels.fly_on(slots, *ap.fly_arrays())
        saturated, thrusts, apply_rotors = ap.saturated.tolist(), ap.all_thrusts(), self.world.apply_rotors
        for ve, tau_q in flying:
            i = ve.slot
            rotors = saturated[i] != 0.0
            axes = ap.saturated_axes_of(i) if rotors else _NO_AXES
            joints = apply_rotors(ve.sysid, thrusts[i], tau_q, axes)
            if rotors or joints.saturated:
                self._saturated(ve.sysid, ve.link.hold.command, rotors, joints.saturated, axes)

    def _saturated(self, s: int, sp: Setpoint, rotors: bool, joints: bool, axes) -> None:
        t = self.world.time_s
        if self.outcome.saturation(s, t, rotors, joints, axes):
            self.log(f"t={t:.3f} s sysid {s}: command saturated ({_describe(sp)}); counted in outcome.json, "
                     f"further ones not printed")

    def note_rejected(self, sysid: int, why: str) -> None:
        """A setpoint of `sysid` answering the current step was refused as implausible: counted;
        its flight controller holds the last valid command (the caller leaves the setpoint out
        of `actuate`), or, the K-th refusal in a row, goes to failsafe for the rest of the run."""
        ve = self.vehicles[sysid]
        if ve.overridden:  # a GCS command rules: ignored, as every setpoint now
            ve.ignored_setpoints += 1
            return
        t = self.time_s
        if len(self.rejected) < 1000:
            self.rejected.append((t, sysid, why))
        else:  # keep the count, not every reason
            self.rejected.append(self.rejected[-1])
        ve.rejected_in_a_row += 1
        if ve.rejected_in_a_row < self.failsafe_after_rejected or ve.distrusted:
            return
        ve.distrusted = True  # `actuate` engages the failsafe (unless a GCS command rules)
        K = self.failsafe_after_rejected
        self.events.append({"t": t, "sysid": sysid, "event": "rejected", "in_a_row": K,
                            "failsafe": "hold, then land"})
        self.log(f"t={t:.3f} s sysid {sysid}: {K} setpoints in a row rejected as implausible (last: {why}); "
                 f"flight controller failsafe: hold, then land, for the rest of the run")

    def _offboard_lost(self, s: int, steps: int) -> None:
        """No setpoint reached AM s's flight controller for more than COM_OF_LOSS_T: it leaves
        offboard for its failsafe (hold, then land), as PX4 does, for the rest of the run."""
        t = self.world.time_s
        ve = self.vehicles[s]
        ve.offboard_lost = True
        ve.failsafe = Failsafe(self.model, self.world.state(s), t)
        c = ve.failsafe.command(t, self.world.state(s))
        self.world.apply(s, c.thrust_n, c.tau_B_nm, c.tau_q_nm)
        self.events.append({"t": t, "sysid": s, "event": "offboard lost", "silent_s": steps * self.spec.dt_s,
                            "failsafe": "hold, then land"})
        self.log(f"t={t:.3f} s sysid {s}: no setpoint for {steps * self.spec.dt_s:.3f} s (COM_OF_LOSS_T); "
                 f"flight controller failsafe: hold, then land, for the rest of the run")

    def note_controller_error(self, sysid: int, what: str) -> None:
        """The controller of `sysid` raised instead of answering (in-process runs)."""
        self.controller_errors.append((self.time_s, sysid, what))

    def step(self) -> None:
        for s, ve in self.vehicles.items():  # the torque acting over this step, as the servo reads it
            if ve.effort is not None:  # its reading formed when a frame reads it
                ve.effort.advance(self.world.joint_torques(s))
        self.world.step()

    # -- flight-controller commands (from the GCS) and state ---------------------------
    def land(self, s: int, by: str = "GCS") -> None:
        """Land vehicle `s` with the failsafe's landing, without its hold (arm compliant, motors
        off on the ground); its companion's setpoints are ignored from now on."""
        ve = self.vehicles[s]
        if ve.landing is not None:
            return
        t = self.world.time_s
        ve.landing = Failsafe(self.model, self.world.state(s), t, LAND_NOW)
        ve.failsafe = None
        self.commanded.append((t, s, "abort" if by == "mission abort" else "land"))
        self.events.append({"t": t, "sysid": s, "event": "land", "by": by})
        self.log(f"t={t:.3f} s sysid {s}: landing ({by} command)")

    def disarm(self, s: int, force: bool = False, by: str = "GCS") -> bool:
        """Motors off and joints limp; refused (False) in the air unless `force`."""
        ve = self.vehicles[s]
        if ve.disarmed:
            return True
        if not force and self.fc_mode(s) != FcMode.LANDED:
            return False
        t = self.world.time_s
        if force and self.fc_mode(s) != FcMode.LANDED:
            self.commanded.append((t, s, "disarm"))
        ve.disarmed = True
        self.events.append({"t": t, "sysid": s, "event": "disarmed", "by": by, "forced": force})
        self.log(f"t={t:.3f} s sysid {s}: disarmed ({by} command{', forced' if force else ''})")
        return True

    def arm(self, s: int, by: str = "GCS") -> None:
        """Undo a disarm; the flight controller applies its companion's setpoints (or keeps landing)."""
        ve = self.vehicles[s]
        if not ve.disarmed:
            return
        t = self.world.time_s
        ve.disarmed = False  # still overridden while it lands
        self.events.append({"t": t, "sysid": s, "event": "armed", "by": by})
        self.log(f"t={t:.3f} s sysid {s}: armed ({by} command)")

    def fc_mode(self, s: int) -> FcMode:
        return self.vehicles[s].mode(started=self._k >= 0)

    def snapshot(self, armed: Mapping[int, bool]) -> FleetSnapshot:
        """What every flight controller reports now (`armed`: who its companion has armed).
        Reads the last frames' values; before the first frame, the world's."""
        t = self._values_t if any(ve.values is not None for ve in self.vehicles.values()) else self.world.time_s
        vehicles = []
        for s, ve in self.vehicles.items():
            v = ve.values or self.world.sensor_values(s)
            mode = self.fc_mode(s)
            vehicles.append(VehicleSnapshot(
                sysid=s, p_WB=tuple(v[0:3]), quat_WB_wxyz=tuple(v[3:7]), v_B=tuple(v[7:10]), w_B=tuple(v[10:13]),
                mode=mode, armed=armed.get(s, False) and not ve.disarmed and mode != FcMode.LANDED,
                failsafe=ve.failsafe is not None and ve.landing is None))
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
                "fc_link": {str(s): {**vars(ve.link.channel.stats), "stale": ve.link.hold.stale,
                                     "other_mode": ve.wrong_kind}
                            for s, ve in self.vehicles.items()},
                **self.outcome.to_dict()}


def _describe(sp: Setpoint) -> str:
    if isinstance(sp, AttitudeSetpoint):
        a = sp.attitude
        return (f"thrust {a.thrust_normalized:.3f} of full, q_d {np.round(a.quat_wxyz, 3)}, rates "
                f"{np.round(a.rates_rad_s, 3)}, tau_q {np.round(sp.tau_q_nm, 3)}")
    return f"thrust {sp.thrust_n:.2f} N, tau_B {np.round(sp.tau_B_nm, 3)}, tau_q {np.round(sp.tau_q_nm, 3)}"
