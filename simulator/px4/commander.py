"""One vehicle's PX4 commander: arming, nav state, land detector, offboard liveness and
failover (pure: no I/O, no clock of its own; every call takes the autopilot's time t [s]).

Followed: PX4-Autopilot v1.14.3 (tag v1.14.3). What it does, with its source:

Start. Disarmed, landed, in Hold: UserModeIntention.hpp:76 starts the user intention at
NAVIGATION_STATE_AUTO_LOITER.

Modes (MAV_CMD_DO_SET_MODE, Commander.cpp:736-847). A custom main/sub mode becomes a nav state
(AUTO with sub mode 0 is MISSION; an unknown AUTO sub mode is TEMPORARILY_REJECTED; an unknown
main mode changes nothing and is ACCEPTED, :827-845). UserModeIntention::change
(UserModeIntention.cpp:43-75) ALWAYS accepts a change while disarmed; armed, only into a mode
that can run, else TEMPORARILY_REJECTED. So OFFBOARD without a live setpoint stream is
refused only while armed; disarmed it is accepted, and then arming is refused (below).
MAV_CMD_NAV_LAND is a change to AUTO_LAND (:1017-1029). Can-run here (mode_requirements.cpp,
modeCheck.cpp): OFFBOARD needs the offboard signal (modeCheck.cpp:124-134); the stick modes
(MANUAL, STAB, ALTCTL, POSCTL, ACRO) need manual control, which this link never has
(:141-163); MISSION needs a mission, never uploaded here (:112-123); HOLD and LAND can run
(the simulator's estimate counts as a valid local and global position: the EKF origin is
taken as set). Modes the emulation does not fly (TAKEOFF, RTL, FOLLOW_TARGET, PRECLAND,
ORBIT, VTOL_TAKEOFF, DESCEND, TERMINATION) answer UNSUPPORTED with a STATUSTEXT (a
deviation: PX4 would switch to them).

Arming (MAV_CMD_COMPONENT_ARM_DISARM, Commander.cpp:849-901; arm() :534-593,
ArmStateMachine.cpp:52-72). param1 not 0 or 1: UNSUPPORTED. Arming runs the pre-arm checks
for the current nav state even when forced from MAVLink (arm(reason, from_external || !forced),
:880); they fail for a mode that cannot run or prevents arming (LAND, RTL, DESCEND,
TERMINATION..., mode_requirements.cpp `mode_req_prevent_arming`; modeCheck.cpp:180-189), so
arming in OFFBOARD with no setpoint stream is TEMPORARILY_REJECTED ("No offboard signal").
Already armed: ACCEPTED. Disarming without force (param2 = 21196) is refused unless the land
detector says landed or maybe-landed (disarm() :595-613): TEMPORARILY_REJECTED. After a
disarm the user intention goes back to the last mode that does not prevent arming
(UserModeIntention::onDisarm, :78-81).

Offboard liveness (offboardCheck.cpp:38-66): the signal is lost unless the last
offboard_control_mode (any SET_ATTITUDE_TARGET with an attitude or roll and pitch rates,
`simulator.px4.setpoint`) is younger than COM_OF_LOSS_T: t < t_last + COM_OF_LOSS_T.

Failover (failsafe.cpp:277-325, 459-461, 480-490; framework.cpp:426-429): only armed; when
the user intention is OFFBOARD and the signal is lost, the COM_OBL_RC_ACT action replaces it:
0 Position, 1 Altitude, 2 Manual(Stabilized), 3 Return, 4 Land, 5 Hold, 6 Terminate, 7 Disarm.
When the signal comes back the action clears (ClearCondition::WhenConditionClears,
framework.h:186) and the vehicle is in OFFBOARD again; a mode change by the user takes over
(UserTakeoverAllowed::Always). One deviation, kept for the lockstep's failsafe (hold, then
land: `simulator.failsafe`, hold_s = 5 s = COM_FAIL_ACT_T's default): the action is preceded
by `offboard_loss_hold_s` of Hold (PX4 v1.14.3 applies its COM_FAIL_ACT_T hold only to
actions added with UserTakeoverAllowed::Auto, framework.cpp:330-340, which the mode fallback
is not; offboard_loss_hold_s = 0 is PX4's behaviour). Our COM_OBL_RC_ACT default is 4 (Land),
PX4's 0 (Position mode, which with centred sticks holds): with the hold first this is "hold,
then land". The stick actions (0, 1, 2) are flown as Hold, Return as Land (home is below).

Land detector (land_detector/MulticopterLandDetector.cpp:159-306, LandDetector.cpp:137-172):
ground contact = low throttle (<= MPC_THR_MIN + 0.3 (hover - MPC_THR_MIN)) and no vertical
(|v_z| < LNDMC_Z_VEL_MAX, x2.5 once landed) or horizontal (< LNDMC_XY_VEL_MAX) movement, and,
in a climb-rate mode (HOLD, LAND), a commanded descent until maybe-landed; maybe landed =
minimum thrust (climb-rate modes: MPC_THR_MIN + 0.1 (hover - MPC_THR_MIN); else
MPC_MANTHR_MIN + 0.01) and no roll/pitch rotation (< LNDMC_ROT_MAX, x2.5 once landed) and
ground contact; landed = maybe landed; each state needs LNDMC_TRIG_TIME / 3 to become true
and leaves at once; disarmed is always landed. (No free-fall or distance-sensor terms.)

Auto-disarm (Commander.cpp:2127-2178): armed and taken off since arming, landed for
COM_DISARM_LAND -> disarm; armed and not taken off within COM_DISARM_PRFLT -> disarm. Takeoff
is detected when the land detector leaves landed while armed (:1763-1770, :1980-1993).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

from amlink import px4

from .setpoint import OffboardSetpoint


class NavState(IntEnum):
    """PX4's vehicle_status NAVIGATION_STATE_* (msg/VehicleStatus.msg:39-59)."""

    MANUAL = 0
    ALTCTL = 1
    POSCTL = 2
    AUTO_MISSION = 3
    AUTO_LOITER = 4
    AUTO_RTL = 5
    ACRO = 10
    DESCEND = 12
    TERMINATION = 13
    OFFBOARD = 14
    STAB = 15
    AUTO_TAKEOFF = 17
    AUTO_LAND = 18
    AUTO_FOLLOW_TARGET = 19
    AUTO_PRECLAND = 20
    ORBIT = 21
    AUTO_VTOL_TAKEOFF = 22


# px4_custom_mode.h get_px4_custom_mode (:93-180): nav state -> (main mode, sub mode)
_CUSTOM = {
    NavState.MANUAL: (px4.MAIN_MANUAL, 0), NavState.ALTCTL: (px4.MAIN_ALTCTL, 0),
    NavState.POSCTL: (px4.MAIN_POSCTL, 0), NavState.AUTO_MISSION: (px4.MAIN_AUTO, px4.SUB_AUTO_MISSION),
    NavState.AUTO_LOITER: (px4.MAIN_AUTO, px4.SUB_AUTO_LOITER), NavState.AUTO_RTL: (px4.MAIN_AUTO, px4.SUB_AUTO_RTL),
    NavState.ACRO: (px4.MAIN_ACRO, 0), NavState.DESCEND: (px4.MAIN_AUTO, px4.SUB_AUTO_LAND),
    NavState.TERMINATION: (px4.MAIN_MANUAL, 0), NavState.OFFBOARD: (px4.MAIN_OFFBOARD, 0),
    NavState.STAB: (px4.MAIN_STABILIZED, 0), NavState.AUTO_TAKEOFF: (px4.MAIN_AUTO, px4.SUB_AUTO_TAKEOFF),
    NavState.AUTO_LAND: (px4.MAIN_AUTO, px4.SUB_AUTO_LAND),
}
_AUTO_SUB = {px4.SUB_AUTO_LOITER: NavState.AUTO_LOITER, px4.SUB_AUTO_MISSION: NavState.AUTO_MISSION,
             px4.SUB_AUTO_RTL: NavState.AUTO_RTL, px4.SUB_AUTO_TAKEOFF: NavState.AUTO_TAKEOFF,
             px4.SUB_AUTO_LAND: NavState.AUTO_LAND}
_MAIN = {px4.MAIN_MANUAL: NavState.MANUAL, px4.MAIN_ALTCTL: NavState.ALTCTL, px4.MAIN_POSCTL: NavState.POSCTL,
         px4.MAIN_ACRO: NavState.ACRO, px4.MAIN_STABILIZED: NavState.STAB, px4.MAIN_OFFBOARD: NavState.OFFBOARD}
STICK_MODES = frozenset({NavState.MANUAL, NavState.ALTCTL, NavState.POSCTL, NavState.STAB, NavState.ACRO})
# mode_requirements.cpp: modes with mode_req_prevent_arming
PREVENTS_ARMING = frozenset({NavState.AUTO_RTL, NavState.DESCEND, NavState.TERMINATION, NavState.AUTO_LAND,
                             NavState.AUTO_FOLLOW_TARGET, NavState.AUTO_PRECLAND, NavState.ORBIT})
# what the emulation flies (module doc)
EMULATED = frozenset({NavState.OFFBOARD, NavState.AUTO_LOITER, NavState.AUTO_LAND, NavState.AUTO_MISSION}) | STICK_MODES
HOLDING = frozenset({NavState.AUTO_LOITER, NavState.POSCTL, NavState.ALTCTL, NavState.STAB})  # flown as Hold
LANDING = frozenset({NavState.AUTO_LAND, NavState.AUTO_RTL})  # flown as Land

# COM_OBL_RC_ACT (commander_params.c:326-342) -> the nav state it selects (failsafe.cpp:277-325)
OBL_ACTIONS = {0: NavState.POSCTL, 1: NavState.ALTCTL, 2: NavState.STAB, 3: NavState.AUTO_RTL,
               4: NavState.AUTO_LAND, 5: NavState.AUTO_LOITER, 6: NavState.TERMINATION}
OBL_DISARM = 7

# vehicle_command.msg / vehicle_command_ack.msg (the MAVLink values)
CMD_NAV_LAND, CMD_DO_SET_MODE, CMD_COMPONENT_ARM_DISARM = 21, 176, 400
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4
RESULT_NAMES = {ACCEPTED: "ACCEPTED", TEMPORARILY_REJECTED: "TEMPORARILY_REJECTED", DENIED: "DENIED",
                UNSUPPORTED: "UNSUPPORTED", FAILED: "FAILED"}
FORCE_MAGIC = 21196  # ARM_DISARM param2 that forces (Commander.cpp:863)
MODE_FLAG_CUSTOM_MODE_ENABLED = 1  # MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
MODE_FLAG_AUTO_ENABLED, MODE_FLAG_MANUAL_INPUT_ENABLED = 4, 64  # DO_SET_MODE without custom mode
MODE_FLAG_GUIDED_ENABLED, MODE_FLAG_STABILIZE_ENABLED, MODE_FLAG_SAFETY_ARMED = 8, 16, 128
# MAV_SEVERITY
CRITICAL, WARNING, NOTICE, INFO = 2, 4, 5, 6


def custom_mode_of(nav: NavState) -> int:
    """HEARTBEAT.custom_mode of a nav state (px4_custom_mode.h)."""
    return px4.custom_mode(*_CUSTOM.get(nav, (0, 0)))


def nav_name(nav: NavState) -> str:
    return px4.mode_name(custom_mode_of(nav)) if nav in _CUSTOM else nav.name


@dataclass(frozen=True)
class CommanderParams:
    """PX4 parameters under their names and units (PX4 v1.14.3 defaults unless noted):
    commander_params.c (COM_*), land_detector_params_mc.c (LNDMC_*), mc_pos_control (MPC_*).
    MPC_THR_HOVER: set it to the vehicle's hover thrust (`for_vehicle`), as a tuned PX4 is.
    COM_OBL_RC_ACT and offboard_loss_hold_s: see the module doc (PX4: 0 and none)."""

    COM_OF_LOSS_T: float = 1.0  # [s]
    COM_OBL_RC_ACT: int = 4  # Land (PX4's default: 0, Position mode)
    offboard_loss_hold_s: float = 5.0  # Hold before the action [s] (not in PX4, see above)
    COM_DISARM_LAND: float = 2.0  # [s]
    COM_DISARM_PRFLT: float = 10.0  # [s]
    LNDMC_TRIG_TIME: float = 1.0  # [s]
    LNDMC_Z_VEL_MAX: float = 0.25  # [m/s]
    LNDMC_XY_VEL_MAX: float = 1.5  # [m/s]
    LNDMC_ROT_MAX: float = 20.0  # [deg/s]
    MPC_THR_MIN: float = 0.12
    MPC_MANTHR_MIN: float = 0.08
    MPC_THR_HOVER: float = 0.5

    def __post_init__(self) -> None:
        if self.COM_OBL_RC_ACT not in (*OBL_ACTIONS, OBL_DISARM):
            raise ValueError(f"COM_OBL_RC_ACT must be 0..7, got {self.COM_OBL_RC_ACT!r}")
        for name in ("COM_OF_LOSS_T", "offboard_loss_hold_s", "LNDMC_TRIG_TIME"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {v!r}")
        if not 0.0 < self.MPC_THR_HOVER < 1.0:
            raise ValueError(f"MPC_THR_HOVER must be in (0, 1), got {self.MPC_THR_HOVER!r}")


class Hysteresis:
    """systemlib::Hysteresis (src/lib/hysteresis/hysteresis.cpp): a boolean that takes
    `from_false_s` to become true and `from_true_s` to become false."""

    def __init__(self, state: bool, from_false_s: float = 0.0, from_true_s: float = 0.0) -> None:
        self.state = self._requested = state
        self.from_false_s, self.from_true_s = from_false_s, from_true_s
        self._t_change = 0.0

    def update(self, requested: bool, t: float) -> bool:
        if requested != self.state:
            if requested != self._requested:
                self._requested, self._t_change = requested, t
        else:
            self._requested = self.state
        if self._requested != self.state:
            wait = self.from_false_s if self._requested else self.from_true_s
            if t - self._t_change >= wait:
                self.state = self._requested
        return self.state


class LandInputs(NamedTuple):
    """What the land detector reads at one instant: throttle = the collective thrust
    setpoint in [0, 1]; v_z [m/s] (either sign), v_xy [m/s], roll/pitch rate norm [rad/s]
    from the estimate; climb_rate_control: the mode controls the climb rate (HOLD, LAND);
    descending: that mode commands a descent."""

    throttle: float
    v_z_mps: float
    v_xy_mps: float
    rate_xy_radps: float
    climb_rate_control: bool = False
    descending: bool = False


class LandDetector:
    """PX4's multicopter land detector, in its three stages (module doc)."""

    def __init__(self, p: CommanderParams) -> None:
        self.p = p
        third = p.LNDMC_TRIG_TIME / 3.0
        self.ground_contact = Hysteresis(True, third)
        self.maybe_landed = Hysteresis(True, third)
        self.landed = Hysteresis(True, third)

    def update(self, t: float, armed: bool, x: LandInputs) -> None:
        p = self.p
        landed = self.landed.state
        hover = p.MPC_THR_HOVER
        v_max = p.LNDMC_Z_VEL_MAX * (2.5 if landed else 1.0)
        low = x.throttle <= p.MPC_THR_MIN + (hover - p.MPC_THR_MIN) * 0.3
        contact = low and abs(x.v_z_mps) < v_max and not x.v_xy_mps > p.LNDMC_XY_VEL_MAX
        if x.climb_rate_control and not self.maybe_landed.state and not landed:
            contact = contact and x.descending
        if x.climb_rate_control:
            minimum = x.throttle <= p.MPC_THR_MIN + (hover - p.MPC_THR_MIN) * 0.1
        else:
            minimum = x.throttle <= p.MPC_MANTHR_MIN + 0.01
        rot_max = math.radians(p.LNDMC_ROT_MAX) * (2.5 if landed else 1.0)
        self.ground_contact.update(not armed or contact, t)
        maybe = not armed or (minimum and not x.rate_xy_radps > rot_max and self.ground_contact.state)
        self.maybe_landed.update(maybe, t)
        self.landed.update(not armed or self.maybe_landed.state, t)


class Commander:
    """One vehicle's commander (module doc). Drive it with `update(t, land_inputs)` once per
    physics step, `offboard_setpoint(t, sp)` per SET_ATTITUDE_TARGET, `handle_command(t, ...)`
    per command; read `armed`, `nav_state`, `target`, `landed`, `failsafe`; `events` and
    `pop_texts()` say what happened (STATUSTEXTs for the port)."""

    def __init__(self, params: CommanderParams = CommanderParams()) -> None:
        self.p = params
        self.armed = False
        self.user_intent = NavState.AUTO_LOITER
        self._after_disarm = NavState.AUTO_LOITER
        self.nav_state = NavState.AUTO_LOITER
        self.failsafe = False
        self.target: OffboardSetpoint | None = None  # the setpoint published in OFFBOARD (held)
        self.land_detector = LandDetector(params)
        self._ocm: OffboardSetpoint | None = None  # the last one that kept the stream alive
        self._failsafe_t0: float | None = None
        self._taken_off = False
        self._auto_disarm = Hysteresis(False)
        self.armed_at_s: float | None = None
        self.offboard_engaged_s: float | None = None  # first time armed in OFFBOARD
        self.events: list[dict] = []
        self._texts: deque[tuple[int, str]] = deque(maxlen=64)

    # -- state read by the port and the runner -----------------------------------------
    @property
    def landed(self) -> bool:
        return self.land_detector.landed.state

    @property
    def maybe_landed(self) -> bool:
        return self.land_detector.maybe_landed.state

    @property
    def custom_mode(self) -> int:
        return custom_mode_of(self.nav_state)

    def offboard_lost(self, t: float) -> bool:
        """offboardCheck.cpp:46-58: no stream message younger than COM_OF_LOSS_T."""
        return self._ocm is None or not t < self._ocm.t_s + self.p.COM_OF_LOSS_T

    def can_run(self, t: float, nav: NavState) -> bool:
        if nav == NavState.OFFBOARD:
            return not self.offboard_lost(t)
        return nav in (NavState.AUTO_LOITER, NavState.AUTO_LAND)

    def can_arm(self, t: float, nav: NavState | None = None) -> bool:
        """The pre-arm checks of `nav` (default: the current nav state) pass."""
        nav = self.nav_state if nav is None else nav
        return self.can_run(t, nav) and nav not in PREVENTS_ARMING

    def arming_refusal(self, t: float, nav: NavState) -> str:
        """What PX4 reports when arming in `nav` fails (modeCheck.cpp), or ""."""
        if nav == NavState.OFFBOARD and self.offboard_lost(t):
            return "No offboard signal"
        if nav in STICK_MODES:
            return "No manual control input"
        if nav == NavState.AUTO_MISSION:
            return "No valid mission available"
        if nav in PREVENTS_ARMING:
            return "Mode not suitable for arming"
        return ""

    def base_mode(self) -> int:
        """HEARTBEAT.base_mode as PX4 sets it (HEARTBEAT.hpp:80-99) from the control-mode
        flags of the nav state (control_mode.cpp:49-146)."""
        m = MODE_FLAG_CUSTOM_MODE_ENABLED | (MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        nav = self.nav_state
        if nav in STICK_MODES:
            m |= MODE_FLAG_MANUAL_INPUT_ENABLED | (0 if nav == NavState.ACRO else MODE_FLAG_STABILIZE_ENABLED)
        elif nav == NavState.OFFBOARD:
            if self._ocm is not None and self._ocm.attitude:
                m |= MODE_FLAG_STABILIZE_ENABLED
        elif nav != NavState.TERMINATION:
            m |= MODE_FLAG_AUTO_ENABLED | MODE_FLAG_GUIDED_ENABLED | MODE_FLAG_STABILIZE_ENABLED
        return m

    def pop_texts(self) -> list[tuple[int, str]]:
        """STATUSTEXTs (severity, text) queued since the last call."""
        out = list(self._texts)
        self._texts.clear()
        return out

    # -- inputs ---------------------------------------------------------------------------
    def offboard_setpoint(self, t: float, sp: OffboardSetpoint) -> None:
        """A SET_ATTITUDE_TARGET for this vehicle: keeps the stream alive (if it carries an
        attitude or body rates) and, in OFFBOARD, becomes the setpoint flown."""
        if not sp.keeps_stream_alive:
            return
        self._ocm = sp
        if self.nav_state == NavState.OFFBOARD:
            self.target = sp

    def handle_command(self, t: float, command: int, params: tuple[float, ...]) -> int:
        """One COMMAND_LONG/COMMAND_INT for the commander (params: param1..param7); the
        COMMAND_ACK result."""
        if command == CMD_DO_SET_MODE:
            result = self._set_mode(t, params)
        elif command == CMD_COMPONENT_ARM_DISARM:
            result = self._arm_disarm(t, params)
        elif command == CMD_NAV_LAND:
            result = self._change(t, NavState.AUTO_LAND, "Landing at current position")
        else:
            result = UNSUPPORTED
        self._evaluate(t)
        return result

    def update(self, t: float, land: LandInputs) -> None:
        """One physics step: land detector, takeoff and landing, auto-disarm, failover."""
        was_landed = self.landed
        self.land_detector.update(t, self.armed, land)
        if self.armed and was_landed != self.landed:
            if self.landed:
                self._say(t, INFO, "Landing detected", "landing")
            else:
                self._taken_off = True
                self._say(t, INFO, "Takeoff detected", "takeoff")
        self._auto_disarm_step(t)
        self._evaluate(t)

    # -- internals ------------------------------------------------------------------------
    def _say(self, t: float, severity: int, text: str, event: str | None = None, **detail) -> None:
        self._texts.append((severity, text))
        if event is not None:
            self.events.append({"t_s": t, "event": event, **detail})

    def _set_mode(self, t: float, params) -> int:
        base, main, sub = (_uint8(params[i]) for i in range(3))  # (uint8_t) casts, Commander.cpp:737-739
        desired: NavState | None = None
        if base & MODE_FLAG_CUSTOM_MODE_ENABLED:
            if main == px4.MAIN_AUTO:
                if sub == 0:
                    desired = NavState.AUTO_MISSION
                elif sub in _AUTO_SUB:
                    desired = _AUTO_SUB[sub]
                elif sub in (8, 9):  # FOLLOW_TARGET, PRECLAND: PX4 switches, the emulation does not fly them
                    self._say(t, CRITICAL, "Mode not emulated by the simulator")
                    return UNSUPPORTED
                else:  # READY, 7, VTOL_TAKEOFF and beyond (Commander.cpp:787-792)
                    self._say(t, CRITICAL, "Unsupported auto mode")
                    return TEMPORARILY_REJECTED
            else:
                desired = _MAIN.get(main)
        elif base & MODE_FLAG_AUTO_ENABLED:
            desired = NavState.AUTO_MISSION
        elif base & MODE_FLAG_MANUAL_INPUT_ENABLED:
            desired = (NavState.POSCTL if base & MODE_FLAG_GUIDED_ENABLED else
                       NavState.STAB if base & MODE_FLAG_STABILIZE_ENABLED else NavState.MANUAL)
        if desired is None:
            return ACCEPTED  # nothing to change (Commander.cpp:840-841)
        return self._change(t, desired)

    def _change(self, t: float, nav: NavState, text: str = "") -> int:
        """UserModeIntention::change; ACCEPTED or TEMPORARILY_REJECTED (or UNSUPPORTED for a
        mode the emulation does not fly)."""
        if nav not in EMULATED:
            self._say(t, CRITICAL, f"{nav_name(nav)} not emulated by the simulator")
            return UNSUPPORTED
        if self.armed and not self.can_run(t, nav):
            reason = self.arming_refusal(t, nav)
            self._say(t, CRITICAL, f"Switching to {nav_name(nav)} is currently not available"
                                   + (f": {reason}" if reason else ""))
            return TEMPORARILY_REJECTED
        if nav != self.user_intent:
            self.events.append({"t_s": t, "event": "mode request", "mode": nav_name(nav)})
        self.user_intent = nav
        if nav not in PREVENTS_ARMING:
            self._after_disarm = nav
        if text:
            self._say(t, INFO, text)
        return ACCEPTED

    def _arm_disarm(self, t: float, params) -> int:
        action = _rounded(params[0])
        if action not in (0, 1):
            self._say(t, CRITICAL, f"Unsupported ARM_DISARM param: {params[0]:.3f}")
            return UNSUPPORTED
        forced = _rounded(params[1]) == FORCE_MAGIC
        ok = self.arm(t) if action == 1 else self.disarm(t, forced, "command")
        return ACCEPTED if ok else TEMPORARILY_REJECTED

    def arm(self, t: float) -> bool:
        """Arm with the pre-arm checks (from MAVLink they always run); True if armed."""
        if self.armed:
            return True
        self._evaluate(t)
        refusal = self.arming_refusal(t, self.nav_state)
        if refusal or not self.can_arm(t):
            self._say(t, CRITICAL, f"Arming denied: {refusal or 'pre-arm checks failed'}", "arming denied",
                      reason=refusal, mode=nav_name(self.nav_state))
            return False
        self.armed, self.armed_at_s = True, t
        self._taken_off = not self.landed
        self._say(t, INFO, "Armed by external command", "armed", mode=nav_name(self.nav_state))
        self._evaluate(t)
        return True

    def disarm(self, t: float, forced: bool = False, by: str = "command") -> bool:
        """Disarm; refused in the air unless forced. True if disarmed."""
        if not self.armed:
            return True
        if not forced and not (self.landed or self.maybe_landed):
            self._say(t, CRITICAL, "Disarming denied! Not landed", "disarming denied")
            return False
        self.armed = False
        self.armed_at_s = None
        self.user_intent = self._after_disarm  # UserModeIntention::onDisarm
        self.target = None
        self._say(t, INFO, f"Disarmed by {by}", "disarmed", by=by, forced=forced,
                  in_air=not (self.landed or self.maybe_landed))
        self._evaluate(t)
        return True

    def _auto_disarm_step(self, t: float) -> None:
        h, p = self._auto_disarm, self.p
        if not self.armed:
            h.update(False, t)
            return
        if p.COM_DISARM_LAND > 0.0 and self._taken_off:
            h.from_false_s = p.COM_DISARM_LAND
            h.update(self.landed, t)
        elif p.COM_DISARM_PRFLT > 0.0 and not self._taken_off:
            h.from_false_s = p.COM_DISARM_PRFLT
            h.update(True, t)
        if h.state:
            self.disarm(t, False, "landing" if self._taken_off else "auto preflight disarming")
            h.update(False, t)

    def _evaluate(self, t: float) -> None:
        """The nav state from the user intention and the failover (module doc)."""
        nav, failsafe = self.user_intent, False
        if self.armed and self.user_intent == NavState.OFFBOARD and self.offboard_lost(t):
            failsafe = True
            if self._failsafe_t0 is None:
                self._failsafe_t0 = t
                self._say(t, CRITICAL, "Failsafe activated: no offboard signal", "failsafe",
                          cause="offboard signal lost", action=self.p.COM_OBL_RC_ACT,
                          last_setpoint_s=None if self._ocm is None else self._ocm.t_s)
            act = self.p.COM_OBL_RC_ACT
            if act == OBL_DISARM:
                self.disarm(t, True, "failsafe")
                return
            held = act != 6 and t - self._failsafe_t0 < self.p.offboard_loss_hold_s
            nav = NavState.AUTO_LOITER if held else OBL_ACTIONS[act]
        elif self._failsafe_t0 is not None:
            self._failsafe_t0 = None
            self._say(t, INFO, "Failsafe cleared", "failsafe cleared")
        self.failsafe = failsafe
        if nav != self.nav_state:
            self.events.append({"t_s": t, "event": "mode", "from": nav_name(self.nav_state), "to": nav_name(nav),
                                "armed": self.armed})
            if nav != NavState.OFFBOARD:
                self.target = None  # a new OFFBOARD flies only setpoints published in it
            self.nav_state = nav
        if self.armed and nav == NavState.OFFBOARD and self.offboard_engaged_s is None:
            self.offboard_engaged_s = t
            self.events.append({"t_s": t, "event": "offboard engaged"})


def _rounded(x: float) -> int | None:
    """lroundf of a command parameter; None for NaN or infinity (MAVSDK sends NaN for unused
    parameters; PX4's lroundf(NaN) matches no value either)."""
    return round(x) if math.isfinite(x) else None


def _uint8(x: float) -> int:
    """(uint8_t) of a command parameter; 0 for NaN or infinity."""
    return int(x) & 0xFF if math.isfinite(x) else 0
