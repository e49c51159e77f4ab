"""simulator.px4.port over loopback UDP: PX4 v1.14.3's onboard streams, commands, partner rule
and bad input (mavlink_main.cpp, mavlink_receiver.cpp)."""
from __future__ import annotations

import math
import socket
import struct
import time

import pytest

from amlink.endpoint import parse_endpoint
from amlink.wire import Decoder, Encoder, frame_crc, mav
from simulator.px4 import commander as cm
from simulator.px4.port import MAX_DATAGRAM, PortError, Px4Port, onboard_endpoint
from simulator.px4.setpoint import VehicleReport

SYSID = 4
REPORT = VehicleReport(time_s=0.0, p_W=(1.0, 2.0, 3.0), quat_WB=(1.0, 0.0, 0.0, 0.0), v_W=(0.1, 0.2, 0.3),
                       w_B=(0.01, 0.02, 0.03), gyro_B=(0.01, 0.02, 0.03), accel_B=(0.0, 0.0, 9.81))


class Client:
    """A MAVLink client on its own loopback port (a companion, as (SYSID, 191))."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.5)
        self.enc = Encoder(SYSID, 191)
        self.dec = Decoder(None)

    @property
    def port(self) -> int:
        return self.sock.getsockname()[1]

    def send(self, port: Px4Port, *msgs) -> None:
        self.sock.sendto(self.enc.pack(msgs), port.local_address)

    def raw(self, port: Px4Port, data: bytes) -> None:
        self.sock.sendto(data, port.local_address)

    def drain(self) -> list:
        out = []
        self.sock.settimeout(0.05)
        try:
            while True:
                data, _ = self.sock.recvfrom(65536)
                out.extend(self.dec.feed(data))
        except (socket.timeout, BlockingIOError):
            pass
        return out

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def link():
    client = Client()
    port = Px4Port(0, SYSID, cm.Commander(), parse_endpoint(f"udpout:127.0.0.1:{client.port}"))
    port.open()
    yield port, client
    port.close()
    client.close()


def command(client: Client, port: Px4Port, cmd: int, *params: float, target=(SYSID, 1), now: float = 0.0):
    p = (list(params) + [0.0] * 7)[:7]
    client.send(port, mav.MAVLink_command_long_message(target[0], target[1], cmd, 0, *p))
    port.poll(now)
    return [m for m in client.drain()]


def acks(msgs) -> list[tuple[int, int]]:
    return [(m.command, m.result) for m in msgs if m.get_type() == "COMMAND_ACK"]


def run_streams(port: Px4Port, t0: float, t1: float, client: Client | None = None) -> list:
    """Publish every ms of autopilot time from t0 to t1; what `client` received (read every
    100 steps: a socket buffer holds a few hundred small datagrams)."""
    got = []
    k = round(t0 * 1000)
    while k < round(t1 * 1000):
        t = k * 1e-3
        port.publish(t, REPORT._replace(time_s=t))
        k += 1
        if client is not None and k % 100 == 0:
            got.extend(client.drain())
    if client is not None:
        got.extend(client.drain())
    return got


def counts(msgs) -> dict[str, int]:
    out: dict[str, int] = {}
    for m in msgs:
        out[m.get_type()] = out.get(m.get_type(), 0) + 1
    return out


def test_default_endpoint_is_px4_sitls():
    """px4-rc.mavlink:25: -u 14580+i -o 14540+i."""
    ep = onboard_endpoint(2)
    assert (ep.kind, ep.host, ep.port) == ("udpout", "127.0.0.1", 14542)
    with pytest.raises(PortError, match="UDP"):
        onboard_endpoint(0, "tcpin:127.0.0.1:5760")
    with pytest.raises(PortError):
        onboard_endpoint(0, "udpout:nonsense")


def test_onboard_streams_at_px4s_rates(link):
    """MAVLINK_MODE_ONBOARD defaults (mavlink_main.cpp:1445-1508, :2144-2147) over 4 s of
    autopilot time, published every ms; HOME_POSITION once the vehicle stood on the ground."""
    port, client = link
    n = counts(run_streams(port, 0.0, 4.0, client))
    expect = {"HEARTBEAT": 4, "TIMESYNC": 40, "HIGHRES_IMU": 200, "LOCAL_POSITION_NED": 120, "ATTITUDE": 400,
              "ODOMETRY": 120, "ATTITUDE_QUATERNION": 200, "EXTENDED_SYS_STATE": 20, "HOME_POSITION": 2,
              "SYS_STATUS": 20, "SYSTEM_TIME": 4}
    for name, k in expect.items():
        assert abs(n.get(name, 0) - k) <= 1, (name, n.get(name), k)
    assert "ATTITUDE_TARGET" not in n  # nothing flown


def test_message_contents(link):
    """NED/FRD on the wire; ODOMETRY as EKF2's vehicle_odometry (LOCAL_NED / LOCAL_NED,
    EKF2.cpp:1525, ODOMETRY.hpp:66, :140); HEARTBEAT as HEARTBEAT.hpp; SYS_STATUS's pre-arm bit
    (SYS_STATUS.hpp:140-142); landed state (EXTENDED_SYS_STATE.hpp:100-103)."""
    port, client = link
    last = {m.get_type(): m for m in run_streams(port, 0.0, 0.05, client)}
    o = last["ODOMETRY"]
    assert (o.frame_id, o.child_frame_id) == (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_LOCAL_NED)
    assert (o.x, o.y, o.z) == pytest.approx((2.0, 1.0, -3.0))
    assert (o.vx, o.vy, o.vz) == pytest.approx((0.2, 0.1, -0.3))
    assert (o.rollspeed, o.pitchspeed, o.yawspeed) == pytest.approx((0.01, -0.02, -0.03))
    assert o.estimator_type == mav.MAV_ESTIMATOR_TYPE_AUTOPILOT and math.isnan(o.pose_covariance[0])
    assert o.time_usec == 34000  # the sample's time: the step at which the 30 Hz stream was due (0, 1/30 s)
    h = last["HEARTBEAT"]
    assert (h.autopilot, h.type, h.system_status) == (mav.MAV_AUTOPILOT_PX4, mav.MAV_TYPE_QUADROTOR,
                                                      mav.MAV_STATE_STANDBY)
    assert h.custom_mode == (4 << 16) | (3 << 24) and h.base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    s = last["SYS_STATUS"]
    assert s.onboard_control_sensors_health & mav.MAV_SYS_STATUS_PREARM_CHECK  # Hold can arm
    assert not s.onboard_control_sensors_present & mav.MAV_SYS_STATUS_PREARM_CHECK
    assert last["EXTENDED_SYS_STATE"].landed_state == mav.MAV_LANDED_STATE_ON_GROUND
    assert tuple(last["ATTITUDE_QUATERNION"].__dict__[k] for k in ("q1", "q2", "q3", "q4")) == pytest.approx(
        (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)))  # ENU identity = nose east = yaw 90 deg in NED
    assert last["HOME_POSITION"].x == pytest.approx(2.0)


def test_first_sender_is_the_partner_for_good(link):
    """mavlink_receiver.cpp:3139-3160: the first datagram's address becomes the partner and is
    never replaced; later senders are executed, answered to the partner."""
    port, first = link
    other = Client()
    try:
        command(first, port, mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        assert port.partner == ("127.0.0.1", first.port)
        assert command(other, port, mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == []  # nothing comes back to it
        assert port.commander.armed  # but it was executed
        assert acks(first.drain()) == [(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0)]  # answered to the partner
        run_streams(port, 0.0, 0.01)
        assert other.drain() == []
        assert counts(first.drain()).get("HEARTBEAT") == 1
        assert port.partner == ("127.0.0.1", first.port)
    finally:
        other.close()


def test_commands_of_the_receiver(link):
    """mavlink_receiver.cpp: REQUEST_MESSAGE ACCEPTED with the message, DENIED without a
    stream (:681-713); SET_MESSAGE_INTERVAL FAILED for HEARTBEAT and unknown ids (:2170-2206),
    -1 stops, >0 sets; a command for another system: FAILED (:484-495)."""
    port, client = link
    run_streams(port, 0.0, 0.01)
    client.drain()
    msgs = command(client, port, mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_HOME_POSITION)
    assert acks(msgs) == [(mav.MAV_CMD_REQUEST_MESSAGE, 0)] and counts(msgs).get("HOME_POSITION") == 1
    assert acks(command(client, port, mav.MAV_CMD_REQUEST_MESSAGE, 9999)) == [(mav.MAV_CMD_REQUEST_MESSAGE, 2)]
    msgs = command(client, port, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1.0, target=(0, 0))
    assert acks(msgs) == [(mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 0)]
    v = next(m for m in msgs if m.get_type() == "AUTOPILOT_VERSION")
    assert v.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2 and v.flight_sw_version >> 24 == 1
    s = mav.MAV_CMD_SET_MESSAGE_INTERVAL
    assert acks(command(client, port, s, mav.MAVLINK_MSG_ID_HEARTBEAT, 100000)) == [(s, 4)]
    assert acks(command(client, port, s, 9999, 100000)) == [(s, 4)]
    assert acks(command(client, port, s, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 200000)) == [(s, 0)]
    assert acks(command(client, port, s, mav.MAVLINK_MSG_ID_ATTITUDE, -1)) == [(s, 0)]
    msgs = command(client, port, mav.MAV_CMD_GET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED)
    assert next(m for m in msgs if m.get_type() == "MESSAGE_INTERVAL").interval_us == 200000
    n = counts(run_streams(port, 1.0, 3.0, client))
    assert abs(n["LOCAL_POSITION_NED"] - 10) <= 1 and "ATTITUDE" not in n
    assert acks(command(client, port, s, mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 0)) == [(s, 0)]  # default again
    assert abs(counts(run_streams(port, 3.0, 4.0, client))["LOCAL_POSITION_NED"] - 30) <= 1
    a = mav.MAV_CMD_COMPONENT_ARM_DISARM
    assert acks(command(client, port, a, 1.0, target=(SYSID + 1, 1))) == [(a, 4)]
    assert acks(command(client, port, a, 1.0, target=(0, 0))) == [(a, 4)]  # broadcast: not for the commander
    msgs = command(client, port, a, 1.0)
    ack = next(m for m in msgs if m.get_type() == "COMMAND_ACK")
    assert (ack.result, ack.target_system, ack.target_component) == (0, SYSID, 191) and port.commander.armed


def test_timesync_is_answered_as_px4s(link):
    """mavlink_timesync.cpp:62-72: a request (tc1 = 0) comes back with tc1 = now [ns] and its ts1."""
    port, client = link
    client.send(port, mav.MAVLink_timesync_message(0, 123456789))
    port.poll(2.5)
    m = next(m for m in client.drain() if m.get_type() == "TIMESYNC")
    assert (m.tc1, m.ts1) == (2_500_000_000, 123456789)


def sat(thrust=0.4, mask=7, target=(SYSID, 1), q=(1.0, 0.0, 0.0, 0.0)):
    return mav.MAVLink_set_attitude_target_message(0, target[0], target[1], mask, list(q), 0.0, 0.0, 0.0, thrust)


def test_setpoints_and_their_targets(link):
    """Setpoints for (sysid or 0, 1 or 0) keep the stream alive (mavlink_receiver.cpp:1516-1518);
    others and unusable ones are counted, not used."""
    port, client = link
    client.send(port, sat(target=(SYSID + 1, 1)), sat(target=(SYSID, 191)))
    port.poll(0.0)
    assert port.stats.not_for_us == 2 and port.commander.offboard_lost(0.0)
    client.send(port, sat(q=(0.0, 0.0, 0.0, 0.0)))
    port.poll(0.0)
    assert port.stats.rejected_setpoints == 1 and port.commander.offboard_lost(0.0)
    client.send(port, sat(target=(0, 0)))
    port.poll(0.1)
    assert port.stats.setpoints == 1 and not port.commander.offboard_lost(0.1)


def test_thrust_body_extension_is_read(link):
    """SET_ATTITUDE_TARGET's thrust_body extension (common.xml), which pymavlink 2.4 lacks, is
    read from the payload (THRUST_BODY_SET = 32)."""
    port, client = link
    cmd_ = port.commander
    cmd_.handle_command(0.0, cm.CMD_DO_SET_MODE, (1.0, 6.0, 0.0, 0, 0, 0, 0))
    payload = struct.pack("<I4f4f3B3f", 0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, SYSID, 1, 7 | 32, 0.0, 0.0, -0.6)
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, 0, SYSID, 191, 82, 0)
    frame = header + payload
    frame += frame_crc(frame).to_bytes(2, "little")
    client.raw(port, frame)
    port.poll(0.0)
    client.raw(port, frame)
    port.poll(0.01)
    assert cmd_.target is not None and cmd_.target.thrust == pytest.approx(0.6)


def test_bad_input_is_counted_and_survived(link):
    """Junk, a bad CRC, a frame cut short and an oversized datagram (> 8000 bytes, PX4's
    buffer, mavlink_receiver.cpp:3077) are counted; the next good command is answered."""
    port, client = link
    good = client.enc.pack([mav.MAVLink_command_long_message(SYSID, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0,
                                                             mav.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0)])
    client.raw(port, b"\x00garbage" * 10)
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    client.raw(port, bytes(bad_crc))
    client.raw(port, good[:-5])
    client.raw(port, b"\xfd" * (MAX_DATAGRAM + 1000))
    client.raw(port, bytes(range(256)) * 4)
    port.poll(0.0)
    s = port.stats
    assert s.oversized == 1 and s.junk_bytes > 0
    assert s.handler_errors == 0
    client.drain()
    msgs = command(client, port, mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert acks(msgs) == [(mav.MAV_CMD_REQUEST_MESSAGE, 0)]


def test_a_setpoint_flood_costs_a_bounded_poll(link):
    """At most max_datagrams per poll; the newest setpoint is flown, the others counted as
    superseded at the next physics step."""
    port, client = link
    port.commander.handle_command(0.0, cm.CMD_DO_SET_MODE, (1.0, 6.0, 0.0, 0, 0, 0, 0))
    for i in range(200):
        client.send(port, sat(thrust=i / 1000.0))
    assert port.poll(0.0) == port.max_datagrams == 64
    while port.poll(0.0):
        pass
    assert port.stats.setpoints == 200
    port.publish(0.0, REPORT)
    assert port.stats.superseded_setpoints == 199
    assert port.commander.target.thrust == pytest.approx(0.199)


def _impaired_port(client: Client, **impairment) -> Px4Port:
    from amlink.impair import LinkImpairment

    port = Px4Port(0, SYSID, cm.Commander(), parse_endpoint(f"udpout:127.0.0.1:{client.port}"),
                   impairment=LinkImpairment(rate_hz=1000.0, seed=3, **impairment))
    port.open()
    return port


def test_a_delayed_link_hands_each_datagram_over_when_it_arrives():
    """[link].delay_s = 10 ms: a setpoint read at t = 0 reaches the commander at 10 ms of the
    autopilot's clock, however often the port is polled before."""
    client = Client()
    port = _impaired_port(client, delay_s=0.010)
    try:
        client.send(port, sat(target=(0, 0)))
        for t in (0.0, 0.0, 0.004, 0.009):
            port.poll(t)
            assert port.stats.setpoints == 0
        port.poll(0.010)
        assert port.stats.setpoints == 1 and not port.commander.offboard_lost(0.010)
        assert port.impaired.stats.delayed == port.impaired.stats.sent == 1
    finally:
        port.close()
        client.close()


def test_a_lossy_link_drops_its_share_of_datagrams_and_an_ideal_one_none():
    """loss = 0.3 of 400 setpoints, one per physics step: about 120 lost (binomial, 4 sigma),
    each reaching the commander when it was read; an ideal impairment builds no channel."""
    client = Client()
    port = _impaired_port(client, loss=0.3)
    try:
        for k in range(400):
            client.send(port, sat(target=(0, 0)))
            time_s = k * 1e-3
            deadline = time.monotonic() + 0.5
            while port.stats.datagrams_rx < k + 1 and time.monotonic() < deadline:
                port.poll(time_s)
            port.poll(time_s)
        lost = port.impaired.stats.lost
        assert abs(lost - 120) < 4 * math.sqrt(400 * 0.3 * 0.7)
        assert port.stats.setpoints == 400 - lost and port.impaired.stats.delayed == 0
    finally:
        port.close()
        client.close()
    from amlink.impair import LinkImpairment

    ideal = Px4Port(0, SYSID, cm.Commander(), impairment=LinkImpairment())
    assert ideal.impaired is None
