"""Plausibility bounds: one place, applied on both receive paths."""

from __future__ import annotations

import math

import pytest

from amlink.types import (
    AttitudeSetpoint,
    AttitudeTarget,
    SensorFrame,
    SensorLimits,
    SetpointLimits,
    TorqueSetpoint,
)
from tests.amlink import codec_reference as ref
from tests.amlink.kit import answer, linked, make_frame


def sp(thrust=10.0, tau_b=(0.0, 0.0, 0.0), tau_q=(0.0, 0.0, 0.0)):
    return TorqueSetpoint(0, thrust, tau_b, tau_q)


def test_setpoint_limits():
    lim = SetpointLimits.for_vehicle(thrust_max_n=40.0, joint_torque_max_nm=5.0, n_joints=3)
    assert (lim.thrust_max_n, lim.body_torque_max_nm, lim.joint_torque_max_nm) == (80.0, 80.0, 10.0)
    assert lim.violation(sp()) is None
    assert "thrust" in lim.violation(sp(thrust=-81.0))
    assert "tau_B" in lim.violation(sp(tau_b=(0, 81.0, 0)))
    assert "tau_q" in lim.violation(sp(tau_q=(0, 0, math.nan)))
    assert "joint" in lim.violation(sp(tau_q=(0.0, 0.0)))
    with pytest.raises(ValueError):
        SetpointLimits(thrust_max_n=math.inf)


def asp(quat=(1.0, 0.0, 0.0, 0.0), rates=(0.0, 0.0, 0.0), thrust=0.4, tau_q=(0.0, 0.0, 0.0)):
    return AttitudeSetpoint(0, AttitudeTarget(0, quat, rates, thrust), tau_q)


def test_attitude_setpoint_limits():
    lim = SetpointLimits.for_vehicle(thrust_max_n=40.0, joint_torque_max_nm=5.0, n_joints=3)
    assert lim.violation(asp()) is None
    assert lim.violation(asp(thrust=-1.0)) is None  # the message's range; the flight controller clamps to [0, 1]
    assert "thrust_normalized" in lim.violation(asp(thrust=1.5))
    assert "quaternion norm" in lim.violation(asp(quat=(2.0, 0.0, 0.0, 0.0)))
    assert "rates" in lim.violation(asp(rates=(0.0, 2e3, 0.0)))
    assert "tau_q" in lim.violation(asp(tau_q=(0.0, 11.0, 0.0)))
    assert "joint" in lim.violation(asp(tau_q=(0.0,)))


def test_sensor_limits():
    lim = SensorLimits()
    ok = make_frame(2, 3)
    assert lim.violation(ok) is None
    bad = SensorFrame(**{**ok.__dict__, "q": [1e4, 0.0], "qdot": [0.0, 0.0]})
    assert "|q|" in lim.violation(bad)
    unnormalized = SensorFrame(**{**ok.__dict__, "quat_WB_wxyz": [0.5, 0, 0, 0]})
    assert "quaternion" in lim.violation(unnormalized)


def test_companion_drops_an_implausible_frame_and_takes_the_next_valid_one():
    with linked([2]) as (server, clients):
        c = clients[2]
        peer = server._peers[2]
        huge = SensorFrame(**{**make_frame(2, 0).__dict__, "wrench_E": [0, 0, 1e9, 0, 0, 0]})
        server._link.send(peer.addr, peer.encoder.pack(ref.sensor_frame_messages(huge, 7)))
        c.send_setpoint(answer(make_frame(2, 0), 2))
        server.exchange({2: make_frame(2, 0)})
        got = c.recv_frame(1.0)
        assert got.step == 0 and got.wrench_E[2] == 2.0
        assert c.stats.rejected_frames == 1 and c.stats.nonfinite_values == 0
