"""The companion's device clients (companion.devices) against the simulator's device servers:
the arm through dynamixel-sdk over TCP and a pty (current control, torques in and out with
the stated constant and limits, the hold on close), the F/T through RDT (exact counts, drops,
bias), the object's pose from the mocap stream; and their errors: an unreachable bus, a
silent servo, corrupt status packets, a refused F/T port, bad endpoints."""
from __future__ import annotations

import math
import select
import socket
import threading
import time

import numpy as np
import pytest

pytest.importorskip("dynamixel_sdk")

from amlink import dxl_protocol as dxl  # noqa: E402
from amlink import mocap_protocol as mp  # noqa: E402
from amlink import rdt_protocol as rdt  # noqa: E402
from companion.devices.arm import ArmClient, ArmError, ServoNotAnswering, parse_arm_endpoint  # noqa: E402
from companion.devices.mocap import MocapClient  # noqa: E402
from companion.devices.netft import FtError, NetFtClient, parse_ft_endpoint  # noqa: E402
from simulator.mocap_stream import MocapStream  # noqa: E402
from simulator.netft import NetFtServer  # noqa: E402
from simulator.servo_bus import ServoBus  # noqa: E402
from tests.simulator.servo_testing import serving  # noqa: E402

NMU = dxl.XM540_W270.nm_per_current_unit
Q0 = np.array([1.0, -2.0, 1.0])  # am3dof's nominal pose
TAU_MAX = np.array([6.0, 4.0, 2.0])  # am3dof's joint_torque_max_nm


def _free_port(kind=socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("via", ["tcp", "pty"])
def test_the_arm_in_current_control_through_dynamixel_sdk(via, tmp_path):
    link = str(tmp_path / "ttyARM")
    bus = ServoBus(3, q0_rad=Q0, torque_max_nm=TAU_MAX, endpoint="tcpin:127.0.0.1:0",
                   pty_link=link if via == "pty" else None)
    bus.open()
    try:
        with serving(bus) as lock:
            arm = ArmClient("tcp:%s:%d" % bus.address if via == "tcp" else f"{link}:4000000", 3)
            arm.open()
            with lock:
                assert all(s.torque_on and s.get("operating_mode") == dxl.MODE_CURRENT for s in bus.servos)
            np.testing.assert_allclose(arm.torque_limits_nm, TAU_MAX, atol=NMU / 2)
            q, qdot, tau = Q0 + [0.01, -0.02, 0.03], np.array([0.5, -0.25, 1.0]), np.array([1.0, -3.3, 0.7])
            with lock:
                bus.observe(0.5, q, qdot, tau)
            s = arm.read()
            np.testing.assert_allclose(s.q, q, atol=dxl.RAD_PER_PULSE / 2 + 1e-12)
            np.testing.assert_allclose(s.qdot, qdot, atol=dxl.RADPS_PER_VELOCITY_UNIT / 2 + 1e-12)
            np.testing.assert_allclose(s.tau_measured_nm, np.round(tau / NMU) * NMU, rtol=1e-12)
            assert s.rtt_ns > 0 and s.t_ns > 0
            sent = arm.write_torques([2.5, -1.0, 3.0])  # 3 N m is beyond joint 3's 2 N m
            np.testing.assert_allclose(sent, [round(2.5 / NMU) * NMU, round(-1.0 / NMU) * NMU, 309 * NMU])
            arm.read()  # the write is on the bus before the read's answer
            with lock:
                np.testing.assert_allclose(bus.joint_torques_nm(q, np.zeros(3)), sent, rtol=1e-12)
            arm.close()
            with lock:  # left holding where it is, in position control
                assert all(s.torque_on and s.get("operating_mode") == dxl.MODE_POSITION for s in bus.servos)
                np.testing.assert_array_equal(bus.joint_torques_nm(q, np.zeros(3)), 0.0)
                assert np.all(bus.joint_torques_nm(q + 0.05, np.zeros(3)) < 0)
        assert arm.stats.crc_errors == arm.stats.timeouts == 0 and arm.stats.reads == 2
    finally:
        bus.close()


def test_arm_errors_name_the_bus_and_the_silent_servo():
    port = _free_port()
    with pytest.raises(ArmError, match=f"tcp:127.0.0.1:{port} unreachable"):
        ArmClient(f"tcp:127.0.0.1:{port}", 3).open()
    bus = ServoBus(2, endpoint="tcpin:127.0.0.1:0")
    bus.open()
    try:
        with serving(bus):
            arm = ArmClient("tcp:%s:%d" % bus.address, 3)
            with pytest.raises(ServoNotAnswering, match="no servo answering ID 3") as e:
                arm.open()
            assert e.value.ids == (3,)
    finally:
        bus.close()


def test_corrupt_status_packets_are_counted_and_refused():
    """A bus whose answers carry a bad CRC: the SDK reports them corrupt, the client counts
    them and says so."""
    srv = socket.create_server(("127.0.0.1", 0))
    stop = threading.Event()

    def corrupt_bus() -> None:
        conn, _ = srv.accept()
        parser = dxl.PacketParser()
        with conn:
            conn.settimeout(0.1)
            while not stop.is_set():
                try:
                    data = conn.recv(256)
                except TimeoutError:
                    continue
                if not data:
                    return
                for p in parser.feed(data):
                    st = bytearray(dxl.status(p.dxl_id, 0, bytes((0x60, 0x04, 46))))
                    st[-1] ^= 0xFF
                    conn.sendall(bytes(st))

    t = threading.Thread(target=corrupt_bus, daemon=True)
    t.start()
    arm = ArmClient("tcp:127.0.0.1:%d" % srv.getsockname()[1], 1)
    with pytest.raises(ArmError, match="ID 1 answered PING with corrupt status packets"):
        arm.open()
    stop.set()
    t.join(2.0)
    srv.close()
    assert arm.stats.crc_errors == 2


def test_endpoints_parse_or_say_what_is_wrong():
    assert str(parse_arm_endpoint("/dev/ttyUSB0:4000000")) == "/dev/ttyUSB0:4000000"
    assert parse_arm_endpoint("/dev/ttyUSB0").baud == 57600  # the X series' factory rate
    assert parse_arm_endpoint("tcp:127.0.0.1:7200") == parse_arm_endpoint("tcp:127.0.0.1:7200")
    for bad, why in [("udp:1.2.3.4:5", "not reached by udpin"), ("/dev/ttyUSB0:1500000", "not 1500000"),
                     ("tcp:host", "HOST:PORT"), ("", "empty")]:
        with pytest.raises(ValueError, match=why):
            parse_arm_endpoint(bad)
    assert parse_ft_endpoint("udp:192.168.1.1:49152") == ("192.168.1.1", 49152)
    for bad in ("tcp:1.2.3.4:5", "udp:0.0.0.0:49152", "udp:1.2.3.4:0"):
        with pytest.raises(ValueError, match="--ft"):
            parse_ft_endpoint(bad)
    with pytest.raises(ValueError, match="--mocap"):
        MocapClient("tcp:127.0.0.1:7400")


def test_the_wrist_sensor_through_rdt():
    server = NetFtServer(endpoint="udpin:127.0.0.1:0")
    server.open()
    try:
        ft = NetFtClient("udp:%s:%d" % server.address)
        ft.open()
        w = np.array([0.1234567, -2.5, 9.81, 0.0004567, -0.05, 0.012])
        with serving(server) as lock:
            with lock:
                server.publish(0.0, w)
            s = ft.wait(2.0)
            deadline = time.monotonic() + 2.0  # a record streamed before the publish may come first
            while not np.any(ft.read().wrench_E) and time.monotonic() < deadline:
                select.select([ft.fileno()], [], [], 0.01)
                ft.poll()
            np.testing.assert_array_equal(ft.read().wrench_E, np.round(w * 1e6) / 1e6)
            ft.bias()
            deadline = time.monotonic() + 2.0
            while np.any(ft.read().wrench_E) and time.monotonic() < deadline:  # until a record reads the bias
                select.select([ft.fileno()], [], [], 0.01)
                ft.poll()
            np.testing.assert_array_equal(ft.read().wrench_E, 0.0)
            assert server.stats.biases == 1
            ft.close()
        assert ft.stats.dropped == 0 and ft.stats.out_of_order == 0 and ft.stats.records >= 2
    finally:
        server.close()


def test_rdt_drops_and_reordering_are_counted_and_a_refused_port_is_named():
    sensor = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sensor.bind(("127.0.0.1", 0))
    ft = NetFtClient("udp:127.0.0.1:%d" % sensor.getsockname()[1])
    ft.open()
    req, addr = sensor.recvfrom(64)
    assert rdt.unpack_request(req) == (rdt.CMD_START_REALTIME, 0)
    for seq in (1, 2, 5, 6, 6, 4, 7):
        sensor.sendto(rdt.pack_record(rdt.Record(seq, seq, 0, (seq, 0, 0, 0, 0, -seq))), addr)
    select.select([ft.fileno()], [], [], 1.0)
    while ft.poll():
        select.select([ft.fileno()], [], [], 0.05)
    assert (ft.stats.records, ft.stats.dropped, ft.stats.out_of_order) == (7, 2, 2)
    assert ft.read().rdt_sequence == 7 and ft.read().wrench_E[5] == -7e-6
    ft.bias()
    assert rdt.unpack_request(sensor.recvfrom(64)[0]).command == rdt.CMD_SET_SOFTWARE_BIAS
    ft.close()
    sensor.close()
    gone = NetFtClient("udp:127.0.0.1:%d" % _free_port(socket.SOCK_DGRAM))
    gone.open()
    with pytest.raises(FtError, match="refused"):
        gone.wait(0.3)
    gone.close()


def test_the_objects_pose_from_the_mocap_stream():
    lp = _free_port(socket.SOCK_DGRAM)
    stream = MocapStream(endpoint="udpin:127.0.0.1:0", destinations=[f"udpout:127.0.0.1:{lp}"])
    stream.open()
    try:
        sub = MocapClient("udp:%s:%d" % stream.address)
        listen = MocapClient(f"udpin:127.0.0.1:{lp}")
        sub.open()
        listen.open()
        assert select.select(stream.fds(), [], [], 2.0)[0]
        stream.poll(0.0)
        assert len(stream.subscribers) == 1
        yaw = 0.7
        q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        for k in range(3):
            if k != 1:  # frame 1 lost
                stream.publish(k * 0.01, [1.0, 2.0, 0.25], q)
            else:
                stream._frame += 1
        for c in (sub, listen):
            select.select([c.fileno()], [], [], 1.0)
            while c.poll():
                select.select([c.fileno()], [], [], 0.05)
            s = c.read()
            assert s.frame == 2 and s.time_us == 20000 and c.stats.dropped == 1
            pose = c.object_pose()
            assert pose.p_W_m == (1.0, 2.0, 0.25) and pose.yaw_rad == pytest.approx(yaw, abs=1e-12)
        stream.poll(mp.SUBSCRIPTION_TIMEOUT_S + 0.1)  # no renewal: forgotten
        assert stream.subscribers == [] and stream.stats.expired == 1
        sub.close()
        listen.close()
    finally:
        stream.close()


def test_the_arms_sync_read_split_into_request_and_collect():
    bus = ServoBus(3, q0_rad=Q0, torque_max_nm=TAU_MAX, endpoint="tcpin:127.0.0.1:0")
    bus.open()
    try:
        with serving(bus) as lock:
            arm = ArmClient("tcp:%s:%d" % bus.address, 3)
            arm.open()
            q, qdot, tau = Q0 + [0.02, 0.01, -0.03], np.array([0.1, 0.2, -0.3]), np.array([0.5, 1.0, -1.5])
            with lock:
                bus.observe(0.5, q, qdot, tau)
            assert not arm.requested
            arm.request()
            assert arm.requested
            s = arm.collect()
            assert not arm.requested and s.rtt_ns > 0
            np.testing.assert_allclose(s.q, q, atol=dxl.RAD_PER_PULSE / 2 + 1e-12)
            np.testing.assert_allclose(s.tau_measured_nm, np.round(tau / NMU) * NMU, rtol=1e-12)
            arm.request()
            arm.request()  # the first one's answers are taken off the bus before the second goes out
            np.testing.assert_allclose(arm.collect().qdot, qdot, atol=dxl.RADPS_PER_VELOCITY_UNIT / 2 + 1e-12)
            arm.write_torques([1.0, -1.0, 0.5])
            arm.request()
            arm.close()  # with answers still out: taken first, then the hold on close works
            with lock:
                assert all(s.torque_on and s.get("operating_mode") == dxl.MODE_POSITION for s in bus.servos)
        assert arm.stats.reads == 4 and arm.stats.crc_errors == arm.stats.timeouts == 0
    finally:
        bus.close()


def test_a_bus_that_went_away_is_named_by_every_call_after_it():
    """The servo bus closes under a sync read (the simulator ended, a cable pulled): the read
    fails naming it, and so do the calls after it, down to the close's hold, rather than the
    SDK's "Port is in use" that an exception mid-transaction leaves behind."""
    bus = ServoBus(3, q0_rad=Q0, torque_max_nm=TAU_MAX, endpoint="tcpin:127.0.0.1:0")
    bus.open()
    arm = ArmClient("tcp:%s:%d" % bus.address, 3)
    try:
        with serving(bus):
            arm.open()
            arm.read()
        bus.close()
        errors = []
        for call in (arm.read, lambda: arm.write_torques([0.0, 0.0, 0.0]), arm.read):
            with pytest.raises(ArmError) as e:
                call()
            errors.append(str(e.value))
        with pytest.raises(ArmError) as e:
            arm.close()  # the hold on close fails as well, and the port is closed all the same
        errors.append(str(e.value))
        assert all("in use" not in m for m in errors), errors
        assert "tcp:127.0.0.1" in errors[0] and arm._port is None
    finally:
        bus.close()
