"""GCS-link messages: NED/FRD conventions against a literal rotation-matrix transcription, PX4
mode names as stock tools read them, STATUSTEXT chunks, and which changes are told."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavutil

from amlink.codec import mav
from simulator import gcs_messages as gm
from simulator.fcstate import FcMode, FleetSnapshot, VehicleSnapshot

R_NED_ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
R_FLU_FRD = np.diag([1.0, -1.0, -1.0])


def _R(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _vehicle(q=(1.0, 0.0, 0.0, 0.0), p=(0.0, 0.0, 1.0), v=(0.0, 0.0, 0.0), w=(0.0, 0.0, 0.0), mode=FcMode.OFFBOARD,
             armed=True, failsafe=False, sysid=4) -> VehicleSnapshot:
    return VehicleSnapshot(sysid=sysid, p_WB=tuple(p), quat_WB_wxyz=tuple(q), v_B=tuple(v), w_B=tuple(w), mode=mode,
                           armed=armed, failsafe=failsafe)


def _angle_between(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2 * math.pi))  # pi and -pi are one angle


unit = st.floats(-1.0, 1.0, allow_nan=False)
quaternions = st.tuples(unit, unit, unit, unit).filter(lambda q: np.linalg.norm(q) > 0.1).map(
    lambda q: tuple(np.asarray(q) / np.linalg.norm(q)))
vectors = st.tuples(*[st.floats(-10.0, 10.0, allow_nan=False)] * 3)


@settings(max_examples=200, deadline=None)
@given(q=quaternions, p=vectors, v=vectors, w=vectors)
def test_attitude_and_local_position_are_the_ned_frd_change_of_frames(q, p, v, w):
    R_WB = _R(q)
    R = R_NED_ENU @ R_WB @ R_FLU_FRD  # R_NED_FRD, literally
    pitch = -math.asin(np.clip(R[2, 0], -1.0, 1.0))
    veh = _vehicle(q, p, v, w)
    att = gm.attitude(veh, 7)
    assert att.pitch == pytest.approx(pitch, abs=1e-6)
    if abs(R[2, 0]) < 0.999:  # away from gimbal lock roll and yaw are defined
        assert _angle_between(att.roll, math.atan2(R[2, 1], R[2, 2])) < 1e-6
        assert _angle_between(att.yaw, math.atan2(R[1, 0], R[0, 0])) < 1e-6
    np.testing.assert_allclose([att.rollspeed, att.pitchspeed, att.yawspeed], R_FLU_FRD @ np.array(w), atol=1e-5)
    pos = gm.local_position_ned(veh, 7)
    np.testing.assert_allclose([pos.x, pos.y, pos.z], R_NED_ENU @ np.array(p), atol=1e-5)
    np.testing.assert_allclose([pos.vx, pos.vy, pos.vz], R_NED_ENU @ R_WB @ np.array(v), atol=1e-4)
    assert att.time_boot_ms == pos.time_boot_ms == 7


def test_headings_read_as_a_compass_does():
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    east = gm.attitude(_vehicle((1.0, 0.0, 0.0, 0.0)), 0)  # body x along world x = east
    north = gm.attitude(_vehicle((c, 0.0, 0.0, s)), 0)  # turned 90 deg to the left, facing north
    assert east.yaw == pytest.approx(math.pi / 2) and north.yaw == pytest.approx(0.0, abs=1e-12)
    nose_up = gm.attitude(_vehicle((math.cos(-0.05), 0.0, math.sin(-0.05), 0.0)), 0)  # FLU: -y rotation pitches up
    assert nose_up.pitch == pytest.approx(0.1) and nose_up.roll == pytest.approx(0.0, abs=1e-12)
    climbing = gm.local_position_ned(_vehicle(p=(1.0, 2.0, 3.0), v=(0.0, 0.0, 0.5)), 0)
    assert (climbing.x, climbing.y, climbing.z, climbing.vz) == (2.0, 1.0, -3.0, -0.5)


@pytest.mark.parametrize("mode,name", [(FcMode.OFFBOARD, "OFFBOARD"), (FcMode.HOLD, "LOITER"),
                                       (FcMode.LAND, "LAND"), (FcMode.LANDED, "LAND"), (FcMode.STANDBY, "LOITER")])
def test_stock_tools_name_the_mode_from_the_heartbeat(mode, name):
    hb = gm.heartbeat(_vehicle(mode=mode))
    assert mavutil.mode_string_v10(hb) == name
    assert (hb.type, hb.autopilot) == (mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4)
    assert hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED


def test_heartbeat_says_armed_and_how_the_system_is():
    assert not gm.heartbeat(_vehicle(armed=False, mode=FcMode.STANDBY)).base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED
    assert gm.heartbeat(_vehicle(armed=False, mode=FcMode.STANDBY)).system_status == mav.MAV_STATE_STANDBY
    assert gm.heartbeat(_vehicle()).system_status == mav.MAV_STATE_ACTIVE
    assert gm.heartbeat(_vehicle(mode=FcMode.HOLD, failsafe=True)).system_status == mav.MAV_STATE_CRITICAL


@pytest.mark.parametrize("n", [0, 1, 49, 50, 51, 100, 149])
def test_statustext_chunks_join_back_to_the_text(n):
    text = "".join(chr(ord("a") + i % 26) for i in range(n))
    msgs = gm.statustexts(text, mav.MAV_SEVERITY_NOTICE, 77)
    raw = [m.text.encode() if isinstance(m.text, str) else m.text for m in msgs]
    assert b"".join(raw).decode() == text
    if n <= 50:
        assert len(msgs) == 1 and msgs[0].id == 0
    else:
        assert [m.chunk_seq for m in msgs] == list(range(len(msgs))) and {m.id for m in msgs} == {77}
        assert len(raw[-1]) < 50 and all(len(r) == 50 for r in raw[:-1])


def _fleet(phase, *vehicles):
    return FleetSnapshot(time_s=1.0, phase=phase, vehicles=tuple(vehicles))


def test_changes_worth_telling_are_told_once_by_the_vehicle_concerned():
    a = _fleet("approach", _vehicle(sysid=4), _vehicle(sysid=5))
    assert gm.status_changes(a, a) == []
    lost = _fleet("approach", _vehicle(sysid=4), _vehicle(sysid=5, mode=FcMode.HOLD, failsafe=True))
    assert gm.status_changes(a, lost) == [(5, mav.MAV_SEVERITY_CRITICAL, "failsafe: companion lost, holding position")]
    back = gm.status_changes(lost, a)
    assert back == [(5, mav.MAV_SEVERITY_NOTICE, "failsafe ended: companion back in control")]
    landing = _fleet("grasp", _vehicle(sysid=4, mode=FcMode.LAND), _vehicle(sysid=5))
    assert gm.status_changes(a, landing) == [(4, mav.MAV_SEVERITY_NOTICE, "landing (GCS command)"),
                                             (4, mav.MAV_SEVERITY_INFO, "mission phase: grasp"),
                                             (5, mav.MAV_SEVERITY_INFO, "mission phase: grasp")]
    down = _fleet("grasp", _vehicle(sysid=4, mode=FcMode.LANDED, armed=False), _vehicle(sysid=5))
    assert gm.status_changes(landing, down) == [(4, mav.MAV_SEVERITY_INFO, "landed, motors off"),
                                                (4, mav.MAV_SEVERITY_NOTICE, "disarmed")]
