"""Codec: exact round trips (float32 where standard messages force it), typed rejections."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amcore.so3 import quat_wxyz_to_R
from amlink import codec, px4
from amlink.codec import mav
from amlink.types import (AttitudeSetpoint, AttitudeTarget, ScenarioInfo, SensorFrame, SetpointFlag, StepFlag,
                          TorqueSetpoint)
from tests.amlink import codec_reference as ref

F64 = st.floats(allow_nan=False, allow_infinity=False)  # any finite double
F32 = st.floats(min_value=-1e30, max_value=1e30, allow_nan=False)  # representable range of float32 fields


def vec(n, elements=F64):
    return st.lists(elements, min_size=n, max_size=n).map(np.array)


@st.composite
def sensor_frames(draw):
    """Frames of either mode: attitude mode's carry the measured joint torques and the flown
    target (ATTITUDE_TARGET has no step: the batch's), or one of them."""
    n = draw(st.integers(0, 8))
    step = draw(st.integers(0, 2**64 - 1))
    effort = draw(st.none() | vec(n))
    target = draw(st.none() | st.builds(AttitudeTarget, st.just(step), vec(4, st.floats(-1, 1)),
                                        vec(3, st.floats(-50, 50)), st.floats(0, 1)))
    return SensorFrame(
        step=step,
        time_s=draw(st.integers(0, 2**50)) / 1e6,  # whole microseconds, as the sim steps
        p_WB=draw(vec(3, F32)), quat_WB_wxyz=draw(vec(4, F32)), v_B=draw(vec(3, F32)), w_B=draw(vec(3, F32)),
        q=draw(vec(n)), qdot=draw(vec(n)), wrench_E=draw(vec(6)),
        flags=draw(st.sampled_from(list(StepFlag))) & ~StepFlag.SHUTDOWN,
        joint_effort_nm=effort, attitude_target=target,
    )  # fmt: skip


@st.composite
def setpoints(draw):
    n = draw(st.integers(0, 8))
    return TorqueSetpoint(
        step=draw(st.integers(0, 2**64 - 1)), thrust_n=draw(F64), tau_B_nm=draw(vec(3)), tau_q_nm=draw(vec(n)),
        flags=draw(st.sampled_from(list(SetpointFlag))),
    )  # fmt: skip


def f32(x):
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def decode_frame(data: bytes):
    asm, out = ref.SensorFrameAssembler(), []
    for m in codec.Decoder().feed(data):
        item = asm.push(m)
        if item is not None:
            out.append(item)
    return out


def decode_setpoints(data: bytes):
    asm, out = ref.SetpointAssembler(), []
    for m in codec.Decoder().feed(data):
        item = asm.push(m)
        if item is not None:
            out.append(item)
    return out


@settings(max_examples=150, deadline=None, database=None)
@given(sensor_frames(), st.integers(0, 2**32 - 1))
def test_sensor_frame_round_trip(frame, scenario_id):
    data = codec.Encoder(1, 1).pack(ref.sensor_frame_messages(frame, scenario_id))
    [got] = decode_frame(data)
    assert got.step == frame.step and got.time_s == frame.time_s and got.flags == frame.flags
    # float32 on the wire (ODOMETRY): exactly the float32 rounding of what was sent
    np.testing.assert_array_equal(got.p_WB, f32(frame.p_WB))
    np.testing.assert_array_equal(got.quat_WB_wxyz, f32(frame.quat_WB_wxyz))
    np.testing.assert_array_equal(got.v_B, f32(frame.v_B))
    np.testing.assert_array_equal(got.w_B, f32(frame.w_B))
    # float64 on the wire (amstack messages): exact
    np.testing.assert_array_equal(got.q, frame.q)
    np.testing.assert_array_equal(got.qdot, frame.qdot)
    np.testing.assert_array_equal(got.wrench_E, frame.wrench_E)
    if frame.joint_effort_nm is None:  # attitude mode's reports: effort float64, exact; the target float32
        assert got.joint_effort_nm is None
    else:
        np.testing.assert_array_equal(got.joint_effort_nm, frame.joint_effort_nm)
    if frame.attitude_target is None:
        assert got.attitude_target is None
    else:
        a, b = got.attitude_target, frame.attitude_target
        assert a.step == frame.step and a.thrust_normalized == f32(np.array([b.thrust_normalized]))[0]
        np.testing.assert_allclose(a.quat_wxyz, b.quat_wxyz, atol=1e-6)
        np.testing.assert_array_equal(a.rates_rad_s, f32(b.rates_rad_s))


@settings(max_examples=150, deadline=None, database=None)
@given(setpoints())
def test_setpoint_round_trip_is_exact(sp):
    [(got, att)] = decode_setpoints(codec.Encoder(2, 191).pack(ref.setpoint_messages(sp)))
    assert att is None
    assert (got.step, got.thrust_n, got.flags) == (sp.step, sp.thrust_n, sp.flags)
    np.testing.assert_array_equal(got.tau_B_nm, sp.tau_B_nm)
    np.testing.assert_array_equal(got.tau_q_nm, sp.tau_q_nm)


@settings(database=None)
@given(vec(4, st.floats(-1, 1)).filter(lambda q: np.linalg.norm(q) > 0.1))
def test_attitude_conversion_is_the_enu_flu_to_ned_frd_change_of_frames(q):
    T_NED_ENU = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]])
    T_FLU_FRD = np.diag([1, -1, -1])
    R_ned_frd = quat_wxyz_to_R(px4.q_enu_flu_to_ned_frd(q))
    np.testing.assert_allclose(R_ned_frd, T_NED_ENU @ quat_wxyz_to_R(q) @ T_FLU_FRD, atol=1e-12)


@settings(database=None)
@given(setpoints(), vec(4, st.floats(-1, 1)), vec(3, st.floats(-50, 50)), st.floats(0, 1))
def test_attitude_target_rides_with_setpoint(sp, quat, rates, thrust):
    att = AttitudeTarget(sp.step, quat, rates, thrust)
    data = codec.Encoder(2, 191).pack(ref.setpoint_messages(sp, att, time_boot_ms=1234))
    [(got_sp, got)] = decode_setpoints(data)
    assert got_sp.step == sp.step and got.step == sp.step
    np.testing.assert_allclose(got.quat_wxyz, quat, atol=1e-6)  # float32 + conversion
    np.testing.assert_allclose(got.rates_rad_s, rates, rtol=1e-6, atol=1e-6)
    assert got.thrust_normalized == f32(thrust)


def test_scenario_round_trip():
    info = ScenarioInfo(scenario_id=2**32 - 1, n_am=3, name="x" * 32, seed=42, rate_hz=1000.0)
    [m] = codec.Decoder().feed(codec.Encoder(1, 1).pack([codec.scenario_message(info)]))
    assert codec.scenario_from_message(m) == info


def test_batch_is_one_datagram_in_order_with_step_marker_last():
    frame = SensorFrame(7, 0.007, [0, 0, 1], [1, 0, 0, 0], [0] * 3, [0] * 3, [0.5], [0.0], [0] * 6)
    msgs = codec.Decoder().feed(codec.Encoder(1, 1).pack(ref.sensor_frame_messages(frame)))
    assert [m.get_type() for m in msgs] == ["ODOMETRY", "AM_JOINT_STATE", "AM_WRENCH", "AM_SIM_STEP"]
    odom = msgs[0]
    assert (odom.frame_id, odom.child_frame_id) == (mav.MAV_FRAME_LOCAL_ENU, 13)
    assert odom.time_usec == 7000 and math.isnan(odom.pose_covariance[0])


def _odometry(**kw):
    args = dict(time_usec=0, frame_id=codec.ODOM_FRAME_ID, child_frame_id=codec.ODOM_CHILD_FRAME_ID,
                x=0.0, y=0.0, z=0.0, q=[1.0, 0.0, 0.0, 0.0], vx=0.0, vy=0.0, vz=0.0, rollspeed=0.0,
                pitchspeed=0.0, yawspeed=0.0, pose_covariance=[0.0] * 21, velocity_covariance=[0.0] * 21)  # fmt: skip
    args.update(kw)
    return mav.MAVLink_odometry_message(**args)


def _batch(odom=None, pos=None, vel=None, wrench=None, joints_step=0, wrench_step=0):
    return [
        odom or _odometry(),
        mav.MAVLink_am_joint_state_message(joints_step, 2, pos or [0.0] * 8, vel or [0.0] * 8),
        mav.MAVLink_am_wrench_message(wrench_step, (wrench or [0.0] * 6)[:3], (wrench or [0.0] * 6)[3:]),
        mav.MAVLink_am_sim_step_message(0, 0, 0, 0),
    ]


BAD = [math.nan, math.inf, -math.inf]


@pytest.mark.parametrize("bad", BAD)
@pytest.mark.parametrize(
    "make",
    [
        lambda b: _batch(odom=_odometry(z=b)),
        lambda b: _batch(odom=_odometry(q=[b, 0.0, 0.0, 0.0])),
        lambda b: _batch(odom=_odometry(yawspeed=b)),
        lambda b: _batch(pos=[0.0, b] + [0.0] * 6),
        lambda b: _batch(vel=[b] + [0.0] * 7),
        lambda b: _batch(wrench=[0.0] * 5 + [b]),
    ],
    ids=["odom.z", "odom.q", "odom.yawspeed", "joint.position", "joint.velocity", "wrench.torque"],
)
def test_decode_rejects_non_finite_sensor_values(make, bad):
    data = codec.Encoder(1, 1).pack(make(bad))
    with pytest.raises(codec.NonFiniteValueError):
        decode_frame(data)


def test_padding_beyond_n_joints_is_not_checked():
    # only the n valid entries are state; garbage past n_joints is ignored, not an error
    [f] = decode_frame(codec.Encoder(1, 1).pack(_batch(pos=[0.1, 0.2, math.nan] + [0.0] * 5)))
    np.testing.assert_array_equal(f.q, [0.1, 0.2])


@pytest.mark.parametrize("bad", BAD)
@pytest.mark.parametrize("field", ["thrust_n", "body_torque_nm", "joint_torque_nm"])
def test_decode_rejects_non_finite_setpoint(field, bad):
    args = dict(step=1, thrust_n=1.0, body_torque_nm=[0.0] * 3, n_joints=3, joint_torque_nm=[0.0] * 8, flags=0)
    args[field] = bad if field == "thrust_n" else [bad] + args[field][1:]
    data = codec.Encoder(2, 191).pack([mav.MAVLink_am_torque_setpoint_message(**args)])
    with pytest.raises(codec.NonFiniteValueError) as err:
        decode_setpoints(data)
    assert field in str(err.value)


def test_encode_rejects_non_finite_and_negative_time():
    f = SensorFrame(0, 0.0, [0, 0, math.nan], [1, 0, 0, 0], [0] * 3, [0] * 3, [], [], [0] * 6)
    with pytest.raises(codec.EncodeError):
        ref.sensor_frame_messages(f)
    with pytest.raises(codec.EncodeError):
        ref.setpoint_messages(TorqueSetpoint(0, math.inf, [0] * 3, []))
    g = SensorFrame(0, -1e-3, [0] * 3, [1, 0, 0, 0], [0] * 3, [0] * 3, [], [], [0] * 6)
    with pytest.raises(codec.EncodeError):
        ref.sensor_frame_messages(g)
    big = SensorFrame(0, 0.0, [1e39, 0, 0], [1, 0, 0, 0], [0] * 3, [0] * 3, [], [], [0] * 6)
    with pytest.raises(codec.EncodeError):  # does not fit the float32 of ODOMETRY
        codec.Encoder(1, 1).pack(ref.sensor_frame_messages(big))


def test_mismatched_steps_times_frames_and_missing_parts_are_rejected():
    enc = codec.Encoder(1, 1)
    with pytest.raises(codec.BatchMismatchError):
        decode_frame(enc.pack(_batch(joints_step=1)))
    with pytest.raises(codec.BatchMismatchError):
        decode_frame(enc.pack(_batch(wrench_step=1)))
    with pytest.raises(codec.BatchMismatchError):
        decode_frame(enc.pack(_batch(odom=_odometry(time_usec=5))))
    with pytest.raises(codec.FrameConventionError):
        decode_frame(enc.pack(_batch(odom=_odometry(frame_id=mav.MAV_FRAME_LOCAL_NED))))
    with pytest.raises(codec.BatchMismatchError, match="AM_WRENCH"):
        decode_frame(enc.pack(_batch()[:2] + _batch()[3:]))


def test_batch_split_over_datagrams_assembles():
    enc, dec, asm = codec.Encoder(1, 1), codec.Decoder(), ref.SensorFrameAssembler()
    out = [asm.push(m) for msg in _batch() for m in dec.feed(enc.pack([msg]))]
    assert out[:3] == [None] * 3 and isinstance(out[3], SensorFrame)


def test_shutdown_step_emits_shutdown_even_without_parts():
    asm = ref.SensorFrameAssembler()
    [m] = codec.Decoder().feed(codec.Encoder(1, 1).pack([codec.shutdown_message(9, 0.5)]))
    item = asm.push(m)
    assert isinstance(item, codec.Shutdown) and item.step == 9 and item.time_s == 0.5


def test_corrupt_and_truncated_frames_are_dropped_and_counted():
    enc, dec = codec.Encoder(1, 1), codec.Decoder()
    good = enc.pack([mav.MAVLink_am_sim_step_message(1, 2, 3, 0)])
    corrupt = bytearray(good)
    corrupt[12] ^= 0xFF  # payload byte: CRC no longer matches
    assert dec.feed(bytes(corrupt)) == [] and dec.bad_frames == 1
    assert dec.feed(good + good[:-3]) != [] and dec.bad_frames == 2  # truncated tail dropped
    [m] = dec.feed(good)  # the parser starts clean on the next datagram
    assert m.step == 1
    assert dec.feed(b"\x00garbage") == [] and dec.bad_frames >= 3


@st.composite
def attitude_setpoints(draw):
    """Attitude-mode setpoints with wire-representable targets (float32 fields)."""
    step, n = draw(st.integers(0, 2**64 - 1)), draw(st.integers(0, 8))
    att = AttitudeTarget(step, draw(vec(4, st.floats(-1, 1))), draw(vec(3, st.floats(-50, 50))), draw(st.floats(0, 1)))
    return AttitudeSetpoint(step, att, draw(vec(n)), draw(st.sampled_from(list(SetpointFlag))))


@settings(max_examples=150, deadline=None, database=None)
@given(attitude_setpoints())
def test_attitude_setpoint_round_trip(sp):
    """Attitude mode: SET_ATTITUDE_TARGET (float32, NED/FRD) + AM_JOINT_TORQUE_SETPOINT (float64, exact)."""
    [(got, att)] = decode_setpoints(codec.Encoder(2, 191).pack(ref.attitude_setpoint_messages(sp, 1234)))
    assert isinstance(got, AttitudeSetpoint) and att is got.attitude
    assert (got.step, got.flags, att.step) == (sp.step, sp.flags, sp.step)
    np.testing.assert_array_equal(got.tau_q_nm, sp.tau_q_nm)
    np.testing.assert_allclose(att.quat_wxyz, sp.attitude.quat_wxyz, atol=1e-6)
    np.testing.assert_allclose(att.rates_rad_s, sp.attitude.rates_rad_s, rtol=1e-6, atol=1e-6)
    assert att.thrust_normalized == f32(sp.attitude.thrust_normalized)


def test_joint_torques_without_their_attitude_target_are_an_error():
    enc = codec.Encoder(2, 191)
    sp = AttitudeSetpoint(3, AttitudeTarget(3, [1, 0, 0, 0], [0, 0, 0], 0.5), [0.1, 0.2])
    att_msg, joint_msg = ref.attitude_setpoint_messages(sp)
    with pytest.raises(codec.BatchMismatchError, match="without SET_ATTITUDE_TARGET"):
        decode_setpoints(enc.pack([joint_msg]))
    with pytest.raises(ValueError, match="step 4 in the setpoint of step 3"):
        AttitudeSetpoint(3, AttitudeTarget(4, [1, 0, 0, 0], [0, 0, 0], 0.5), [])
