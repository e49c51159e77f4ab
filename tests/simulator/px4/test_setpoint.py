"""simulator.px4.setpoint: SET_ATTITUDE_TARGET's type_mask as PX4 v1.14.3's
mavlink_receiver.cpp:1510-1599 reads it, and the feed-forward mc_att_control makes of it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amlink import px4
from simulator.px4.setpoint import SetpointError, flown_target, from_set_attitude_target

H = math.sqrt(0.5)
Q_EAST = (H, 0.0, 0.0, H)  # NED <- FRD, yaw 90 deg: nose east (what MAVSDK's Attitude(0, 0, 90, T) sends)
LEVEL_ENU = (1.0, 0.0, 0.0, 0.0)


def sp(mask, q=Q_EAST, rates=(0.1, 0.2, 0.3), thrust=0.4, thrust_body=(0.0, 0.0, 0.0)):
    return from_set_attitude_target(mask, q, rates, thrust, thrust_body, 1.5)


def test_mavsdk_set_attitude_mask_7():
    """type_mask 7 (roll, pitch, yaw rate ignored): attitude only; no yaw feed-forward (NaN)."""
    s = sp(px4.IGNORE_BODY_RATES)
    assert (s.attitude, s.body_rate, s.keeps_stream_alive) == (True, False, True)
    assert math.isnan(s.yaw_move_rate_rad_s) and s.rates_FRD_rad_s is None
    assert s.thrust == pytest.approx(0.4) and s.t_s == 1.5


def test_attitude_with_rates_feeds_forward_the_yaw_rate_only():
    """type_mask 0: both flags (offboard_control_mode attitude and body_rate), but mc_att_control
    flies the attitude and takes only body_yaw_rate, as yaw_sp_move_rate about the earth's z axis
    (:1550, AttitudeControl.cpp:101); the roll and pitch rates are not feed-forward."""
    s = sp(0)
    assert s.attitude and s.body_rate
    assert s.yaw_move_rate_rad_s == pytest.approx(0.3)
    t = flown_target(s, LEVEL_ENU)
    assert np.allclose(t.quat_wxyz, LEVEL_ENU, atol=1e-12)  # nose east = ENU x: the identity
    # 0.3 rad/s about NED down is -0.3 about ENU up; level: the body z is the earth's
    assert np.allclose(t.rates_rad_s, [0.0, 0.0, -0.3])
    # rolled 90 deg about x (FLU): the earth's z is the body's +y (R e_y = e_z)
    tilted = (H, H, 0.0, 0.0)
    assert np.allclose(flown_target(s, tilted).rates_rad_s, [0.0, -0.3, 0.0], atol=1e-12)
    assert np.allclose(flown_target(sp(px4.IGNORE_BODY_RATES), LEVEL_ENU).rates_rad_s, 0.0)


def test_rates_only():
    """ATTITUDE_IGNORE (128) with roll and pitch rates: the rate loop alone flies them
    (control_mode.cpp:144-146); thrust the scalar unless THROTTLE_IGNORE (:1588-1590)."""
    s = sp(px4.IGNORE_ATTITUDE)
    assert (s.attitude, s.body_rate) == (False, True)
    assert s.rates_FRD_rad_s == pytest.approx((0.1, 0.2, 0.3)) and s.thrust == pytest.approx(0.4)
    q_now = (0.9, 0.1, -0.2, 0.3)
    q_now = tuple(np.array(q_now) / np.linalg.norm(q_now))
    t = flown_target(s, q_now, (0.0, 0.0, 0.7))
    assert np.allclose(t.quat_wxyz, q_now)  # the attitude loop adds nothing
    assert np.allclose(t.rates_rad_s, px4.frd_to_flu((0.1, 0.2, 0.3)))
    s = sp(px4.IGNORE_ATTITUDE | px4.IGNORE_YAW_RATE)
    assert math.isnan(s.rates_FRD_rad_s[2])
    # a NaN rate setpoint is the measured rate (MulticopterRateControl.cpp:178-181)
    assert np.allclose(flown_target(s, q_now, (0.0, 0.0, 0.7)).rates_rad_s, [0.1, -0.2, 0.7])


def test_neither_attitude_nor_roll_and_pitch_rates():
    """:1522-1524: body_rates needs roll AND pitch; with the attitude ignored too, nothing."""
    s = sp(px4.IGNORE_ATTITUDE | px4.IGNORE_PITCH_RATE)
    assert not s.keeps_stream_alive


def test_thrust_bits():
    """:1553-1560 attitude: THRUST_BODY_SET takes thrust_body (z is -thrust for a multicopter);
    THROTTLE_IGNORE without it leaves the zero-initialised thrust. :1588 rates: only
    THROTTLE_IGNORE counts."""
    assert sp(7 | px4.THRUST_BODY_SET, thrust_body=(0.0, 0.0, -0.55)).thrust == pytest.approx(0.55)
    assert sp(7 | px4.IGNORE_THROTTLE).thrust == 0.0
    assert sp(px4.IGNORE_ATTITUDE | px4.THRUST_BODY_SET, thrust_body=(0.0, 0.0, -0.55)).thrust == pytest.approx(0.4)
    assert sp(px4.IGNORE_ATTITUDE | px4.IGNORE_THROTTLE).thrust == 0.0


def test_quaternion_frames():
    """MAVLink's NED <- FRD attitude maps onto the stack's ENU <- FLU (amlink.px4)."""
    north = flown_target(sp(7, q=(1.0, 0.0, 0.0, 0.0)), LEVEL_ENU).quat_wxyz  # nose north: ENU yaw +90 deg
    assert np.allclose(north, (H, 0.0, 0.0, H))


@pytest.mark.parametrize("kwargs", [dict(q=(0.0, 0.0, 0.0, 0.0)), dict(q=(math.nan, 0, 0, 1)),
                                    dict(thrust=math.inf), dict(mask=0, rates=(0.0, 0.0, math.nan)),
                                    dict(mask=px4.IGNORE_ATTITUDE, rates=(math.nan, 0.0, 0.0))])
def test_unusable_values_are_refused(kwargs):
    mask = kwargs.pop("mask", 7)
    with pytest.raises(SetpointError):
        sp(mask, **kwargs)


def test_ignored_values_may_be_anything():
    s = sp(px4.IGNORE_BODY_RATES, rates=(math.nan, math.nan, math.nan))
    assert s.attitude
    s = sp(px4.IGNORE_ATTITUDE, q=(math.nan, 0.0, 0.0, 0.0))
    assert s.body_rate
