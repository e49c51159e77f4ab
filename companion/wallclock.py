"""The companion's wall-clock loop: one AM's controller flying a PX4 (the free-running
simulator's, or a real one) in OFFBOARD, with its own timer.

What a step does, at [scenario].control_rate_hz on a drift-free timer (`looptimer.DeadlineTimer`):

1. (engaged) send the servos' sync read instruction; serve the links without blocking: the
   autopilot's (samples, TIMESYNC, ACKs), the F/T sensor's;
2. collect the servos' answers (joint angles, rates, measured torques), timestamped at the read:
   the bus's round trip overlaps step 1 rather than adding to it;
3. take each source's latest sample and its age in the autopilot's time base (TIMESYNC); a
   source older than its limit (`sampling.StalenessLimits`) makes the step hold its last
   setpoint, and beyond `handback_s` the companion hands the vehicle back (HOLD) and yields;
4. carry the base estimate over its age (`sampling.predict_base`) and build the sensor frame
   the controller takes, at the mission time t (below), with the step's measured dt;
5. run the controller (`companion.pilot.Pilot`, the same as in lockstep) and send its
   attitude target (SET_ATTITUDE_TARGET) and its joint torques (the servos' Goal Current)
   at once; then the bookkeeping (outcome, telemetry, the loop's own measurements).

The mission clock starts when the autopilot reports OFFBOARD and armed (the handshake,
`amlink.offboard_handshake`): t = (autopilot time - engage time) - TAKEOFF_S. For t < 0 the
references blend from where the vehicle stood on the ground to the mission's start
(`amcore.mission.join_blend`, the restart's blend): the take-off. Before the engage the loop
streams a level, zero-thrust target, as PX4 wants a live stream before it accepts OFFBOARD.

The loop knows nothing of which clock drives it: `clock` is monotonic ns, the autopilot's
time comes from the link's time base, and the period is the control period in the
autopilot's time (so an autopilot whose clock runs at a speed factor is followed).
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from amcore.mission import TAKEOFF_S
from amcore.so3 import Rz, R_to_quat_wxyz
from amlink.types import AttitudeTarget, sensor_frame_from_wire, with_autopilot_reports

from .devices import DeviceError
from .looptimer import DeadlineTimer, LoopStats
from .sampling import BaseEstimate, StalenessLimits, frame_values, predict_base


# the handshake's states in which an armed vehicle is flown by the controller (`_flies`)
_TAKEOVER_STATES = ("priming", "request_offboard", "arming", "wait_engaged")
# PX4's COM_OF_LOSS_T default [s] (src/modules/commander/commander_params.c): the offboard
# stream's age at which Commander fails over (offboardCheck.cpp)
COM_OF_LOSS_T_S = 1.0
STATS_EVERY_S = 2.0  # the loop's measurements to telemetry this often (`WallClockLoop`'s on_stats)


@dataclass
class WallClockResult:
    why: str  # why the loop ended
    code: int  # the process's exit code for it
    engaged_fc_us: float | None = None
    steps: int = 0
    held_steps: int = 0
    stats: dict = field(default_factory=dict)


class WallClockLoop:
    def __init__(self, pilot, autopilot, arm, wrench, *, clock: Callable[[], int] = time.monotonic_ns,
                 limits: StalenessLimits = StalenessLimits(), predict: bool = True,
                 on_step: Callable | None = None, log: Callable[[str], None] = lambda _m: None,
                 link_timeout_s: float = 5.0, mission_start_s: float | None = None,
                 on_stats: Callable[[float, dict], None] | None = None, stats_every_s: float = STATS_EVERY_S,
                 offboard_loss_s: float = COM_OF_LOSS_T_S) -> None:
        """pilot: companion.pilot.Pilot. autopilot: companion.autopilot.Autopilot (the PX4 link
        and its handshake). arm: the servo bus client (companion.devices.arm). wrench: the F/T
        client (companion.devices.netft), or None (no wrist sensor: a zero wrench).
        on_step(t, phase, result): telemetry. predict: carry the estimate over its age.
        on_stats(t, stats): the loop's measurements so far (LoopStats.to_dict) every stats_every_s
        of the loop's clock and at its end, t the mission time (telemetry: the MCAP records them).
        mission_start_s: the autopilot's boot time [s] at which the mission's t = 0 comes, shared
        by a team whose autopilots share a clock (one simulator; or synchronized clocks); the
        team's clock counts whenever this companion engages: engaged before it, the take-off blends
        into it; engaged after it (a companion restarted, or started late), the companion joins
        the mission in progress with the restart's blend (companion.pilot). None: the engage +
        TAKEOFF_S. offboard_loss_s: the autopilot's offboard loss timeout (PX4's COM_OF_LOSS_T);
        engaged, a loop that has sent nothing for longer (its process stalled) yields without
        sending again: the autopilot has failed over, and a late setpoint would undo that."""
        self.pilot, self.ap, self.arm, self.wrench = pilot, autopilot, arm, wrench
        self.clock, self.limits, self.predict, self.on_step, self.log = clock, limits, predict, on_step, log
        self.link_timeout_s = link_timeout_s
        self.mission_start_us = None if mission_start_s is None else mission_start_s * 1e6
        self.t0_fc_us: float | None = None  # the autopilot's time of the mission's t = 0
        spec = pilot.spec
        self.control_dt_s = spec.control_dt_s
        self.timer = DeadlineTimer(round(self.control_dt_s * 1e9), clock)
        self.stats = LoopStats()
        self.n = pilot.model.n
        self.steps = 0
        self.held = 0
        self._last_sp = None
        self._last_sent_ns: int | None = None  # the last setpoint sent while engaged
        self.offboard_loss_s = offboard_loss_s
        self._rate = 1.0  # the autopilot's clock rate against ours
        self._takeoff_started = False
        self._level_q = R_to_quat_wxyz(Rz(pilot.mission.psi))  # level at the mission's heading
        # SET_ATTITUDE_TARGET's thrust that carries the whole AM (m g over thrust 1's force)
        self._hover_thrust = min(1.0, pilot.model.mass_kg * spec.vehicle.gravity_mps2 / pilot.thrust_max_n)
        self.arm_errors = 0
        self.on_stats, self._stats_every_ns = on_stats, round(stats_every_s * 1e9)
        self._next_stats_ns: int | None = None
        self._t = 0.0  # the last step's mission time [s]

    # -- the step's inputs -------------------------------------------------------
    def _age_s(self, fc_now_us: float, sample_fc_us: float) -> float:
        return max(0.0, (fc_now_us - sample_fc_us) * 1e-6)

    def _inputs(self, now_ns: int, fc_now_us: float, mission_t: float = 0.0):
        """(values, attitude_target, joint_effort, stale sources, freshest rx ns) of this step."""
        stale = []
        odo = self.ap.odometry
        att = self.ap.attitude
        if odo is None:
            return None, None, None, ["odometry"], None
        a_odo = self._age_s(fc_now_us, odo.t_us)
        self.stats.sample_age("odometry", round(a_odo * 1e9), a_odo > self.limits.odometry_hold_s)
        if a_odo > self.limits.odometry_hold_s:
            stale.append("odometry")
        if att is not None:
            a_att = self._age_s(fc_now_us, att.t_us)
            self.stats.sample_age("attitude", round(a_att * 1e9), a_att > self.limits.attitude_hold_s)
            if a_att > self.limits.attitude_hold_s:
                att = None  # the odometry's attitude then
        base = predict_base(odo, fc_now_us, att) if self.predict else (att and _with_attitude(odo, att) or odo)
        try:
            # the sync read the step sent at its start (`_request_joints`), else one now; its
            # age counts from its request
            joints = self.arm.collect() if getattr(self.arm, "requested", False) else self.arm.read()
        except DeviceError as exc:
            joints = None
            self.arm_errors += 1
            if self.arm_errors == 1:
                self.log(f"servo bus: {exc} (counted; the step holds)")
        if joints is None:
            stale.append("joints")
            q, qdot, effort = np.zeros(self.n), np.zeros(self.n), None
        else:
            a_j = (self.clock() - joints.t_ns + joints.rtt_ns) * 1e-9  # from the read's start
            self.stats.sample_age("joints", round(a_j * 1e9), a_j > self.limits.joints_hold_s)
            if a_j > self.limits.joints_hold_s:
                stale.append("joints")
            q, qdot, effort = joints.q, joints.qdot, joints.tau_measured_nm
        wrench = (0.0,) * 6
        if self.wrench is not None:
            w = self.wrench.read()
            if w is None:
                stale.append("wrench")
            else:
                a_w = (now_ns - w.t_ns) * 1e-9
                self.stats.sample_age("wrench", round(a_w * 1e9), a_w > self.limits.wrench_hold_s)
                if a_w > self.limits.wrench_hold_s:
                    stale.append("wrench")
                # in the take-off (t < 0) the pad may still rest on the ground and the sensor is not
                # tared: what it reads is no contact the law is to compensate (the lockstep's flight
                # starts in the air), so the law takes none until the mission starts
                wrench = w.wrench_E if mission_t >= 0.0 else (0.0,) * 6
        rx = self.ap.odometry_rx_ns  # the latency below is from the estimate's arrival
        values = frame_values(base, q, qdot, wrench)
        return values, self.ap.attitude_target, effort, stale, rx

    # -- the loop ------------------------------------------------------------------
    def run(self, stop: Callable[[], bool] = lambda: False) -> WallClockResult:
        ap = self.ap
        self.timer.start()
        since_stale_ns: int | None = None
        while not stop():
            wait = self.timer.wait_s()
            if wait > 0:
                ap.wait(wait)  # serves the link while it waits (select on its socket)
            if self.timer.wait_s() > 0:
                continue
            late = self.timer.fire()
            start = self.clock()
            self.stats.step_started(start, late)
            if self._flies(ap.state):
                self._request_joints()  # the servos answer while the link is served
            ap.poll(start)
            if self.wrench is not None:
                self.wrench.poll()
            rate = ap.clock_rate()
            if rate and abs(rate - self._rate) > 1e-3 * self._rate:  # follow the autopilot's clock speed
                self._rate = rate
                self.timer.set_period(round(self.control_dt_s * 1e9 / rate))
            if ap.silent_for_s(start) > self.link_timeout_s:
                return self._end(f"the autopilot has been silent for {self.link_timeout_s:g} s", 1)
            state = ap.state
            if state == "failed":
                return self._end(f"the offboard handshake failed: {ap.error}", 1)
            if state == "yielded":
                return self._end(f"yielded: {ap.error or 'the vehicle left OFFBOARD'}", 0)
            fc_now = ap.fc_time_us(start)
            if not self._flies(state) or fc_now is None:
                self._drop_joints()
                ap.stream_idle(self._idle_target())  # PX4 accepts OFFBOARD only on a live stream
                continue
            if self.t0_fc_us is None:
                engaged_us = ap.engaged_fc_us
                self.t0_fc_us = ((fc_now if engaged_us is None else engaged_us) + TAKEOFF_S * 1e6
                                 if self.mission_start_us is None else self.mission_start_us)
                if engaged_us is not None:
                    self.log(f"OFFBOARD engaged at autopilot time {engaged_us * 1e-6:.3f} s; the mission "
                             f"starts at {self.t0_fc_us * 1e-6:.3f} s")
                else:
                    self.log(f"the vehicle is armed: flying it from autopilot time {fc_now * 1e-6:.3f} s, before "
                             f"OFFBOARD is engaged; the mission starts at {self.t0_fc_us * 1e-6:.3f} s")
            t = (fc_now - self.t0_fc_us) * 1e-6
            values, att_report, effort, stale, rx = self._inputs(start, fc_now, t)
            if stale:
                since_stale_ns = since_stale_ns or start
                if (start - since_stale_ns) * 1e-9 > self.limits.handback_s:
                    ap.hand_back(f"inputs stale: {', '.join(stale)}")
                    return self._end(f"handed back to the autopilot (HOLD): stale {', '.join(stale)}", 1)
                self.held += 1
                if self._last_sp is not None:
                    if (why := self._stalled()) is not None:
                        return self._end(why, 0)
                    ap.send_setpoint(self._last_sp.attitude)  # the autopilot keeps flying the last one
                    self._last_sent_ns = self.clock()
                else:
                    ap.stream_idle(self._idle_target())
                continue
            since_stale_ns = None
            if not self._takeoff_started:
                self._takeoff_started = True
                self.arm.start_current_control()  # the servos held their pose until now
                if t < 0.0:  # before the mission's start: the take-off's blend into it
                    self.pilot.start_takeoff(values, t)
                else:  # the mission is under way (a restart): the pilot joins it where the vehicle is
                    self.log(f"joining the mission at t = {t:.2f} s (the restart's blend)")
            frame = sensor_frame_from_wire(self.steps, t, values, self.n, 0)
            frame = with_autopilot_reports(frame, effort, att_report)
            sp, _, res = self.pilot.command(frame)
            if (why := self._stalled()) is not None:
                return self._end(why, 0)
            ap.send_setpoint(sp.attitude)
            self._last_sent_ns = self.clock()
            self.arm.write_torques(sp.tau_q_nm)
            self.stats.sent(start, rx, self.clock())
            self._last_sp = sp
            self.steps += 1
            if t >= 0.0:
                self.pilot.record(t, res)
            if self.on_step is not None:
                self.on_step(t, self.pilot.mission.phase(max(t, 0.0)), res)
            self._t = t
            if self.on_stats is not None:
                if self._next_stats_ns is None:
                    self._next_stats_ns = start + self._stats_every_ns
                elif start >= self._next_stats_ns:
                    self._next_stats_ns += self._stats_every_ns
                    self.on_stats(t, self.stats.to_dict(self.timer))
        return self._end("stopped", 0)

    def _stalled(self) -> str | None:
        """Why nothing may be sent any more, checked just before each setpoint once engaged (the
        process may have been stopped anywhere in the step, even after its inputs were read):
        if the last setpoint went out longer ago than the autopilot's offboard loss timeout, in
        the autopilot's time, PX4 has failed over, and a setpoint now would clear that failsafe
        and give the vehicle back to this loop's stale state."""
        if self._last_sent_ns is None:
            return None
        gap_s = (self.clock() - self._last_sent_ns) * 1e-9 * self._rate
        if gap_s <= self.offboard_loss_s:
            return None
        return (f"yielded: no setpoint sent for {gap_s:.2f} s of the autopilot's clock, over its offboard loss "
                f"timeout (COM_OF_LOSS_T {self.offboard_loss_s:g} s): the autopilot has failed over; not sending again")

    def _request_joints(self) -> None:
        """Send this step's servo sync read now (an arm client with `request`), to be collected
        in `_inputs` after the autopilot's link has been served: the bus's round trip (the
        simulator answers between its physics steps) overlaps the link's work instead of
        adding to the step's latency. A failed request is counted there (the read is retried)."""
        request = getattr(self.arm, "request", None)
        if request is None:
            return
        try:
            request()
        except DeviceError:
            pass  # `_inputs` reads again and counts the error

    def _drop_joints(self) -> None:
        """Take the answers of a sync read this step will not use off the bus."""
        if getattr(self.arm, "requested", False):
            try:
                self.arm.collect()
            except DeviceError:
                pass

    def _flies(self, state: str) -> bool:
        """Whether this step flies the controller: engaged; or, the vehicle armed (a restart, a
        vehicle handed over in the air), from the priming on. An armed vehicle flies the stream
        that primes OFFBOARD as soon as it is in OFFBOARD: at once if PX4's failover (its user
        intention still OFFBOARD) clears on the stream's first setpoint, else when the mode
        request is accepted; either comes before the HEARTBEAT that shows it (up to a second
        later). So the priming stream is the controller's own, and the take-over is bumpless."""
        return state == "engaged" or (bool(self.ap.armed) and state in _TAKEOVER_STATES)

    def _idle_target(self) -> AttitudeTarget | None:
        """What the loop streams before it flies (PX4 accepts OFFBOARD only on a live stream).

        Before any HEARTBEAT, nothing (an armed vehicle would fly it). Disarmed: level at the
        mission's heading, zero thrust (the motors are off). Armed, before the controller
        flies (the streams still being asked for, or no time base yet): the attitude the
        autopilot reports (ATTITUDE_QUATERNION) at the whole AM's hover thrust, which holds
        the vehicle where zero thrust would drop it; with no report yet, nothing."""
        if self.ap.armed is None:
            return None
        if self.ap.armed:
            att = self.ap.attitude
            if att is None:
                return None
            return AttitudeTarget(0, quat_wxyz=np.asarray(att.q_WB_wxyz, dtype=float), rates_rad_s=np.zeros(3),
                                  thrust_normalized=self._hover_thrust)
        return AttitudeTarget(0, quat_wxyz=self._level_q, rates_rad_s=np.zeros(3), thrust_normalized=0.0)

    def _end(self, why: str, code: int) -> WallClockResult:
        self._drop_joints()
        stats = self.stats.to_dict(self.timer)
        stats["mission_t0_fc_s"] = None if self.t0_fc_us is None else self.t0_fc_us * 1e-6
        if self.on_stats is not None and self.steps:
            self.on_stats(self._t, stats)
        return WallClockResult(why=why, code=code, engaged_fc_us=self.ap.engaged_fc_us, steps=self.steps,
                               held_steps=self.held, stats=stats)


def _with_attitude(odo: BaseEstimate, att: BaseEstimate) -> BaseEstimate:
    """The odometry's position and velocity with the fresher attitude sample's attitude and rates
    (no prediction): the velocity re-expressed in the body frame it is read in."""
    from amcore.so3 import quat_wxyz_to_R
    v_W = quat_wxyz_to_R(np.asarray(odo.q_WB_wxyz)) @ np.asarray(odo.v_B)
    v_B = quat_wxyz_to_R(np.asarray(att.q_WB_wxyz)).T @ v_W
    return BaseEstimate(att.t_us, odo.p_WB, att.q_WB_wxyz, tuple(v_B.tolist()), att.w_B)

