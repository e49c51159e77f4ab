"""The free-running simulator: the scenario's world stepped on the wall clock, each vehicle played
as PX4 SITL plays it (its commander, `simulator.px4.commander`; its onboard MAVLink port,
`simulator.px4.port`), so that any PX4 offboard program (MAVSDK, or the stack's companion)
flies it with standard MAVLink, and its arm answers on its own device bus (`arm` objects).

Time. Physics steps at [scenario].rate_hz of simulated time, paced to the wall clock (a
`time.monotonic_ns`-style callable, passed in) without drift: step k starts at
deadline_k = t0 + k dt / speed (`Pacer`). Until a deadline the loop waits in select() over the
ports' sockets (and the arms' descriptors), serving MAVLink as it arrives. A step that starts
late is not skipped: the loop runs back to back until it has caught up, but by at most
MAX_BEHIND_PERIODS periods: a start later than that moves the schedule (every later deadline)
by its lateness, so that an overloaded machine runs the simulation slower than asked, as
Gazebo's world loop does (it paces each step from the previous one's wall time), instead of
racing the autopilots' clock ahead in a burst after a stall (a burst of 100 ms of simulated
time in a few wall milliseconds is 100 ms the companions' loops never see). Counted: steps, the
lateness of each start (mean, worst, in bins) and deadline misses, a step whose start came more
than one period after its deadline (the next step's deadline had passed), the schedule's moves
and the wall time they gave up. The autopilots' clock (PX4's
boot time) is the simulated time since the start, as PX4 SITL's hrt is the simulator's: with
--speed 0.5 PX4's clock, its streams and COM_OF_LOSS_T run at half the wall rate, and when the
loop falls behind they fall behind with it. Between steps (I/O served while waiting) it reads the
time of the coming step.

Each physics step, per vehicle (from SitlCore's pieces: the world, the devices and estimator,
the outcome and the verdict; the emulated autopilot `simulator.flight_controller` and the
failsafe `simulator.failsafe`):

- the commander's land detector and failover run on the autopilot's estimate;
- disarmed (or TERMINATION): motors off (every rotor 0 N);
- armed in OFFBOARD with a setpoint published in OFFBOARD: the emulated autopilot flies it
  (`simulator.px4.setpoint.flown_target`; rate integrator frozen while the land detector says
  (maybe) landed, as PX4's RateControl::update(..., landed), and fresh at each arming); armed in
  OFFBOARD before the first such setpoint: the loops have no target, thrust 0;
- HOLD (and the stick modes a failsafe selects) / LAND (and RTL): `simulator.failsafe`'s hold
  (no time limit) / its landing without hold, from the vehicle's state at the mode's entry,
  evaluated at the scenario's control rate and held between (PX4's position controller runs
  slower than its rate loop; one evaluation costs a pinocchio gravity term, too much for
  every 1 kHz step of several vehicles on the wall clock); on the ground (land detector)
  motors idle at 0 N;
- the arm's joint torques always come from the vehicle's `arm` (a Dynamixel bus server, or
  `HoldJoints` by default): the servos are not PX4's, and arming does not touch them; a bus is
  served at the step's start and again after the physics (one select() says which descriptors
  have something, so an idle socket costs no accept()/recv() call), besides while waiting;
- the port's report: the estimate the autopilot flies on (with [devices] the estimator's
  output, `SitlCore._sense`, as PX4 flies on EKF2's; without, the exact state; [sensors] noise
  is not applied here), and an ideal IMU (the body rate, and the specific force from the last
  step's change of velocity) for HIGHRES_IMU.

Start. Each vehicle stands landed and disarmed below its mission's start pose
(`simulator.core.initial_state` moved down until its lowest collision shape touches z = 0,
`ground_start_states`). For am3dof the lowest shape is the pad (7 cm below the base's box at the
nominal arm pose), so the vehicle first settles tilted back onto the base's rear edge.

Mission clock. t_mission = t - mission_t0_s, mission_t0_s = the first OFFBOARD engage (armed in
OFFBOARD, any vehicle) + TAKEOFF_S (amcore.mission), unless set by the caller. Only ground-truth
samples at t_mission >= 0 go into the outcome (simulator.outcome), with their mission time, and
the existing verdict (simulator.verdict) judges them; the run ends when the mission clock
reaches [scenario].duration_s, or after `duration_s` of simulated time if given.
"""
from __future__ import annotations

import dataclasses
import gc
import math
import select
import time
from collections.abc import Callable, Sequence

import numpy as np

from amcore.allocation import Allocation
from amcore.config import ScenarioSpec
from amcore.mission import TAKEOFF_S
from amcore.model import AmState, build_model
from amcore.so3 import quat_wxyz_R_T_times, quat_wxyz_R_times, unit_quat_wxyz_to_R
from amlink import px4
from amlink.endpoint import Endpoint
from amlink.impair import LinkImpairment

from . import scene
from .bullet import pb
from .core import LAND_NOW, SitlCore, initial_state, truth_every
from .failsafe import Failsafe, FailsafeGains, joint_damping
from .flight_controller import FlightController
from .object_mocap import measure_object
from .px4 import commander as cm
from .px4.port import Px4Port
from .px4.setpoint import VehicleReport, flown_target
from .verdict import judge

HOLD_FOREVER = FailsafeGains(hold_s=math.inf)  # HOLD: the failsafe's hold, never its landing
START_TIMEOUT_S = 120.0  # no OFFBOARD engage this long after the start (autopilot time): the run ends
HOLD_JOINTS_K_NM_PER_RAD = 20.0  # HoldJoints' stiffness (see there)
TAKEOFF_TRACK_EVERY = 100  # steps between the take-off track's samples (`_track_takeoff`)
MAX_BEHIND_PERIODS = 10  # the most physics periods the loop catches up back to back (module doc)
TIMING_EVERY_S = 2.0  # the loop's measurements to `on_timing` this often [s of simulated time]


class HoldJoints:
    """The default arm: every servo in position mode holding its initial angle, as X-series
    servos do after torque-on (XM430/XM540 e-Manual: Operating Mode 3). PD per joint,
    tau = K (q0 - q) - D qdot, within torque_max_nm: K = 20 N m/rad (an XM430-W350 at its
    default Position P Gain 800 (KPP = 800/128) reaches its 885 PWM limit at 0.22 rad, stall
    torque 4.1 N m: ~19 N m/rad), D = simulator.failsafe's joint damping d_q (N m s/rad).
    The ServoBus interface: open, close, poll, joint_torques_nm, observe."""

    def __init__(self, q0_rad, torque_max_nm, d_q, k_q: float = HOLD_JOINTS_K_NM_PER_RAD) -> None:
        self.q0 = np.array(q0_rad, dtype=float)
        n = self.q0.shape[0]
        if len(d_q) != n or len(torque_max_nm) != n:
            raise ValueError(f"HoldJoints: {n} joints, but {len(d_q)} damping gains and {len(torque_max_nm)} limits")
        self.k, self.d = float(k_q), np.array(d_q, dtype=float)
        self.tau_max = np.array(torque_max_nm, dtype=float)
        self._q0, self._d, self._tau_max = self.q0.tolist(), self.d.tolist(), self.tau_max.tolist()
        self.last: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def poll(self, now_s: float) -> None:
        pass

    def joint_torques_nm(self, q, qdot) -> np.ndarray:
        k = self.k
        return np.array([min(max(k * (q0 - qi) - d * wi, -m), m)
                         for q0, qi, d, wi, m in zip(self._q0, q, self._d, qdot, self._tau_max)])

    def observe(self, t_s: float, q, qdot, tau_nm) -> None:
        self.last = (t_s, np.asarray(q), np.asarray(qdot), np.asarray(tau_nm))


_LATE_NS = (100_000, 1_000_000, 10_000_000, 100_000_000)  # the Pacer's lateness bins [ns]


class _GcTimer:
    """A gc.callbacks entry timing Python's garbage collections (by generation) on `clock`
    [ns]: a pause of the collector is a pause of the physics loop."""

    def __init__(self, clock: Callable[[], int]) -> None:
        self.clock = clock
        self._t0 = 0
        self.count = [0, 0, 0]
        self.sum_ns = [0, 0, 0]
        self.max_ns = [0, 0, 0]

    def __call__(self, phase: str, info: dict) -> None:
        if phase == "start":
            self._t0 = self.clock()
            return
        g = info.get("generation", 0)
        d = self.clock() - self._t0
        self.count[g] += 1
        self.sum_ns[g] += d
        self.max_ns[g] = max(self.max_ns[g], d)

    def to_dict(self) -> dict:
        return {f"gen{g}": {"collections": self.count[g], "total_s": self.sum_ns[g] * 1e-9,
                            "max_s": self.max_ns[g] * 1e-9} for g in range(3)}


class Pacer:
    """Drift-free pacing: step k starts at deadline_k = t0 + k period_ns. `wait(k)` calls
    `serve(timeout_s)` (which may return early, on I/O) until the clock reaches deadline_k and
    returns the start's lateness [ns], counted (module doc); `done()` after the step counts
    its compute time."""

    def __init__(self, clock: Callable[[], int], period_ns: float, serve: Callable[[float], None],
                 max_behind_periods: float = math.inf) -> None:
        if not period_ns > 0:
            raise ValueError(f"period must be > 0 ns, got {period_ns}")
        if not max_behind_periods >= 0:
            raise ValueError(f"max_behind_periods must be >= 0, got {max_behind_periods}")
        self.clock, self.period_ns, self.serve = clock, period_ns, serve
        self.max_behind_ns = max_behind_periods * period_ns
        self.shift_ns = 0  # the schedule's moves so far (module doc)
        self.shifts = 0
        self.t0_ns: int | None = None
        self.steps = self.misses = 0
        self.worst_ns = self.sum_ns = 0
        self.worst_step = -1
        self.busy_sum_ns = self.busy_max_ns = self._started = 0
        self.late_counts = [0] * len(_LATE_NS)  # starts later than each of _LATE_NS

    def start(self) -> int:
        self.t0_ns = self.clock()
        return self.t0_ns

    def deadline(self, k: int) -> int:
        return self.t0_ns + self.shift_ns + round(k * self.period_ns)

    def wait(self, k: int) -> int:
        deadline = self.deadline(k)
        now = self.clock()
        while now < deadline:
            self.serve((deadline - now) * 1e-9)
            now = self.clock()
        late = now - deadline
        self._started = now
        self.steps += 1
        self.sum_ns += late
        if late > self.worst_ns:
            self.worst_ns, self.worst_step = late, k
        if late > self.period_ns:
            self.misses += 1
        for i, limit in enumerate(_LATE_NS):
            if late > limit:
                self.late_counts[i] += 1
        if late > self.max_behind_ns:  # too far behind to catch up: the schedule moves (module doc)
            self.shift_ns += late
            self.shifts += 1
        return late

    def done(self) -> None:
        """The step that `wait` let start is done: its compute time (start to now) is counted."""
        busy = self.clock() - self._started
        self.busy_sum_ns += busy
        self.busy_max_ns = max(self.busy_max_ns, busy)

    def to_dict(self) -> dict:
        n = max(self.steps, 1)
        elapsed = (self.clock() - self.t0_ns) * 1e-9 if self.t0_ns is not None else 0.0
        return {"steps": self.steps, "elapsed_s": elapsed, "deadline_misses": self.misses, "worst_lateness_s": self.worst_ns * 1e-9,
                "worst_step": self.worst_step, "mean_lateness_s": self.sum_ns * 1e-9 / n,
                "mean_step_compute_s": self.busy_sum_ns * 1e-9 / n, "max_step_compute_s": self.busy_max_ns * 1e-9,
                "period_s": self.period_ns * 1e-9,
                "schedule_shifts": self.shifts, "schedule_shifted_s": self.shift_ns * 1e-9,
                "late_steps": {f">{limit * 1e-6:g} ms": c for limit, c in zip(_LATE_NS, self.late_counts)}}


def start_joints(spec: ScenarioSpec, model=None) -> dict[int, np.ndarray]:
    """Each vehicle's joint angles at the start (its mission's nominal arm pose) [rad], by
    sysid: what its servos hold at power-up (HoldJoints; a ServoBus's q0_rad)."""
    model = build_model(spec.vehicle) if model is None else model
    return {am.sysid: initial_state(spec, am, model).q for am in spec.ams}


def ground_start_states(spec: ScenarioSpec, model, object_pose=None) -> dict[int, AmState]:
    """Each vehicle's start: `initial_state` moved straight down until its lowest collision
    shape (PyBullet's AABB of each link with one, in a scratch DIRECT client) rests on z = 0."""
    states = {am.sysid: initial_state(spec, am, model, object_pose) for am in spec.ams}
    c = pb.connect(pb.DIRECT)
    if c < 0:
        raise RuntimeError("PyBullet could not start a DIRECT client")
    try:
        body = scene.load_am(c, spec.vehicle, friction=scene.pad_lateral_friction(spec.object))
        out = {}
        for sysid, x in states.items():
            scene.reset_am(c, body, x)
            z_min = min(pb.getAABB(body.body_id, link, physicsClientId=c)[0][2]
                        for link in range(-1, pb.getNumJoints(body.body_id, physicsClientId=c))
                        if pb.getCollisionShapeData(body.body_id, link, physicsClientId=c))
            out[sysid] = x._replace(p_WB=x.p_WB - np.array([0.0, 0.0, z_min]))
        return out
    finally:
        pb.disconnect(physicsClientId=c)


@dataclasses.dataclass(eq=False)
class Px4Vehicle:
    """One free-running vehicle as PX4 SITL holds it: its commander (the arming and mode state
    machine), its onboard and GCS ports (the link state), its arm and wrist sensor, and the
    state of its loops between physics steps."""

    index: int  # its [[am]] order: PX4 SITL instance `instance` + index
    sysid: int
    commander: cm.Commander
    port: Px4Port  # onboard (the companion's)
    gcs_port: Px4Port | None
    arm: object  # HoldJoints or a servo bus (simulator.servo_bus)
    wrist: object | None  # its F/T server (simulator.netft), or None
    start: AmState | None = None  # where it stands (open)
    fc: FlightController | None = None  # the emulated autopilot's loops, made afresh at each arming or OFFBOARD
    flying: list | None = None  # [kind, Failsafe, last command] while the autopilot flies itself (hold, land)
    throttle: float = 0.0  # the last normalized thrust (the land detector's input)
    was_armed: bool = False
    last_nav: cm.NavState | None = None
    v_prev: tuple[float, float, float] | None = None  # the last step's velocity (the IMU's specific force)
    target: tuple | None = None  # (setpoint, its AttitudeTarget), reused while it is the same setpoint


class FreeRun:
    """The free-running simulator of one scenario (module doc). Nothing opens before `open()`.

    endpoints: one onboard endpoint per vehicle ([[am]] order; None: PX4 SITL's ports).
    arms: one arm per vehicle (None: HoldJoints). speed: real-time factor. clock: monotonic
    nanoseconds. mission_t0_s: the mission clock's zero on the autopilot clock (None: first
    OFFBOARD engage + TAKEOFF_S). params: the commanders' PX4 parameters (None: PX4's, with
    this vehicle's COM_OF_LOSS_T and hover thrust). gcs: one GCS endpoint per vehicle (None: no
    GCS instances; an entry None: PX4 SITL's, 18570+i -> 127.0.0.1:14550); gcs_key and
    gcs_signed: their signing (`simulator.px4.port`, Signing). instance: vehicle i is PX4 SITL
    instance `instance` + i (its GCS instance binds 18570 + instance + i). onboard_key: the onboard
    ports sign and read only signed frames (None: unsigned, as PX4's). on_truth(gt): each ground-truth
    sample of the mission (its time the mission's; telemetry). on_timing(t, timing): the physics
    loop's measurements so far (`Pacer.to_dict`) every TIMING_EVERY_S of simulated time, t the
    mission time (negative before its start)."""

    def __init__(self, spec: ScenarioSpec, endpoints: Sequence[Endpoint | None] | None = None, *,
                 arms: Sequence | None = None, speed: float = 1.0, clock: Callable[[], int] = time.monotonic_ns,
                 mission_t0_s: float | None = None, params: cm.CommanderParams | None = None,
                 wrist_sensors: Sequence | None = None, mocap=None,
                 gcs: Sequence[Endpoint | None] | None = None, gcs_key: bytes | None = None,
                 gcs_signed: bool = True, instance: int = 0, onboard_key: bytes | None = None,
                 on_truth: Callable | None = None, on_timing: Callable[[float, dict], None] | None = None,
                 log: Callable[[str], None] = lambda _m: None) -> None:
        v = spec.vehicle
        if v.flight_controller.mode != "attitude":
            raise ValueError(f"{spec.name}: free-running needs [flight_controller].mode = \"attitude\" (PX4 takes "
                             f"attitude setpoints, not body torques); this scenario is in {v.flight_controller.mode!r}")
        if not (math.isfinite(speed) and speed > 0.0):
            raise ValueError(f"speed must be a real-time factor > 0, got {speed!r}")
        n = len(spec.ams)
        endpoints = list(endpoints) if endpoints is not None else [None] * n
        if len(endpoints) != n:
            raise ValueError(f"{len(endpoints)} onboard endpoints for {n} vehicles (one per [[am]], in order)")
        self.spec, self.speed, self.clock, self.log = spec, float(speed), clock, log
        self.max_behind_periods = MAX_BEHIND_PERIODS
        self.mission_t0_s = mission_t0_s
        self._t0_given = mission_t0_s is not None
        self.model = build_model(v)
        self.sysids = [am.sysid for am in spec.ams]
        self.thrust_scale_n = Allocation(v.rotors).thrust_scale_n
        hover = self.model.mass_kg * v.gravity_mps2 / self.thrust_scale_n
        p = params or cm.CommanderParams(COM_OF_LOSS_T=v.flight_controller.COM_OF_LOSS_T, MPC_THR_HOVER=hover)
        commanders = [cm.Commander(p) for _ in self.sysids]
        # [link]: each onboard port impairs what reaches its autopilot (simulator.px4.port, Impairment);
        # the arm's torques go on its own bus here, so an impairment of them ("link") cannot be flown
        links = [am.link or spec.link for am in spec.ams]
        for am, ln in zip(spec.ams, links):
            if ln.joints == "link" and not LinkImpairment.for_scenario(dataclasses.replace(spec, link=ln)).is_ideal:
                raise ValueError(f"{spec.name}: [link].joints = \"link\" (sysid {am.sysid}): free-running, the arm's "
                                 f"torques go on its own servo bus, never through the autopilot's link; use "
                                 f"\"servo_bus\" (the default)")
        ports = [Px4Port(i, s, commanders[i], endpoints[i], signing_key=onboard_key,
                              require_signed=onboard_key is not None, rotor_count=v.rotors.count, log=log,
                              impairment=LinkImpairment.for_scenario(dataclasses.replace(spec, link=ln)))
                      for i, (s, ln) in enumerate(zip(self.sysids, links))]
        if gcs is not None and len(gcs) != n:
            raise ValueError(f"{len(gcs)} GCS endpoints for {n} vehicles (one per [[am]], in order)")
        # each vehicle's GCS instance (simulator.px4.port, role "gcs"), HEARTBEATs forwarded both ways
        gcs_ports = [None] * n if gcs is None else [
            Px4Port(i, s, commanders[i], gcs[i], role="gcs", signing_key=gcs_key, require_signed=gcs_signed,
                    local_port=px4.gcs_local_port(instance + i), rotor_count=v.rotors.count, log=log)
            for i, s in enumerate(self.sysids)]
        for onboard, g in zip(ports, gcs_ports):
            if g is not None:
                onboard.forward, g.forward = g.forwarded, onboard.forwarded
        if arms is not None and len(arms) != n:
            raise ValueError(f"{len(arms)} arms for {n} vehicles (one per [[am]], in order)")
        q0 = start_joints(spec, self.model)
        arms = list(arms) if arms is not None else [
            HoldJoints(q0[s], v.joint_torque_max_nm, joint_damping(self.model)) for s in self.sysids]
        if wrist_sensors is not None and len(wrist_sensors) != n:
            raise ValueError(f"{len(wrist_sensors)} wrist sensors for {n} vehicles (one per [[am]], in order)")
        # each vehicle's wrist F/T server (simulator.netft: publish(t, wrench_E), poll(t)), and the
        # object's motion-capture stream (simulator.mocap_stream), or None
        wrists = list(wrist_sensors) if wrist_sensors is not None else [None] * n
        self.vehicles = {s: Px4Vehicle(i, s, commanders[i], ports[i], gcs_ports[i], arms[i], wrists[i])
                         for i, s in enumerate(self.sysids)}
        self.ports = ports
        self.gcs_ports = [g for g in gcs_ports if g is not None]
        self.all_ports = [*self.ports, *self.gcs_ports]
        self._arms = arms
        self._wrists = [ft for ft in wrists if ft is not None]
        self.mocap = mocap
        self._mocap_every = max(1, round(spec.rate_hz / spec.devices.mocap.rate_hz))
        self._object_bias = None  # the object's first measurement less its truth (open)
        self.core: SitlCore | None = None  # the world and its pieces (open)
        # the autopilot's loops, with feed-forward on: `flown_target` forms PX4's feed-forward
        self._fc_params = dataclasses.replace(v.flight_controller, body_rate_feedforward=True)
        self.pacer: Pacer | None = None
        self._gc: dict | None = None  # the run's garbage collections (`_GcTimer`)
        self.takeoff_track: dict[str, list[dict]] = {}  # by sysid: the vehicles before the mission (`_track_takeoff`)
        self._cpu_s: float | None = None  # the loop's thread CPU time over the run [s]
        self._fixed_fds: list[int] | None = None  # (`_readable`)
        self._arm_fds: list = []
        self._truth_every = truth_every(spec.rate_hz)
        self.mission_steps = 0
        self.on_truth, self.on_timing = on_truth, on_timing
        self._timing_every = max(1, round(TIMING_EVERY_S * spec.rate_hz))
        self.status = ""
        self._opened = False

    # -- life cycle ---------------------------------------------------------------------
    def open(self) -> None:
        """Build the world (the vehicles on the ground), bind the ports, open the arms (OSError
        names what failed)."""
        pose = measure_object(self.spec) if self.spec.mission.object_pose == "mocap" else None  # as SitlCore's
        starts = ground_start_states(self.spec, self.model, pose)
        for s, ve in self.vehicles.items():
            ve.start = starts[s]
        self.core = SitlCore(self.spec, log=self.log, initial=starts)
        self.core.connect()
        self._opened = True
        for port in self.all_ports:
            try:
                port.open()
            except OSError as exc:
                raise OSError(f"vehicle {port.index} (sysid {port.sysid}): cannot bind its {port.role} port "
                              f"for {port.endpoint}: {exc.strerror or exc}") from None
        for arm in self._arms:
            arm.open()
        for dev in self._devices():
            dev.open()
        if self.mocap is not None:  # the stream reports the object with its first measurement's error
            p_true, _ = self.core.world.object_pose()
            p_meas = pose.p_W_m if pose is not None else p_true
            self._object_bias = np.asarray(p_meas, dtype=float) - np.asarray(p_true, dtype=float)

    def _devices(self) -> list:
        return [*self._wrists, *([self.mocap] if self.mocap is not None else [])]

    def close(self) -> None:
        self._fixed_fds = None
        for port in self.all_ports:
            port.close()
        for arm in self._arms:
            arm.close()
        for dev in self._devices():
            dev.close()
        if self._opened:
            self.core.close()
            self._opened = False

    # -- clocks ---------------------------------------------------------------------------
    def boot_s(self) -> float:
        """The autopilots' time [s]: the simulated time since the start (PX4 SITL's hrt is the
        simulator's clock), so it lags with the physics when the loop falls behind."""
        return self.core.world.time_s if self._opened else 0.0

    def mission_time_s(self) -> float:
        """The mission's clock [s]: the autopilots' time less mission_t0_s (0 before it is known)."""
        return self.boot_s() - self.mission_t0_s if self.mission_t0_s is not None else 0.0

    # -- the loop -------------------------------------------------------------------------
    def run(self, duration_s: float | None = None, should_stop: Callable[[], bool] = lambda: False) -> dict:
        """Run until the mission clock reaches [scenario].duration_s, `duration_s` of simulated
        time, START_TIMEOUT_S without an OFFBOARD engage, or `should_stop()` (called after every
        physics step) says so; the result (`result`)."""
        spec = self.spec
        dt_ns = 1e9 / spec.rate_hz
        self.pacer = Pacer(self.clock, dt_ns / self.speed, self._serve, self.max_behind_periods)
        wall0 = time.perf_counter()
        cpu0 = time.thread_time_ns()  # the loop's own CPU time (apart from time lost to other processes)
        gc_timer = _GcTimer(self.clock)
        gc.callbacks.append(gc_timer)
        self.pacer.start()
        k = 0
        self.status = "run complete"
        while True:
            self.pacer.wait(k)
            self._step()
            self.pacer.done()
            k += 1
            t = k * spec.dt_s
            if duration_s is not None and t >= duration_s - 1e-9:
                break
            t0 = self.mission_t0_s
            if duration_s is None and t0 is not None and t - t0 >= spec.duration_s - 1e-9:
                break
            if t0 is None and duration_s is None and t >= START_TIMEOUT_S:
                self.status = f"no vehicle engaged OFFBOARD within {START_TIMEOUT_S:g} s"
                break
            if should_stop():
                self.status = "stopped"
                break
        gc.callbacks.remove(gc_timer)
        self._gc = gc_timer.to_dict()
        self._cpu_s = (time.thread_time_ns() - cpu0) * 1e-9
        return self.result(time.perf_counter() - wall0)

    def _readable(self, timeout_s: float) -> set[int]:
        """The descriptors of the ports, arms and devices that select() finds readable within
        timeout_s [s] (0: a look, no wait)."""
        if self._fixed_fds is None:  # the ports' and devices' sockets: fixed once open
            self._fixed_fds = [p.fileno() for p in self.all_ports]
            for dev in self._devices():
                self._fixed_fds.extend(getattr(dev, "fds", lambda: [])())
            self._arm_fds = [arm.fds for arm in self._arms if hasattr(arm, "fds")]
        fds = list(self._fixed_fds)
        for arm_fds in self._arm_fds:  # (a bus's client comes and goes)
            fds.extend(arm_fds())
        try:
            readable, _, _ = select.select(fds, [], [], max(0.0, timeout_s))
        except InterruptedError:
            return set()
        return set(readable)

    def _poll_arms(self, now: float, ready: set[int]) -> None:
        for arm in self._arms:
            if hasattr(arm, "fds"):
                arm.poll(now, ready)  # only what is readable costs a system call
            else:
                arm.poll(now)

    def _serve(self, timeout_s: float) -> None:
        ready = self._readable(timeout_s)
        if ready:
            now = self.boot_s()
            for port in self.all_ports:
                if port.fileno() in ready:
                    port.poll(now)
            self._poll_arms(now, ready)
            for dev in self._devices():
                dev.poll(now)

    def _step(self) -> None:
        """One physics step: I/O, every vehicle (`_vehicle`), physics, the mission clock and the
        ground truth, the ports' streams."""
        w = self.core.world
        now = w.time_s  # the autopilots' time: this physics step's start
        for port in self.ports:
            port.poll(now)
        ready = self._readable(0.0)
        for port in self.gcs_ports:  # (a GCS is seldom heard: read when select says so)
            if port.fileno() in ready:
                port.poll(now)
        self._poll_arms(now, ready)
        for dev in self._devices():
            dev.poll(now)  # (they stream: polled every step)
        reports = {s: self._vehicle(ve, now) for s, ve in self.vehicles.items()}
        if self.mocap is not None and w.step_index % self._mocap_every == 0:
            p_obj, q_obj = w.object_pose()
            self.mocap.publish(now, np.asarray(p_obj) + self._object_bias, q_obj)
        w.step()  # (not core.step: the lockstep's servo-current model is the arm's business here)
        t_next = w.time_s
        # a servo bus is answered twice a step: a companion's sync read that came in during the
        # physics waits half as long (its loop blocks on the answer)
        self._poll_arms(t_next, self._readable(0.0))
        if self.mission_t0_s is None:
            engaged = [ve.commander.offboard_engaged_s for ve in self.vehicles.values()
                       if ve.commander.offboard_engaged_s is not None]
            if engaged:
                self.mission_t0_s = min(engaged) + TAKEOFF_S
                self.log(f"t = {min(engaged):.3f} s: OFFBOARD engaged; mission clock starts at "
                         f"t = {self.mission_t0_s:.3f} s (take-off {TAKEOFF_S:g} s)")
        if self.on_timing is not None and w.step_index % self._timing_every == 0:
            self.on_timing(t_next - (self.mission_t0_s if self.mission_t0_s is not None else t_next),
                           self.pacer.to_dict() if self.pacer is not None else {})
        if w.step_index % TAKEOFF_TRACK_EVERY == 0 and (self.mission_t0_s is None or t_next < self.mission_t0_s):
            self._track_takeoff(t_next, reports)
        if self.mission_t0_s is not None and t_next - self.mission_t0_s >= -1e-9:
            self.mission_steps += 1
            if w.step_index % self._truth_every == 0:
                self._truth(t_next - self.mission_t0_s)
        for port in self.all_ports:
            port.publish(now, reports[port.sysid])

    def _vehicle(self, ve: Px4Vehicle, t: float) -> VehicleReport:
        """One vehicle's commander and actuation for the physics step that starts at t (module doc)."""
        core, w, c, s = self.core, self.core.world, ve.commander, ve.sysid
        n = self.model.n
        if self.spec.devices.enabled:  # the autopilot flies on its estimator (EKF2's place)
            values = w.sensor_values(s)
            est = core._sense(s, values, t)
            rate_B = tuple(core.vehicles[s].devices.autopilot_rate.tolist())
        else:
            values = est = w.flight_values(s)
            rate_B = tuple(values[10:13])
        p, quat, w_B = tuple(est[0:3]), tuple(est[3:7]), tuple(est[10:13])
        v_W = quat_wxyz_R_times(quat, est[7:10])
        q, qdot = values[13:13 + n], values[13 + n:13 + 2 * n]
        c.update(t, cm.LandInputs(throttle=ve.throttle, v_z_mps=v_W[2], v_xy_mps=math.hypot(v_W[0], v_W[1]),
                                    rate_xy_radps=math.hypot(w_B[0], w_B[1]),
                                    climb_rate_control=c.nav_state in cm.HOLDING or c.nav_state in cm.LANDING,
                                    descending=c.nav_state in cm.LANDING))
        arm = ve.arm
        tau_q = arm.joint_torques_nm(q, qdot)
        target = rates_sp = None
        nav = c.nav_state
        entered = nav == cm.NavState.OFFBOARD and ve.last_nav != nav
        if c.armed and (not ve.was_armed or entered):
            # PX4 resets the rate integrator while disarmed; after another mode (the failsafe flew)
            # the loops start afresh, as the lockstep's (simulator.core)
            ve.fc = FlightController(self._fc_params, self.spec.vehicle.rotors, self.spec.dt_s)
        ve.was_armed = c.armed
        ve.last_nav = nav
        mission_t = None if self.mission_t0_s is None else t - self.mission_t0_s
        if not c.armed or nav == cm.NavState.TERMINATION or (nav != cm.NavState.OFFBOARD and c.landed):
            ve.flying = None
            self._motors_off(ve, tau_q)
        elif nav == cm.NavState.OFFBOARD:
            ve.flying = None
            sp = c.target
            if sp is None:
                self._motors_off(ve, tau_q)
            else:
                target = self._target(ve, sp, quat, rate_B)
                fc = ve.fc
                frozen = list(fc.rate_int) if (c.landed or c.maybe_landed) else None
                out = fc.step(quat, rate_B, target)
                if frozen is not None:
                    fc.rate_int = frozen  # RateControl::update(..., landed): no integration on the ground
                rates_sp = out.rates_sp
                ve.throttle = out.thrust_sp
                axes = out.allocation.saturated_axes
                joints = w.apply_rotors(s, out.rotor_thrusts_n, tau_q, axes)
                self._count_saturation(s, mission_t, out.allocation.saturated, joints.saturated, axes)
        else:
            kind = "land" if nav in cm.LANDING else "hold"
            flying = ve.flying
            if flying is None or flying[0] != kind:
                x = _state(values, n)
                gains = LAND_NOW if kind == "land" else HOLD_FOREVER
                flying = ve.flying = [kind, Failsafe(self.model, x, t, gains), None]
            # vehicles take turns (index offset), so that two evaluations rarely share a step
            if flying[2] is None or (w.step_index + ve.index) % self.spec.control_every == 0:
                flying[2] = flying[1].command(t, _state(values, n))
            cmd = flying[2]
            rep = w.apply(s, cmd.thrust_n, cmd.tau_B_nm, tau_q)
            ve.throttle = cmd.thrust_n / self.thrust_scale_n
            self._count_saturation(s, mission_t, rep.mix.saturated, rep.joints.saturated,
                                   rep.mix.allocation.saturated_axes)
        arm.observe(t, q, qdot, w.joint_torques(s))
        ft = ve.wrist
        if ft is not None:  # the wrist sensor's reading (with [devices], the F/T device model's)
            ft.publish(t, est[13 + 2 * n:19 + 2 * n] if self.spec.devices.enabled else w.wrench_ee(s))
        # the IMU (ideal): body rate, and specific force R^T (a_W + g e_z) over the last step
        v_exact = v_W if est is values else quat_wxyz_R_times(values[3:7], values[7:10])
        v_prev = v_exact if ve.v_prev is None else ve.v_prev
        ve.v_prev = v_exact
        g = self.spec.vehicle.gravity_mps2
        a_W = ((v_exact[0] - v_prev[0]) / self.spec.dt_s, (v_exact[1] - v_prev[1]) / self.spec.dt_s,
               (v_exact[2] - v_prev[2]) / self.spec.dt_s + g)
        accel_B = quat_wxyz_R_T_times(values[3:7], a_W)
        return VehicleReport(time_s=t, p_W=p, quat_WB=quat, v_W=v_W, w_B=w_B, gyro_B=tuple(values[10:13]),
                             accel_B=accel_B, target=target, rates_sp_B=rates_sp)

    def _target(self, ve: Px4Vehicle, sp, quat, rate_B):
        """`flown_target` of sp, reused while it is the same setpoint and needs no attitude
        (no yaw feed-forward, not rates only): one AttitudeTarget per setpoint, not per step."""
        last = ve.target
        if last is not None and last[0] is sp:
            return last[1]
        target = flown_target(sp, quat, rate_B)
        if sp.attitude and (math.isnan(sp.yaw_move_rate_rad_s) or sp.yaw_move_rate_rad_s == 0.0):
            ve.target = (sp, target)
        return target

    def _track_takeoff(self, t: float, reports: dict) -> None:
        """Before the mission clock's zero: each vehicle's height, tilt and mode (the take-off, which
        the mission's outcome does not see), every TAKEOFF_TRACK_EVERY steps."""
        for s, r in reports.items():
            w, x, y, z = r.quat_WB
            tilt = math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (x * x + y * y)))))
            ve = self.vehicles[s]
            c = ve.commander
            self.takeoff_track.setdefault(str(s), []).append(
                {"t_s": round(t, 3), "z_m": round(r.p_W[2], 4), "tilt_deg": round(tilt, 2),
                 "thrust": round(ve.throttle, 3), "armed": c.armed, "landed": c.landed,
                 "mode": cm.nav_name(c.nav_state)})

    def _motors_off(self, ve: Px4Vehicle, tau_q) -> None:
        ve.throttle = 0.0
        self.core.world.apply_rotors(ve.sysid, [0.0] * self.spec.vehicle.rotors.count, tau_q)

    def _count_saturation(self, s: int, mission_t: float | None, rotors: bool, joints: bool, axes) -> None:
        if (rotors or joints) and mission_t is not None and mission_t >= 0.0:
            if self.core.outcome.saturation(s, mission_t, rotors, joints, axes):
                self.log(f"sysid {s}: command saturated at mission t = {mission_t:.3f} s; counted in outcome.json, "
                         f"further ones not printed")

    def _truth(self, mission_t: float) -> None:
        w = self.core.world
        gt = dataclasses.replace(w.ground_truth(), time_s=mission_t)
        self.core.outcome.add(gt, {s: w.wrench_ee(s) for s in self.sysids})
        if self.on_truth is not None:
            self.on_truth(gt)

    # -- the result -----------------------------------------------------------------------
    def _commanded(self) -> list[tuple[float, int, str]]:
        """What the verdict counts as commanded within the mission: a LAND asked for (NAV_LAND
        or DO_SET_MODE) and a forced disarm in the air, at mission times 0..duration_s."""
        out = []
        t0 = self.mission_t0_s
        if t0 is None:
            return out
        for s, ve in self.vehicles.items():
            for e in ve.commander.events:
                tm = e["t_s"] - t0
                if not 0.0 <= tm < self.spec.duration_s:
                    continue
                if e["event"] == "mode request" and e.get("mode") == "LAND":
                    out.append((tm, s, "land"))
                elif e["event"] == "disarmed" and e.get("in_air") and e.get("by") == "command":
                    out.append((tm, s, "disarm"))
        return out

    def _failovers(self) -> list[tuple[float, int, str, float | None]]:
        """Each vehicle taken out of OFFBOARD while armed (in flight or about to fly), before the mission's
        end, at mission time t (negative in the take-off): (t, sysid, why, t of its next OFFBOARD
        engage or None). A LAND asked for is `_commanded`'s."""
        out = []
        t0 = self.mission_t0_s
        if t0 is None:
            return out
        for s, ve in self.vehicles.items():
            engaged, pending, why = False, None, None
            for e in ve.commander.events:
                tm = e["t_s"] - t0
                if tm >= self.spec.duration_s:
                    break
                kind = e["event"]
                if kind == "failsafe":
                    why = f"failsafe: {e.get('cause', '?')}"
                elif kind == "mode request":
                    why = f"{e.get('mode')} asked for"
                elif kind == "mode":
                    if e.get("to") == "OFFBOARD":
                        if pending is not None:
                            out.append((*pending, tm))
                            pending = None
                        engaged, why = True, None
                    elif e.get("from") == "OFFBOARD" and engaged and e.get("armed"):
                        engaged = False
                        if not (e.get("to") == "LAND" and why == "LAND asked for"):
                            pending = (tm, s, why or f"to {e.get('to')}")
            if pending is not None:
                out.append((*pending, None))
        return out

    def result(self, wall_s: float | None = None) -> dict:
        """The run's outcome (outcome.json's free-running part)."""
        core, spec = self.core, self.spec
        if core is None:
            raise RuntimeError("FreeRun.result() before open()")
        t0 = self.mission_t0_s
        complete = t0 is not None
        if complete and self._opened and core.world.time_s - t0 >= 0.0:
            self._truth(core.world.time_s - t0)
        failsafe_at_end = [s for s, ve in self.vehicles.items() if ve.commander.failsafe]
        verdict = judge(core.outcome, spec.success, self.mission_steps, failsafe_at_end, (), (), self._commanded(),
                        self._failovers())
        timing = self.pacer.to_dict() if self.pacer is not None else {}
        if self._gc is not None:
            timing["gc"] = self._gc
        if self._cpu_s is not None and timing.get("steps"):
            # on-CPU time per step (waits in select are off-CPU): the step's compute without the time
            # the processor ran something else, which mean_step_compute_s (wall) includes
            timing["cpu_s"] = self._cpu_s
            timing["mean_step_cpu_s"] = self._cpu_s / timing["steps"]
        sim_s = core.world.time_s if self._opened else 0.0
        vehicles = {}
        for ve in self.vehicles.values():
            port, c = ve.port, ve.commander
            vehicles[str(port.sysid)] = {
                "index": port.index, "port": port.describe() if port.sock is not None else str(port.endpoint),
                "offboard_engaged_s": c.offboard_engaged_s, "armed_at_end": c.armed,
                "mode_at_end": cm.nav_name(c.nav_state), "landed_at_end": c.landed, "failsafe_at_end": c.failsafe,
                "events": c.events, "link": dataclasses.asdict(port.stats),
                "impairment": None if port.impaired is None else vars(port.impaired.stats),
                "start_p_WB_m": ve.start.p_WB.tolist()}
        for g in self.gcs_ports:
            vehicles[str(g.sysid)]["gcs"] = {
                "port": g.describe() if g.sock is not None else str(g.endpoint), "signing": g.signing,
                "link": dataclasses.asdict(g.stats)}
        return {"mode": "free-running", "speed": self.speed, "rate_hz": spec.rate_hz, "status": self.status,
                "mission_t0_s": t0, "mission_t0_given": self._t0_given, "takeoff_s": TAKEOFF_S,
                "sim_time_s": sim_s, "wall_s": wall_s, "timing": timing, "takeoff_track": self.takeoff_track,
                "real_time_factor": sim_s / wall_s if wall_s else None,
                "ports": [vehicles[str(s)]["port"] for s in self.sysids],
                "gcs_ports": [vehicles[str(s)]["gcs"]["port"] for s in self.sysids] if self.gcs_ports else [],
                "vehicles": vehicles,
                "verdict": verdict.to_dict() if complete else {
                    "status": "incomplete", "success": False, "failure_class": None, "failures": [],
                    "incomplete": "the mission clock never started (no OFFBOARD engage)",
                    "text": "mission incomplete: no vehicle engaged OFFBOARD"},
                **core.outcome.to_dict()}


def _state(values, n: int) -> AmState:
    """The AmState of one vehicle's `World.flight_values` (velocities in B)."""
    return AmState(p_WB=np.array(values[0:3]), R_WB=unit_quat_wxyz_to_R(values[3:7]), v_B=np.array(values[7:10]), w_B=np.array(values[10:13]),
                   q=np.array(values[13:13 + n]), qdot=np.array(values[13 + n:13 + 2 * n]))


def endpoints_for(spec: ScenarioSpec, texts: Sequence[str] | None) -> list[Endpoint]:
    """One onboard endpoint per vehicle from --onboard values (none: PX4 SITL's ports);
    `simulator.px4.port.PortError` if their count or one of them is wrong."""
    from .px4.port import PortError, onboard_endpoint
    n = len(spec.ams)
    if texts and len(texts) != n:
        raise PortError(f"--onboard given {len(texts)} times for {n} vehicles: give one per [[am]] (in order) or none")
    return [onboard_endpoint(i, texts[i] if texts else None) for i in range(n)]
