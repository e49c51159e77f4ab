"""simulator.px4.commander: each PX4 rule it follows, against the PX4 v1.14.3 source it cites."""
from __future__ import annotations

import math

import pytest

from simulator.px4 import commander as cm
from simulator.px4.commander import (ACCEPTED, CMD_COMPONENT_ARM_DISARM, CMD_DO_SET_MODE, CMD_NAV_LAND,
                                     TEMPORARILY_REJECTED, UNSUPPORTED, Commander, CommanderParams, LandInputs,
                                     NavState)
from simulator.px4.setpoint import from_set_attitude_target

NAN = math.nan
OFFBOARD = (1.0, 6.0, 0.0)  # DO_SET_MODE base_mode CUSTOM, PX4 main OFFBOARD
HOLD = (1.0, 4.0, 3.0)  # AUTO.LOITER
LAND = (1.0, 4.0, 6.0)
POSCTL = (1.0, 3.0, 0.0)
ON_GROUND = LandInputs(throttle=0.0, v_z_mps=0.0, v_xy_mps=0.0, rate_xy_radps=0.0)
CLIMBING = LandInputs(throttle=0.6, v_z_mps=1.0, v_xy_mps=0.0, rate_xy_radps=0.0)
HOVER = LandInputs(throttle=0.37, v_z_mps=0.0, v_xy_mps=0.0, rate_xy_radps=0.0)


def cmd(c: Commander, t: float, command: int, *params: float) -> int:
    p = (list(params) + [NAN] * 7)[:7]  # MAVSDK sends NaN for the parameters it does not use
    return c.handle_command(t, command, tuple(p))


def setpoint(t: float, mask: int = 7, thrust: float = 0.4):
    """A MAVSDK set_attitude (type_mask 7: body rates ignored), level, heading north."""
    return from_set_attitude_target(mask, (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), thrust, (0.0, 0.0, 0.0), t)


def stream(c: Commander, t0: float, t1: float, rate_hz: float = 20.0, land=ON_GROUND) -> float:
    """Setpoints at rate_hz and a commander step every ms from t0 to t1; returns t1."""
    t, next_sp = t0, t0
    while t < t1 - 1e-12:
        if t >= next_sp - 1e-12:
            c.offboard_setpoint(t, setpoint(t))
            next_sp += 1.0 / rate_hz
        c.update(t, land)
        t = round(t + 0.001, 9)
    return t1


def steps(c: Commander, t0: float, t1: float, land=ON_GROUND) -> float:
    t = t0
    while t < t1 - 1e-12:
        c.update(t, land)
        t = round(t + 0.001, 9)
    return t1


def flying_offboard(params: CommanderParams = CommanderParams()) -> tuple[Commander, float]:
    """Armed in OFFBOARD, in the air, the stream live until t = 3 s (the MAVSDK order: first
    setpoint, offboard.start(), action.arm())."""
    c = Commander(params)
    c.offboard_setpoint(0.0, setpoint(0.0))
    assert cmd(c, 0.0, CMD_DO_SET_MODE, *OFFBOARD) == ACCEPTED
    assert cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 1.0) == ACCEPTED
    t = stream(c, 0.0, 1.0, land=CLIMBING)
    assert not c.landed
    return c, stream(c, t, 3.0, land=HOVER)


def test_starts_disarmed_landed_in_hold():
    """UserModeIntention.hpp:76-77: the user intention starts at AUTO_LOITER; a disarmed vehicle
    is landed (MulticopterLandDetector: !_armed)."""
    c = Commander()
    c.update(0.0, ON_GROUND)
    assert (c.armed, c.landed, c.nav_state, c.failsafe) == (False, True, NavState.AUTO_LOITER, False)
    assert c.custom_mode == (4 << 16) | (3 << 24)


def test_offboard_accepted_while_disarmed_without_stream_then_arming_refused():
    """UserModeIntention.cpp:48: any mode change is allowed while disarmed; the arming check then
    fails for OFFBOARD without a signal (modeCheck.cpp:124-134 "No offboard signal")."""
    c = Commander()
    assert cmd(c, 0.0, CMD_DO_SET_MODE, *OFFBOARD) == ACCEPTED
    assert c.nav_state == NavState.OFFBOARD
    assert cmd(c, 0.1, CMD_COMPONENT_ARM_DISARM, 1.0) == TEMPORARILY_REJECTED
    assert not c.armed
    assert any("No offboard signal" in text for _, text in c.pop_texts())
    assert not c.can_arm(0.1)  # SYS_STATUS's MAV_SYS_STATUS_PREARM_CHECK is clear
    c.offboard_setpoint(0.2, setpoint(0.2))
    assert c.can_arm(0.2)
    assert cmd(c, 0.2, CMD_COMPONENT_ARM_DISARM, 1.0) == ACCEPTED and c.armed
    assert c.offboard_engaged_s == 0.2


def test_offboard_refused_while_armed_without_stream():
    """UserModeIntention.cpp:51-52: armed, only a mode that can run; OFFBOARD needs the offboard
    signal (mode_requirements.cpp mode_req_offboard_signal) -> Commander.cpp:843-844
    TEMPORARILY_REJECTED."""
    c = Commander()
    assert cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 1.0) == ACCEPTED  # in Hold on the ground
    assert cmd(c, 0.1, CMD_DO_SET_MODE, *OFFBOARD) == TEMPORARILY_REJECTED
    assert c.nav_state == NavState.AUTO_LOITER
    c.offboard_setpoint(0.2, setpoint(0.2))
    assert cmd(c, 0.2, CMD_DO_SET_MODE, *OFFBOARD) == ACCEPTED
    assert c.nav_state == NavState.OFFBOARD


def test_stream_liveness_is_strictly_younger_than_com_of_loss_t():
    """offboardCheck.cpp:46-47: data_is_recent = now < timestamp + COM_OF_LOSS_T."""
    c = Commander(CommanderParams(COM_OF_LOSS_T=0.5))
    assert c.offboard_lost(0.0)
    c.offboard_setpoint(1.0, setpoint(1.0))
    assert not c.offboard_lost(1.4999)
    assert c.offboard_lost(1.5)


def test_a_message_with_neither_attitude_nor_rates_keeps_no_stream():
    """mavlink_receiver.cpp:1530: offboard_control_mode is published only if attitude or
    body_rates (roll and pitch rates) are given."""
    c = Commander()
    c.offboard_setpoint(0.0, setpoint(0.0, mask=128 | 1))  # attitude and roll rate ignored
    assert c.offboard_lost(0.0)
    c.offboard_setpoint(0.0, setpoint(0.0, mask=128 | 4))  # yaw rate ignored: rates still count
    assert not c.offboard_lost(0.0)


def test_setpoints_are_flown_only_once_in_offboard():
    """mavlink_receiver.cpp:1562-1563: the attitude setpoint is published only in OFFBOARD."""
    c = Commander()
    c.offboard_setpoint(0.0, setpoint(0.0))
    assert c.target is None  # in Hold: keeps the stream alive, not flown
    cmd(c, 0.0, CMD_DO_SET_MODE, *OFFBOARD)
    assert c.target is None  # the one sent before the switch is not flown either
    sp = setpoint(0.05, thrust=0.3)
    c.offboard_setpoint(0.05, sp)
    assert c.target is sp


def test_offboard_loss_holds_then_takes_com_obl_rc_act():
    """COM_OF_LOSS_T after the last setpoint the mode fallback takes COM_OBL_RC_ACT
    (failsafe.cpp:459-461, 480-490); here after offboard_loss_hold_s of Hold (the lockstep's
    failsafe: hold, then land). HEARTBEAT reports the failsafe (MAV_STATE_CRITICAL)."""
    c, t = flying_offboard()
    last = 3.0 - 0.05  # the last setpoint of the stream
    t = steps(c, t, last + 1.0 - 0.002, HOVER)
    assert c.nav_state == NavState.OFFBOARD and not c.failsafe
    t = steps(c, t, last + 1.0 + 0.002, HOVER)
    assert c.nav_state == NavState.AUTO_LOITER and c.failsafe and c.armed
    assert c.target is None
    t = steps(c, t, last + 1.0 + 5.0 - 0.002, HOVER)
    assert c.nav_state == NavState.AUTO_LOITER
    steps(c, t, last + 1.0 + 5.0 + 0.002, HOVER)
    assert c.nav_state == NavState.AUTO_LAND and c.failsafe
    assert [e["event"] for e in c.events].count("failsafe") == 1


@pytest.mark.parametrize("act, nav", [(4, NavState.AUTO_LAND), (5, NavState.AUTO_LOITER), (0, NavState.POSCTL),
                                      (3, NavState.AUTO_RTL), (6, NavState.TERMINATION)])
def test_offboard_loss_without_hold_is_px4s_immediate_fallback(act, nav):
    """offboard_loss_hold_s = 0: PX4 v1.14.3 exactly, the COM_OBL_RC_ACT mode at once
    (fromOffboardLossActParam, failsafe.cpp:277-325)."""
    c, t = flying_offboard(CommanderParams(COM_OBL_RC_ACT=act, offboard_loss_hold_s=0.0))
    steps(c, t, 3.0 - 0.05 + 1.0 + 0.002, HOVER)
    assert c.nav_state == nav and c.armed


def test_offboard_loss_disarm_action():
    """COM_OBL_RC_ACT = 7: Action::Disarm."""
    c, t = flying_offboard(CommanderParams(COM_OBL_RC_ACT=7))
    steps(c, t, 3.0 - 0.05 + 1.0 + 0.002, HOVER)
    assert not c.armed
    assert c.events[-1]["event"] in ("disarmed", "mode", "failsafe cleared")


def test_the_fallback_clears_when_the_stream_returns():
    """ActionOptions' clear_condition WhenConditionClears (framework.h:186): the user intention
    (OFFBOARD) applies again once the signal is back."""
    c, t = flying_offboard()
    t = steps(c, t, 4.5, HOVER)
    assert c.nav_state == NavState.AUTO_LOITER and c.failsafe
    c.offboard_setpoint(t, setpoint(t))
    c.update(t, HOVER)
    assert c.nav_state == NavState.OFFBOARD and not c.failsafe


def test_the_user_takes_over_from_the_fallback():
    """UserTakeoverAllowed::Always: a mode change that can run ends the fallback."""
    c, t = flying_offboard()
    t = steps(c, t, 4.5, HOVER)
    assert cmd(c, t, CMD_NAV_LAND) == ACCEPTED
    assert c.nav_state == NavState.AUTO_LAND and not c.failsafe


def test_disarm_in_the_air_needs_force():
    """disarm() (Commander.cpp:595-613): not landed and not forced -> denied ->
    TEMPORARILY_REJECTED (:887-888); param2 = 21196 forces (:863)."""
    c, t = flying_offboard()
    assert cmd(c, t, CMD_COMPONENT_ARM_DISARM, 0.0) == TEMPORARILY_REJECTED and c.armed
    assert cmd(c, t, CMD_COMPONENT_ARM_DISARM, 0.0, 21196.0) == ACCEPTED and not c.armed


def test_arm_disarm_parameters():
    """Commander.cpp:853-860: param1 neither 0 nor 1 leaves the result UNSUPPORTED (:688);
    arming twice is ACCEPTED (TRANSITION_NOT_CHANGED)."""
    c = Commander()
    assert cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 2.0) == UNSUPPORTED
    assert cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, NAN) == UNSUPPORTED
    assert cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 1.0) == ACCEPTED
    assert cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 1.0) == ACCEPTED and c.armed
    assert cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 0.0) == ACCEPTED and not c.armed  # on the ground


@pytest.mark.parametrize("mode, why", [(LAND, "Mode not suitable for arming"), (POSCTL, "No manual control input"),
                                       ((1.0, 4.0, 0.0), "No valid mission available")])
def test_arming_refused_where_the_mode_forbids_it(mode, why):
    """LAND prevents arming (mode_requirements.cpp mode_req_prevent_arming, modeCheck.cpp:180-189);
    the stick modes need manual control, absent here (modeCheck.cpp:141-163); MISSION a mission
    (:112-123). The change itself is accepted while disarmed."""
    c = Commander()
    assert cmd(c, 0.0, CMD_DO_SET_MODE, *mode) == ACCEPTED
    assert cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 1.0) == TEMPORARILY_REJECTED
    assert any(why in text for _, text in c.pop_texts())


def test_do_set_mode_decoding():
    """Commander.cpp:744-845: AUTO sub 0 is MISSION; an unknown AUTO sub mode is denied
    (TEMPORARILY_REJECTED); an unknown main mode changes nothing and is ACCEPTED; modes the
    emulation does not fly are UNSUPPORTED."""
    c = Commander()
    assert cmd(c, 0.0, CMD_DO_SET_MODE, 1.0, 4.0, 0.0) == ACCEPTED and c.user_intent == NavState.AUTO_MISSION
    assert cmd(c, 0.0, CMD_DO_SET_MODE, 1.0, 4.0, 1.0) == TEMPORARILY_REJECTED  # AUTO.READY
    assert cmd(c, 0.0, CMD_DO_SET_MODE, 1.0, 99.0, 0.0) == ACCEPTED and c.user_intent == NavState.AUTO_MISSION
    assert cmd(c, 0.0, CMD_DO_SET_MODE, 1.0, 4.0, 5.0) == UNSUPPORTED  # RTL: not emulated
    assert cmd(c, 0.0, CMD_DO_SET_MODE, 1.0, 4.0, 3.0) == ACCEPTED and c.nav_state == NavState.AUTO_LOITER
    assert cmd(c, 0.0, 12345) == UNSUPPORTED  # a command the commander does not know (:688)


def test_nav_land_and_back_after_disarm():
    """MAV_CMD_NAV_LAND -> AUTO_LAND (Commander.cpp:1017-1029); after the disarm the intention
    is the last mode that does not prevent arming (UserModeIntention::onDisarm)."""
    c, t = flying_offboard()
    assert cmd(c, t, CMD_NAV_LAND) == ACCEPTED
    assert c.nav_state == NavState.AUTO_LAND
    assert cmd(c, t, CMD_COMPONENT_ARM_DISARM, 0.0, 21196.0) == ACCEPTED
    assert c.nav_state == NavState.OFFBOARD and not c.armed


def test_auto_disarm_after_landing():
    """handleAutoDisarm (Commander.cpp:2127-2151): taken off, then landed for COM_DISARM_LAND."""
    c, t = flying_offboard()
    land = LandInputs(throttle=0.05, v_z_mps=0.0, v_xy_mps=0.0, rate_xy_radps=0.0)
    t_landed = None
    while t < 10.0:
        c.offboard_setpoint(t, setpoint(t, thrust=0.05))
        c.update(t, land)
        if c.landed and t_landed is None:
            t_landed = t
        if not c.armed:
            break
        t = round(t + 0.001, 9)
    # ground contact, maybe landed, landed: each LNDMC_TRIG_TIME / 3 (MulticopterLandDetector.cpp:316-321)
    assert t_landed == pytest.approx(3.0 + 1.0, abs=0.01)
    assert not c.armed and t == pytest.approx(t_landed + 2.0, abs=0.01)
    assert any(e["event"] == "disarmed" and e["by"] == "landing" for e in c.events)


def test_auto_disarm_when_not_taking_off():
    """Commander.cpp:2140-2142: armed and not taken off for COM_DISARM_PRFLT -> disarm."""
    c = Commander()
    cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 1.0)
    steps(c, 0.0, 9.99)
    assert c.armed
    steps(c, 9.99, 10.01)
    assert not c.armed


def test_takeoff_is_detected_at_once_and_landing_after_the_trigger_time():
    """The land detector's states need LNDMC_TRIG_TIME / 3 each to become true and none to
    become false (LandDetector.h:145-148 hysteresis from true = 0). In a non-climb-rate mode
    (offboard attitude) minimum thrust is MPC_MANTHR_MIN + 0.01 (MulticopterLandDetector.cpp:265)."""
    c = Commander()
    c.offboard_setpoint(0.0, setpoint(0.0))
    cmd(c, 0.0, CMD_DO_SET_MODE, *OFFBOARD)
    cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 1.0)
    c.update(0.001, LandInputs(throttle=0.085, v_z_mps=0.0, v_xy_mps=0.0, rate_xy_radps=0.0))
    assert c.landed  # 0.085 <= 0.09
    c.update(0.002, LandInputs(throttle=0.095, v_z_mps=0.0, v_xy_mps=0.0, rate_xy_radps=0.0))
    assert not c.landed and not c.maybe_landed  # takeoff detected at once
    assert [e["event"] for e in c.events][-1] == "takeoff"


def test_heartbeat_base_mode_flags():
    """HEARTBEAT.hpp:80-99 with control_mode.cpp: CUSTOM always; ARMED; OFFBOARD attitude ->
    STABILIZE; AUTO modes -> AUTO | GUIDED | STABILIZE."""
    c = Commander()
    assert c.base_mode() == 1 | 4 | 8 | 16  # Hold, disarmed
    c.offboard_setpoint(0.0, setpoint(0.0))
    cmd(c, 0.0, CMD_DO_SET_MODE, *OFFBOARD)
    cmd(c, 0.0, CMD_COMPONENT_ARM_DISARM, 1.0)
    assert c.base_mode() == 1 | 16 | 128


def test_params_are_checked():
    with pytest.raises(ValueError, match="COM_OBL_RC_ACT"):
        CommanderParams(COM_OBL_RC_ACT=9)
    with pytest.raises(ValueError, match="MPC_THR_HOVER"):
        CommanderParams(MPC_THR_HOVER=1.5)


def test_hysteresis_is_px4s():
    """systemlib::Hysteresis: a request must persist for the time; a flip back resets it."""
    h = cm.Hysteresis(False, from_false_s=1.0)
    assert not h.update(True, 0.0)
    assert not h.update(True, 0.99)
    assert h.update(True, 1.0)
    h = cm.Hysteresis(False, from_false_s=1.0)
    h.update(True, 0.0)
    h.update(False, 0.5)
    assert not h.update(True, 1.2)
    assert h.update(True, 2.2)
