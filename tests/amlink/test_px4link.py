"""The PX4 client against a minimal PX4-like endpoint on real UDP sockets (tests/amlink/px4_fake.py).

The link and the fake share a test-driven clock, so stamps and ages are exact; the sockets are
real (loopback), and every exchange is polled until it arrived.
"""
from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mc

from amlink import px4
from amlink.px4link import LinkOpenError, Px4Link, SetpointError, default_endpoint
from amlink.tlog import TlogWriter

from .px4_fake import FakeClock, FakePx4

SYSID = 3
MS = 1_000_000


@pytest.fixture
def rig():
    clock = FakeClock()
    link = Px4Link(SYSID, "udpin:127.0.0.1:0", clock=clock, timesync_rate_hz=0).open()
    fake = FakePx4(SYSID, clock)
    fake.dest = ("127.0.0.1", link.local_address[1])
    yield clock, link, fake
    link.close()
    fake.close()


def pump(link, fake, rounds=3):
    """Let datagrams cross both ways: the fake serves, the link polls."""
    events = []
    for _ in range(rounds):
        fake.serve(0.002)
        events += link.poll(0.002)
    return events


# -- reference frame maps, independent of amlink.px4 ------------------------------------
T_NED_ENU = np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]])
D_FLU_FRD = np.diag([1.0, -1, -1])


def R_of(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def q_of(R):
    """Shepperd's method."""
    t = np.trace(R)
    if t > 0:
        s = 2 * math.sqrt(1 + t)
        return np.array([s / 4, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2 * math.sqrt(1 + R[i, i] - R[j, j] - R[k, k])
    q = np.zeros(4)
    q[0] = (R[k, j] - R[j, k]) / s
    q[1 + i] = s / 4
    q[1 + j] = (R[j, i] + R[i, j]) / s
    q[1 + k] = (R[k, i] + R[i, k]) / s
    return q


def ned_frd_pose(p_enu, R_enu_flu, v_flu, w_flu):
    """The same pose as PX4 states it: p in NED, q_NED_FRD, v and w in FRD."""
    R_ned_frd = T_NED_ENU @ R_enu_flu @ D_FLU_FRD
    return T_NED_ENU @ p_enu, q_of(R_ned_frd), D_FLU_FRD @ v_flu, D_FLU_FRD @ w_flu


def f32(x):
    return np.asarray(x, dtype=np.float32).astype(np.float64)


# -- endpoints --------------------------------------------------------------------------
def test_default_endpoint_is_the_mavsdk_listening_port():
    assert default_endpoint(0) == "udpin:0.0.0.0:14540"
    assert default_endpoint(3) == "udpin:0.0.0.0:14543"


def test_constructor_opens_nothing_and_bad_arguments_are_named():
    link = Px4Link(SYSID, default_endpoint(0))
    assert link.peer is None
    with pytest.raises(RuntimeError, match="open"):
        link.poll()
    with pytest.raises(ValueError, match="sysid"):
        Px4Link(0, "udpin:127.0.0.1:0")
    with pytest.raises(ValueError, match="endpoint"):
        Px4Link(SYSID, "bogus:1:2")
    with Px4Link(SYSID, "udpin:127.0.0.1:0") as a:
        port = a.local_address[1]
        with pytest.raises(LinkOpenError, match=f"cannot open udpin:127.0.0.1:{port}: .*in use"):
            Px4Link(SYSID, f"udpin:127.0.0.1:{port}").open()
    with pytest.raises(LinkOpenError, match="/dev/nonexistent-tty"):
        Px4Link(SYSID, "/dev/nonexistent-tty:57600").open()


def test_listening_link_sends_nothing_before_the_autopilot_spoke_then_answers_it(rig):
    clock, link, fake = rig
    link.send_heartbeat()
    assert link.stats.send_drops == 1 and fake.serve(0.02) == 0
    fake.heartbeat()
    events = pump(link, fake)
    assert link.autopilot_heard and link.peer == fake.sock.getsockname()
    hb = [e for e in events if type(e).__name__ == "HeartbeatEvent"][0]
    assert hb.value.mode == "POSCTL" and not hb.value.armed and hb.rx_ns == clock()
    link.send_heartbeat()
    fake.serve(0.05)
    (_, m), = fake.heartbeats
    assert (m.get_srcSystem(), m.get_srcComponent()) == (SYSID, 191)
    assert m.type == mc.MAV_TYPE_ONBOARD_CONTROLLER and m.autopilot == mc.MAV_AUTOPILOT_INVALID


# -- TIMESYNC ----------------------------------------------------------------------------
def test_autopilot_timesync_request_answered_with_our_time_and_its_ts1(rig):
    clock, link, fake = rig
    fake.heartbeat()
    pump(link, fake)
    ts1 = fake.timesync_request()
    pump(link, fake)
    (ans,) = fake.timesync_answers
    assert ans.ts1 == ts1 and ans.tc1 == clock()  # tc1: our monotonic ns when we answered
    assert (ans.get_srcSystem(), ans.get_srcComponent()) == (SYSID, 191)
    assert link.stats.timesync_answered == 1


@pytest.mark.parametrize("rate", [0.5, 1.0, 2.0])
def test_own_timesync_follows_the_autopilot_clock(rate):
    clock = FakeClock()
    with Px4Link(SYSID, "udpin:127.0.0.1:0", clock=clock, timesync_rate_hz=10.0) as link:
        fake = FakePx4(SYSID, clock, rate=rate, boot_us=12_345_678)
        fake.dest = ("127.0.0.1", link.local_address[1])
        try:
            fake.heartbeat()
            for _ in range(12):  # 1.2 s of 10 Hz exchanges
                pump(link, fake, rounds=2)
                clock.advance(100 * MS)
            pump(link, fake, rounds=2)
            tb = link.timebase
            assert tb.converged and tb.accepted >= 10 and link.stats.timesync_sent >= 12
            assert tb.rate == pytest.approx(rate, rel=1e-5)
            # the exchanges take no time on the shared clock: exact up to PX4's 1 us quantization
            assert abs(link.fc_time_us() - fake.fc_us()) <= 1.0 * rate + 1.0
            assert abs(tb.mono_ns(fake.fc_us()) - clock()) <= 2_000 / rate + 1_000
        finally:
            fake.close()


# -- samples --------------------------------------------------------------------------------
def test_odometry_at_30_hz_decoded_with_frames_converted(rig):
    clock, link, fake = rig
    rng = np.random.default_rng(4)
    fake.heartbeat()
    pump(link, fake)
    period = round(1e9 / 30)
    for k in range(30):
        clock.advance(period)
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        R = R_of(q)
        p, v, w = rng.uniform(-5, 5, 3), rng.uniform(-2, 2, 3), rng.uniform(-1, 1, 3)
        p_ned, q_ned, v_frd, w_frd = ned_frd_pose(p, R, v, w)
        child = mc.MAV_FRAME_BODY_FRD if k % 2 == 0 else mc.MAV_FRAME_LOCAL_NED
        v_wire = v_frd if child == mc.MAV_FRAME_BODY_FRD else T_NED_ENU @ (R @ v)  # LOCAL_NED: world velocity
        t_us = fake.odometry(p_ned, q_ned, v_wire, w_frd, child_frame_id=child)
        pump(link, fake, rounds=1)
        s = link.store.latest("odometry")
        assert s.count == k + 1 and s.fc_us == t_us and s.rx_ns == clock()
        o = s.value
        tol = 2e-6 * 5  # float32 on the wire, values up to 5
        assert np.allclose(o.p_WB, f32(p_ned) @ T_NED_ENU, atol=tol)  # T is its own inverse
        assert np.allclose(R_of(o.q_WB_wxyz), R, atol=1e-6)
        assert np.allclose(o.v_B, v, atol=tol) and np.allclose(o.w_B, w, atol=tol)
        assert o.child_frame_id == child
    assert s.gaps == 0 and link.store.out_of_order("odometry") == 0
    st = link.stats
    assert st.nonfinite_values == st.malformed == st.frame_refused == st.bad_frames == 0


def test_a_known_ned_frd_pose_maps_to_the_enu_flu_one(rig):
    """Facing east, nose 30 deg up, at 10 m: every number by hand."""
    clock, link, fake = rig
    fake.heartbeat()
    pump(link, fake)
    c, s = math.cos(math.radians(15)), math.sin(math.radians(15))
    # NED/FRD: yaw 90 deg (east), then pitch +30 deg (nose up): q = q_z(90) * q_y(30)
    h = math.sqrt(0.5)
    q_ned = np.array([h * c, -h * s, h * s, h * c])
    fake.odometry((2.0, 1.0, -10.0), q_ned, (4.0, 0.0, 0.0), (0.0, 0.5, 0.0))
    pump(link, fake, rounds=1)
    o = link.store.latest("odometry").value
    assert o.p_WB == (1.0, 2.0, 10.0)  # east 1, north 2, up 10
    # ENU/FLU: body x along east tilted 30 deg up, y to the north, z up-ish
    R = R_of(o.q_WB_wxyz)
    assert np.allclose(R[:, 0], (math.cos(math.radians(30)), 0, math.sin(math.radians(30))), atol=1e-6)
    assert np.allclose(R[:, 1], (0, 1, 0), atol=1e-6)
    assert o.v_B == (4.0, -0.0, -0.0) and o.w_B == (0.0, -0.5, -0.0)  # FRD pitch-up rate = FLU -y


def test_other_streams_are_decoded_into_enu_flu(rig):
    clock, link, fake = rig
    fake.heartbeat()
    pump(link, fake)
    h = math.sqrt(0.5)
    fake.send(mc.MAVLink_attitude_quaternion_message(5000, h, 0, 0, h, 0.1, 0.2, 0.3, [0, 0, 0, 0]))
    fake.send(mc.MAVLink_attitude_target_message(5010, 0, [h, 0, 0, h], 0.1, 0.2, 0.3, 0.6))
    fake.send(mc.MAVLink_highres_imu_message(5_020_000, 0.5, 0.25, -9.75, 0.1, 0.2, 0.3, 0.2, 0.0, 0.4,
                                             1013.0, 0.5, 12.0, 25.0, 0x1FFF, 0))
    fake.send(mc.MAVLink_extended_sys_state_message(0, mc.MAV_LANDED_STATE_IN_AIR))
    fake.send(mc.MAVLink_sys_status_message(1, 1, 1, 250, 16000, -1, 80, 0, 0, 0, 0, 0, 0))
    fake.send(mc.MAVLink_statustext_message(mc.MAV_SEVERITY_WARNING, b"Preflight Fail: ekf2 not ready"))
    events = pump(link, fake)
    st = link.store
    a = st.latest("attitude")
    assert a.fc_us == 5_000_000 and np.allclose(a.value.q_WB_wxyz, (1, 0, 0, 0), atol=1e-7)
    assert a.value.w_B == pytest.approx((0.1, -0.2, -0.3))
    t = st.latest("attitude_target")
    assert t.fc_us == 5_010_000 and t.value.thrust_normalized == pytest.approx(0.6)
    assert np.allclose(t.value.quat_wxyz, (1, 0, 0, 0), atol=1e-7)
    assert np.allclose(t.value.rates_rad_s, (0.1, -0.2, -0.3))
    imu = st.latest("imu").value
    assert imu.acc_B == pytest.approx((0.5, -0.25, 9.75)) and imu.gyro_B == pytest.approx((0.1, -0.2, -0.3))
    assert imu.t_us == 5_020_000 and imu.abs_pressure_hpa == pytest.approx(1013.0)
    assert st.latest("extended_sys_state").value.landed_state == mc.MAV_LANDED_STATE_IN_AIR
    ss = st.latest("sys_status").value
    assert ss.load_pct == 25.0 and ss.voltage_v == 16.0 and ss.current_a is None and ss.battery_remaining_pct == 80
    (text,) = [e for e in events if type(e).__name__ == "StatusTextEvent"]
    assert text.text == "Preflight Fail: ekf2 not ready" and text.severity == mc.MAV_SEVERITY_WARNING


def test_stale_samples_age_and_are_flagged_past_their_limit(rig):
    clock, link, fake = rig
    fake.heartbeat()
    pump(link, fake)
    fake.odometry((0, 0, 0), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0))
    pump(link, fake, rounds=1)
    rx = link.store.latest("odometry").rx_ns
    limit = link.store.limits.limit_ns("odometry")
    assert limit == 100 * MS  # 3 periods of 30 Hz
    assert not link.store.is_stale("odometry", clock())
    for dt in (30 * MS, 60 * MS, 99 * MS):
        clock.now = rx + dt
        assert link.store.age_ns("odometry", clock()) == dt and not link.store.is_stale("odometry", clock())
    clock.now = rx + 101 * MS
    assert link.store.is_stale("odometry", clock())
    assert link.store.stale(clock(), ("odometry", "heartbeat", "imu")) == ["odometry", "imu"]  # imu: never came
    clock.now = rx + 3001 * MS
    assert link.store.is_stale("heartbeat", clock())


def test_gaps_and_out_of_order_samples_are_counted(rig):
    clock, link, fake = rig
    fake.heartbeat()
    pump(link, fake)
    t = 10_000_000
    for k in range(10):
        t += 33_333 if k != 6 else 3 * 33_333  # one sample lost before the 7th
        fake.odometry((0, 0, 0), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0), t_us=t)
        pump(link, fake, rounds=1)
    fake.odometry((0, 0, 0), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0), t_us=t - 33_333)  # a late one
    pump(link, fake, rounds=1)
    s = link.store.latest("odometry")
    assert s.gaps == 1 and s.count == 10 and s.fc_us == t
    assert link.store.out_of_order("odometry") == 1 and link.stats.out_of_order == 1


def _frame(msgid: int, payload: bytes, sysid=SYSID, compid=1, crc_extra=0) -> bytes:
    from pymavlink.generator.mavcrc import x25crc

    hdr = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, 0, sysid, compid, msgid & 0xFFFF, msgid >> 16)
    crc = x25crc(hdr[1:] + payload)
    crc.accumulate(bytes((crc_extra,)))
    return hdr + payload + struct.pack("<H", crc.crc)


def test_unknown_and_malformed_frames_are_counted_not_raised(rig):
    clock, link, fake = rig
    fake.heartbeat()
    pump(link, fake)
    good = mc.MAVLink_odometry_message(1, 1, 12, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0, 0, 0,
                                       [0] * 21, [0] * 21).pack(fake.mav)
    fake.send_raw(b"\x00not mavlink at all")
    fake.send_raw(good[:-1] + bytes((good[-1] ^ 0xFF,)))  # bad CRC
    fake.send_raw(good[:-3])  # truncated
    fake.send_raw(_frame(61_234, b"\x01\x02\x03"))  # a message id no dialect here knows
    fake.send_raw(bytes((0xFE, 9, 0, SYSID, 1, 0)) + bytes(11))  # a MAVLink 1 frame
    before = link.stats.bad_frames
    pump(link, fake)
    assert link.stats.bad_frames - before == 5
    nan = float("nan")
    fake.odometry((nan, 0, 0), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0))
    fake.odometry((0, 0, 0), (0, 0, 0, 0), (0, 0, 0), (0, 0, 0))  # no attitude
    fake.odometry((0, 0, 0), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0), frame_id=mc.MAV_FRAME_LOCAL_FRD)
    fake.odometry((0, 0, 0), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0), child_frame_id=mc.MAV_FRAME_BODY_NED)
    fake.send(mc.MAVLink_attitude_message(1, 0, 0, 0, 0, 0, 0))  # valid, not used here
    other = mc.MAVLink(None, srcSystem=SYSID + 1, srcComponent=1)
    fake.send_raw(mc.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3).pack(other))
    camera = mc.MAVLink(None, srcSystem=SYSID, srcComponent=100)
    fake.send_raw(mc.MAVLink_heartbeat_message(30, 8, 0, 0, 4, 3).pack(camera))
    pump(link, fake)
    st = link.stats
    assert st.nonfinite_values == 1 and st.malformed == 1 and st.frame_refused == 2
    assert "LOCAL_FRD" in link.last_refusal or "BODY_NED" in link.last_refusal
    assert st.ignored >= 1 and st.unknown_sysid == 1 and st.other_components == 1
    assert link.store.latest("odometry") is None
    fake.odometry((1, 2, 3), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0))  # and the link still works
    pump(link, fake, rounds=1)
    assert link.store.latest("odometry").value.p_WB == (2.0, 1.0, -3.0)


# -- sending --------------------------------------------------------------------------------
def test_attitude_target_sent_in_ned_frd(rig):
    clock, link, fake = rig
    fake.heartbeat()
    pump(link, fake)
    rng = np.random.default_rng(9)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w = np.array([0.1, -0.2, 0.3])
    link.send_attitude_target(q, w, 0.55, type_mask=0)
    fake.serve(0.05)
    (_, m), = fake.setpoints
    assert (m.target_system, m.target_component, m.type_mask) == (SYSID, 1, 0)
    R_ned_frd = T_NED_ENU @ R_of(q) @ D_FLU_FRD
    assert np.allclose(R_of(m.q), R_ned_frd, atol=1e-6)
    assert np.allclose((m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate), D_FLU_FRD @ w, atol=1e-7)
    assert m.thrust == pytest.approx(0.55) and link.stats.setpoints_sent == 1
    link.send_attitude_target((1, 0, 0, 0), (0, 0, 0), 0.0)
    fake.serve(0.05)
    assert fake.setpoints[-1][1].type_mask == px4.IGNORE_BODY_RATES


@pytest.mark.parametrize("args, match", [
    (((1, 0, 0, float("nan")), (0, 0, 0), 0.5), "non-finite"),
    (((1, 1, 0, 0), (0, 0, 0), 0.5), "unit quaternion"),
    (((1, 0, 0, 0), (0, 0), 0.5), "3 values"),
    (((1, 0, 0, 0), (0, 0, 0), 1.5), r"outside \[0, 1\]"),
    (((1, 0, 0, 0), (0, 0, 0), "x"), "numbers"),
])
def test_bad_setpoints_are_refused_by_name(rig, args, match):
    clock, link, fake = rig
    with pytest.raises(SetpointError, match=match):
        link.send_attitude_target(*args)
    with pytest.raises(SetpointError, match="thrust_body"):
        link.send_attitude_target((1, 0, 0, 0), (0, 0, 0), 0.5, type_mask=px4.THRUST_BODY_SET)
    assert link.stats.setpoints_sent == 0


def test_command_long_is_tracked_to_its_ack(rig):
    clock, link, fake = rig
    fake.heartbeat()
    pump(link, fake)
    fake.interval_results[mc.MAVLINK_MSG_ID_HIGHRES_IMU] = mc.MAV_RESULT_UNSUPPORTED
    p1 = link.set_message_interval(mc.MAVLINK_MSG_ID_ODOMETRY, 4000)
    pump(link, fake)
    assert p1.done and p1.accepted and p1.acked_ns == clock()
    (m,) = fake.commands_of(mc.MAV_CMD_SET_MESSAGE_INTERVAL)
    assert (m.param1, m.param2, m.target_system, m.target_component) == (331, 4000, SYSID, 1)
    p2 = link.set_message_interval(mc.MAVLINK_MSG_ID_HIGHRES_IMU, 4000)
    pump(link, fake)
    assert p2.done and p2.result == mc.MAV_RESULT_UNSUPPORTED and not p2.accepted
    fake.ignore[mc.MAV_CMD_COMPONENT_ARM_DISARM] = 1
    a = link.command_long(mc.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    pump(link, fake)
    assert not a.done
    b = link.command_long(mc.MAV_CMD_COMPONENT_ARM_DISARM, 1, confirmation=1)
    pump(link, fake)
    assert a.superseded and not a.done and b.accepted
    assert [m.confirmation for m in fake.commands_of(mc.MAV_CMD_COMPONENT_ARM_DISARM)] == [0, 1]


def test_signing_and_tlog(tmp_path):
    key = bytes(range(32))
    clock = FakeClock()
    tlog = TlogWriter(tmp_path / "px4.tlog").open()
    with Px4Link(SYSID, "udpin:127.0.0.1:0", clock=clock, signing_key=key, tlog=tlog, timesync_rate_hz=0) as link:
        signed, plain = FakePx4(SYSID, clock, signing_key=key), FakePx4(SYSID, clock)
        for f in (signed, plain):
            f.dest = ("127.0.0.1", link.local_address[1])
        try:
            plain.heartbeat()
            link.poll(0.05)
            assert not link.autopilot_heard and link.stats.unsigned == 1
            signed.heartbeat()
            link.poll(0.05)
            assert link.autopilot_heard
            link.send_heartbeat()
            assert signed.serve(0.05) == 1
        finally:
            signed.close()
            plain.close()
    tlog.close()
    assert tlog.records == 3  # two received (one unsigned), one sent


# -- the other endpoint forms ------------------------------------------------------------------
def test_udpout_sends_at_once():
    clock = FakeClock()
    fake = FakePx4(SYSID, clock)
    try:
        with Px4Link(SYSID, f"udpout:127.0.0.1:{fake.sock.getsockname()[1]}", clock=clock,
                     timesync_rate_hz=0) as link:
            link.send_heartbeat()
            assert fake.serve(0.2) == 1 and len(fake.heartbeats) == 1
            fake.dest = link.local_address
            fake.odometry((1, 2, 3), (1, 0, 0, 0), (0, 0, 0), (0, 0, 0))
            link.poll(0.2)
            assert link.store.latest("odometry").value.p_WB == (2.0, 1.0, -3.0)
    finally:
        fake.close()


def _stream_exchange(link, write, read):
    """The autopilot's side of a byte stream: a heartbeat and an ODOMETRY in, our HEARTBEAT out."""
    ap = mc.MAVLink(None, srcSystem=SYSID, srcComponent=1)
    data = mc.MAVLink_heartbeat_message(2, 12, 1, px4.custom_mode(px4.MAIN_POSCTL), 4, 3).pack(ap)
    data += mc.MAVLink_odometry_message(5, 1, 12, 1, 2, 3, [1, 0, 0, 0], 0, 0, 0, 0, 0, 0,
                                        [0] * 21, [0] * 21).pack(ap)
    write(data[:7])  # a frame cut across two reads
    link.poll(0.1)
    write(data[7:])
    for _ in range(20):
        link.poll(0.05)
        if link.store.latest("odometry") is not None:
            break
    assert link.store.latest("heartbeat").value.mode == "POSCTL"
    assert link.store.latest("odometry").value.p_WB == (2.0, 1.0, -3.0)
    link.send_heartbeat()
    rx = mc.MAVLink(None)
    got = []
    for _ in range(20):
        link.poll(0.01)
        got += rx.parse_buffer(read()) or []
        if got:
            break
    assert got and got[0].get_type() == "HEARTBEAT" and got[0].get_srcComponent() == 191


def test_tcp_client_form():
    import select
    import socket

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    try:
        with Px4Link(SYSID, f"tcp:127.0.0.1:{srv.getsockname()[1]}", timesync_rate_hz=0) as link:
            for _ in range(50):
                link.poll(0.02)  # connects while it polls
                if select.select([srv], [], [], 0)[0]:
                    break
            conn, _ = srv.accept()
            conn.settimeout(0.05)

            def read():
                try:
                    return conn.recv(65536)
                except TimeoutError:
                    return b""
            _stream_exchange(link, conn.sendall, read)
            conn.close()
    finally:
        srv.close()


def test_serial_form():
    import os

    from .ptys import pty_pair

    with pty_pair() as (dev_a, dev_b):
        fd = os.open(dev_b, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            with Px4Link(SYSID, f"{dev_a}:921600", timesync_rate_hz=0) as link:
                def read():
                    try:
                        return os.read(fd, 65536)
                    except BlockingIOError:
                        return b""
                _stream_exchange(link, lambda d: os.write(fd, d), read)
        finally:
            os.close(fd)
