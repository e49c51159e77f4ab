"""The emulated DYNAMIXEL bus (amlink.dxl_protocol, simulator.dxl_servo, simulator.servo_bus):
packets byte for byte as the e-Manual's examples, the CRC as the e-Manual's (and the SDK's)
table, byte stuffing, status errors, ROBOTIS's dynamixel-sdk over TCP and over a pty, and the
servos' torque: position-mode hold, current mode with its constant and limits, the present
current they report."""
from __future__ import annotations

import math
import os
import socket
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amcore.config import JointEffortSpec
from amlink import dxl_protocol as dxl
from simulator.dxl_servo import BusPort, DxlBus, XServo
from simulator.servo_bus import ServoBus

from .servo_testing import serving

sdk = pytest.importorskip("dynamixel_sdk")

H = bytes.fromhex
M = dxl.XM540_W270
NMU = M.nm_per_current_unit  # N m per current unit


def test_crc_table_is_the_e_manuals():
    from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler

    t = dxl._CRC_TABLE
    assert t[:8] == (0x0000, 0x8005, 0x800F, 0x000A, 0x801B, 0x001E, 0x0014, 0x8011)
    data = bytes(range(256)) * 2
    assert dxl.crc16(data) == Protocol2PacketHandler().updateCRC(0, list(data), len(data))


# (packet as built, the e-Manual's bytes): protocol2.md's examples
GOLDEN = [
    (dxl.instruction(1, dxl.PING), H("FFFFFD0001030001194E")),
    (dxl.status(1, 0, H("060426")), H("FFFFFD000107005500060426655D")),
    (dxl.status(2, 0, H("060426")), H("FFFFFD0002070055000604266F6D")),
    (dxl.instruction(1, dxl.READ, H("84000400")), H("FFFFFD0001070002840004001D15")),
    (dxl.status(1, 0, H("A6000000")), H("FFFFFD000108005500A60000008CC0")),
    (dxl.instruction(1, dxl.WRITE, H("740000020000")), H("FFFFFD0001090003740000020000CA89")),
    (dxl.status(1, 0), H("FFFFFD000104005500A10C")),
    (dxl.instruction(dxl.BROADCAST_ID, dxl.SYNC_READ, H("840004000102")), H("FFFFFD00FE090082840004000102CEFA")),
    (dxl.instruction(dxl.BROADCAST_ID, dxl.SYNC_WRITE, H("74000400019600000002AA000000")),
     H("FFFFFD00FE11008374000400019600000002AA0000008287")),
    (dxl.instruction(dxl.BROADCAST_ID, dxl.BULK_READ, H("01900002000292000100")),
     H("FFFFFD00FE0D0092019000020002920001001A05")),
    (dxl.status(1, 0, H("7700")), H("FFFFFD0001060055007700C369")),
    (dxl.status(2, 0, H("24")), H("FFFFFD000205005500248BA9")),
]


@pytest.mark.parametrize("built, manual", GOLDEN)
def test_packets_are_byte_for_byte_the_e_manuals_examples(built, manual):
    assert built == manual
    (pkt,) = dxl.PacketParser().feed(manual)
    assert pkt.crc_ok


def _at(pulse: int) -> float:
    return dxl.pulse_to_rad(pulse)


def test_the_bus_answers_the_e_manuals_sync_read_and_bulk_read_exactly():
    w210 = dxl.ServoModel("XM430-W210", 1030, 3.0, 2.3, 77.0, 1193, 330, firmware_version=38)
    s1, s2 = XServo(1, w210, _at(166)), XServo(2, w210, _at(2079))
    port = BusPort(DxlBus([s1, s2]))
    assert port.feed(GOLDEN[0][1]) == GOLDEN[1][1]  # PING ID 1 -> model 1030, firmware 38
    assert port.feed(GOLDEN[7][1]) == GOLDEN[4][1] + H("FFFFFD0002080055001F080000BABE")
    s1._set("present_input_voltage", 119)  # the example's 11.9 V; 36 degC is ours too
    assert port.feed(GOLDEN[9][1]) == GOLDEN[10][1] + GOLDEN[11][1]


@given(st.binary(max_size=64))
def test_stuffing_round_trips_and_leaves_no_header_inside(body):
    s = dxl.stuff(body)
    assert dxl.unstuff(s) == body
    assert dxl.HEADER not in s  # a receiver never mistakes a stuffed body for a packet's start


def test_stuffing_example_and_a_stuffed_status_decoded_by_the_sdk():
    assert dxl.stuff(H("5500FFFFFD01")) == H("5500FFFFFDFD01")
    pkt = dxl.status(1, 0, H("FFFFFDFF"))
    assert pkt[5] == 4 + 4 + 1  # LEN counts the stuffed byte
    (back,) = dxl.PacketParser().feed(pkt)
    assert back.crc_ok and back.params == H("00FFFFFDFF")


@settings(max_examples=50)
@given(st.lists(st.integers(0, 255), min_size=0, max_size=40), st.integers(1, 30), st.binary(max_size=20))
def test_the_parser_finds_the_same_packets_however_the_stream_is_cut(params, cut, junk):
    pkts = [dxl.instruction(3, dxl.WRITE, bytes(params[:k])) for k in range(0, len(params) + 1, 7)]
    stream = junk.replace(b"\xff", b"") + b"".join(pkts)
    p = dxl.PacketParser()
    got = []
    for k in range(0, len(stream), cut):
        got += p.feed(stream[k:k + cut])
    assert [(g.dxl_id, g.inst, g.params) for g in got] == [(3, dxl.WRITE, bytes(params[:k]))
                                                            for k in range(0, len(params) + 1, 7)]
    assert all(g.crc_ok for g in got)


def test_a_bad_crc_gets_protocol_2s_crc_status_error():
    port = BusPort(DxlBus([XServo(1, M), XServo(2, M)]))
    bad = bytearray(dxl.instruction(2, dxl.READ, H("84000400")))
    bad[-1] ^= 0x5A
    (st_,) = dxl.PacketParser().feed(port.feed(bytes(bad)))
    assert (st_.dxl_id, st_.inst, st_.params[0]) == (2, dxl.STATUS, dxl.ERR_CRC)
    assert port.bus.stats.crc_errors == 1
    bad_bc = bytearray(dxl.instruction(dxl.BROADCAST_ID, dxl.PING))
    bad_bc[-2] ^= 1
    assert port.feed(bytes(bad_bc)) == b""  # nobody answers a corrupt broadcast


def _status_of(port, *args) -> dxl.Packet:
    (s,) = dxl.PacketParser().feed(port.feed(dxl.instruction(*args)))
    return s


def test_write_rules_access_range_limit_length():
    s = XServo(1, M, current_limit=500)
    port = BusPort(DxlBus([s]))
    err = lambda *a: _status_of(port, 1, *a).params[0]  # noqa: E731
    assert s.torque_on and s.get("operating_mode") == dxl.MODE_POSITION  # power-up (module doc)
    assert err(dxl.WRITE, H("0B00") + b"\x00") == dxl.ERR_ACCESS  # Operating Mode: EEPROM, torque on
    assert err(dxl.WRITE, H("2600") + (100).to_bytes(2, "little")) == dxl.ERR_ACCESS  # Current Limit too
    assert err(dxl.WRITE, H("8400") + b"\x00\x00") == dxl.ERR_ACCESS  # Present Position: read only
    assert err(dxl.WRITE, H("0E00") + b"\x00") == dxl.ERR_ACCESS  # 14: undefined
    assert err(dxl.WRITE, H("7400") + b"\x00\x08") == dxl.ERR_DATA_LENGTH  # half of Goal Position
    assert err(dxl.WRITE, H("4000") + b"\x02") == dxl.ERR_DATA_RANGE  # Torque Enable 2
    assert err(dxl.WRITE, H("7400") + (5000).to_bytes(4, "little")) == dxl.ERR_DATA_LIMIT  # > Max Position Limit
    assert err(dxl.WRITE, H("6600") + (501).to_bytes(2, "little", signed=True)) == dxl.ERR_DATA_LIMIT
    assert err(dxl.WRITE, H("6600") + (-500).to_bytes(2, "little", signed=True)) == 0
    assert err(dxl.WRITE, H("4000") + b"\x00") == 0
    assert err(dxl.WRITE, H("0B00") + b"\x01") == dxl.ERR_DATA_RANGE  # velocity mode: not emulated
    assert err(dxl.WRITE, H("0B00") + b"\x00") == 0 and s.get("operating_mode") == 0
    assert err(dxl.REG_WRITE, H("7400") + bytes(4)) == dxl.ERR_INSTRUCTION
    assert _status_of(port, 1, dxl.READ, H("9200") + (1).to_bytes(2, "little")).params == bytes((0, 36))
    assert err(dxl.READ, H("9000") + (10).to_bytes(2, "little")) == dxl.ERR_ACCESS  # beyond the table


def test_status_return_level_bulk_write_and_reboot():
    s1, s2 = XServo(1, M, 0.3), XServo(2, M, -0.3)
    port = BusPort(DxlBus([s1, s2]))
    assert s1.write(68, b"\x01") == 0  # Status Return Level 1: PING and READ only
    assert port.feed(dxl.instruction(1, dxl.WRITE, H("4100") + b"\x01")) == b"" and s1.get("led") == 1
    assert _status_of(port, 1, dxl.READ, H("4100") + H("0100")).params == H("0001")
    assert s1.write(68, b"\x00") == 0  # 0: PING only
    assert port.feed(dxl.instruction(1, dxl.READ, H("4100") + H("0100"))) == b""
    assert _status_of(port, 1, dxl.PING).params[0] == 0
    for s in (s1, s2):
        _current_mode(s, 0)
    body = bytes((1,)) + H("6600") + H("0200") + (40).to_bytes(2, "little", signed=True) \
        + bytes((2,)) + H("6600") + H("0200") + (-70).to_bytes(2, "little", signed=True)
    assert port.feed(dxl.instruction(dxl.BROADCAST_ID, dxl.BULK_WRITE, body)) == b""
    assert (s1.get("goal_current"), s2.get("goal_current")) == (40, -70)
    s2.observe(0.1, -0.25, 0.0, 0.0)
    assert _status_of(port, 2, dxl.REBOOT).params[0] == 0
    assert s2.torque_on and s2.get("operating_mode") == dxl.MODE_CURRENT  # EEPROM kept, RAM reset
    assert s2.get("goal_current") == 0 and s2.get("goal_position") == dxl.rad_to_pulse(-0.25)


# -- dynamixel-sdk against the emulated bus --------------------------------------------
class _TcpPort(sdk.PortHandler):
    def setupPort(self, cflag_baud):
        import serial

        self.ser = serial.serial_for_url(self.port_name, timeout=0)
        with socket.socket(fileno=os.dup(self.ser.fileno())) as s:
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.is_open = True
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True


Q0 = np.array([0.1, -0.2, 0.3])


@pytest.fixture(params=["tcp", "pty"])
def sdk_bus(request, tmp_path):
    """(bus, lock, port handler) with dynamixel-sdk's port open on the bus, over TCP or the pty."""
    link = str(tmp_path / "ttyDXL")
    bus = ServoBus(3, q0_rad=Q0, torque_max_nm=[6.0, 4.0, 2.0], endpoint="tcpin:127.0.0.1:0",
                   pty_link=link if request.param == "pty" else None)
    bus.open()
    with serving(bus) as lock:
        port = _TcpPort("socket://%s:%d" % bus.address) if request.param == "tcp" else sdk.PortHandler(link)
        assert port.setBaudRate(1000000)
        yield bus, lock, port
        port.closePort()
    bus.close()
    assert not os.path.lexists(link)


def test_sdk_pings_reads_sync_reads_and_sync_writes(sdk_bus):
    bus, lock, port = sdk_bus
    ph = sdk.PacketHandler(2.0)
    for i in (1, 2, 3):
        assert ph.ping(port, i) == (1120, sdk.COMM_SUCCESS, 0)
    assert ph.ping(port, 4)[1] == sdk.COMM_RX_TIMEOUT
    assert ph.read4ByteTxRx(port, 2, 132) == (dxl.rad_to_pulse(-0.2), sdk.COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 3, 38)[0] == round(2.0 / NMU)  # the torque limit as Current Limit
    tau, qdot = np.array([0.5, -1.25, 0.0]), np.array([0.3, -0.6, 0.0])
    with lock:
        bus.observe(0.01, Q0, qdot, tau)
    r = sdk.GroupSyncRead(port, ph, *dxl.PRESENT_BLOCK)
    for i in (1, 2, 3):
        r.addParam(i)
    assert r.txRxPacket() == sdk.COMM_SUCCESS
    for j, i in enumerate((1, 2, 3)):
        cur = int.from_bytes(r.getData(i, 126, 2).to_bytes(2, "little"), "little", signed=True)
        vel = int.from_bytes(r.getData(i, 128, 4).to_bytes(4, "little"), "little", signed=True)
        assert cur == round(tau[j] / NMU)
        assert vel == round(qdot[j] / dxl.RADPS_PER_VELOCITY_UNIT)
        assert r.getData(i, 132, 4) == dxl.rad_to_pulse(Q0[j])
    # current control: mode change refused while torque is on, accepted after torque off
    assert ph.write1ByteTxRx(port, 1, 11, 0) == (sdk.COMM_SUCCESS, dxl.ERR_ACCESS)
    w = sdk.GroupSyncWrite(port, ph, 64, 1)
    for i in (1, 2, 3):
        w.addParam(i, [0])
    assert w.txPacket() == sdk.COMM_SUCCESS
    for i in (1, 2, 3):
        assert ph.write1ByteTxRx(port, i, 11, 0) == (sdk.COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, i, 64, 1) == (sdk.COMM_SUCCESS, 0)
    units = [300, -200, 100]
    g = sdk.GroupSyncWrite(port, ph, 102, 2)
    for i, u in zip((1, 2, 3), units):
        g.addParam(i, list(u.to_bytes(2, "little", signed=True)))
    assert g.txPacket() == sdk.COMM_SUCCESS
    assert ph.read2ByteTxRx(port, 3, 102)[0] == 100  # the sync write is in before the next answer
    with lock:
        np.testing.assert_allclose(bus.joint_torques_nm(Q0, np.zeros(3)), np.array(units) * NMU, rtol=1e-12)


def test_a_second_tcp_client_is_closed_while_one_is_connected():
    bus = ServoBus(1, endpoint="tcpin:127.0.0.1:0")
    bus.open()
    try:
        with serving(bus):
            a = socket.create_connection(bus.address, timeout=2.0)
            a.sendall(dxl.instruction(1, dxl.PING))
            assert a.recv(64)[:5] == H("FFFFFD0001")
            b = socket.create_connection(bus.address, timeout=2.0)
            assert b.recv(64) == b""  # closed at once
            bad = bytearray(dxl.instruction(1, dxl.PING))
            bad[-1] ^= 0xFF
            a.sendall(bytes(bad))
            (s,) = dxl.PacketParser().feed(a.recv(64))
            assert s.params[0] == dxl.ERR_CRC
            a.close()
            b.close()
            time.sleep(0.02)
            c = socket.create_connection(bus.address, timeout=2.0)  # the first one gone: served
            c.sendall(dxl.instruction(1, dxl.PING))
            assert c.recv(64)[:5] == H("FFFFFD0001")
            c.close()
        assert bus.stats.refused_clients == 1 and bus.stats.clients == 2
    finally:
        bus.close()


# -- the torque the servos apply ---------------------------------------------------------
def _current_mode(s: XServo, goal_units: int) -> None:
    assert s.write(64, b"\x00") == 0 and s.write(11, b"\x00") == 0
    assert s.write(102, goal_units.to_bytes(2, "little", signed=True)) == 0
    assert s.write(64, b"\x01") == 0


def test_power_up_holds_the_start_pose():
    bus = ServoBus(3, q0_rad=Q0, endpoint=None)
    np.testing.assert_array_equal(bus.joint_torques_nm(Q0, np.zeros(3)), 0.0)
    tau = bus.joint_torques_nm(Q0 + [0.05, -0.05, 0.01], np.zeros(3))
    assert tau[0] < 0 < tau[1] and tau[2] < 0


def test_position_mode_returns_the_joint_toward_its_goal_and_holds_a_load():
    """A joint of inertia J (am3dof's joint 1, ~0.0135 kg m^2) let go 0.2 rad off its goal:
    the error never grows and ends within one pulse; under a constant load the servo holds
    with the error the P gain gives, e = load / (K_t I_stall (P / 128) / 885) pulses."""
    J, dt = 0.0135, 1e-4
    s = XServo(1, M, 0.0)
    q, w, e_max = 0.2, 0.0, []
    for k in range(20000):  # 2 s
        tau = s.torque_nm(q, w)
        w += tau / J * dt
        q += w * dt
        s.observe(k * dt, q, w, tau)
        e_max.append(abs(q))
    e = np.array(e_max)
    assert abs(q) < dxl.RAD_PER_PULSE
    later_max = np.maximum.accumulate(e[::-1])[::-1]  # the largest error from each instant on
    assert np.all(later_max <= e + dxl.RAD_PER_PULSE)
    load = 2.0
    q, w, cur = 0.0, 0.0, []
    for k in range(20000):
        tau = s.torque_nm(q, w)
        w += (tau - load) / J * dt
        q += w * dt
        s.observe(2.0 + k * dt, q, w, tau)
        cur.append(s.get("present_current"))
    k_pulse = M.stall_torque_nm * (800 / 128) / dxl.PWM_FULL  # N m per pulse of error
    assert abs(-q / dxl.RAD_PER_PULSE - load / k_pulse) <= 1.0
    # a P law on whole pulses holds the load between two steps of its output: on average, the load
    assert np.mean(cur[-5000:]) == pytest.approx(load / NMU, abs=1.0)


def test_current_mode_applies_the_goal_current_with_the_stated_constant_and_limit():
    assert M.torque_constant_nm_per_a == pytest.approx(10.6 / 4.4) and NMU == pytest.approx(0.0064807, rel=1e-4)
    bus = ServoBus(3, torque_max_nm=[6.0, 4.0, 2.0], endpoint=None)
    limits = [s.get("current_limit") for s in bus.servos]
    assert limits == [round(6.0 / NMU), round(4.0 / NMU), round(2.0 / NMU)] == [926, 617, 309]
    np.testing.assert_allclose(bus.current_limits_nm, [6.0, 4.0, 2.0], atol=NMU / 2)
    s = bus.servos[0]
    for u in (0, 1, -1, 123, -926, 926):
        _current_mode(s, u)
        assert s.torque_nm(0.0, 0.0) == pytest.approx(u * NMU, rel=1e-12, abs=1e-15)
    assert s.write(102, (927).to_bytes(2, "little", signed=True)) == dxl.ERR_DATA_LIMIT
    # at speed the duty saturates: i <= I_stall (1 - w / w_0) (motor at 12 V)
    w = 0.8 * M.no_load_speed_radps
    assert s.torque_nm(0.0, w) == pytest.approx(M.stall_torque_nm * 0.2, rel=1e-12)
    assert s.torque_nm(0.0, -w) == pytest.approx(926 * NMU, rel=1e-12)
    assert s.write(64, b"\x00") == 0 and s.torque_nm(0.0, 0.0) == 0.0


def test_present_current_is_the_applied_torque_quantized_and_lags_and_noise_as_stated():
    s = XServo(1, M)
    for tau in (0.0, 1.0, -2.345, 5.9):
        s.observe(0.0, 0.0, 0.0, tau)
        assert s.get("present_current") == round(tau / NMU)
    lag = XServo(1, M, effort=JointEffortSpec(lag_s=0.002))
    lag.observe(0.0, 0.0, 0.0, 0.0)
    for k in range(1, 10):
        lag.observe(k * 1e-3, 0.0, 0.0, 6.0)
        assert lag.get("present_current") == pytest.approx(6.0 / NMU * (1 - math.exp(-k * 1e-3 / 0.002)), abs=0.5)
    noisy = [XServo(1, M, effort=JointEffortSpec(noise_nm=0.013), rng=np.random.default_rng(s_)) for s_ in (3, 3, 4)]
    reads = []
    for n in noisy:
        r = []
        for k in range(20000):
            n.observe(k * 1e-3, 0.0, 0.0, 1.0)
            r.append(n.get("present_current"))
        reads.append(np.array(r))
    np.testing.assert_array_equal(reads[0], reads[1])
    assert not np.array_equal(reads[0], reads[2])
    y = reads[0] * NMU - 1.0
    assert abs(y.mean()) < 5e-4
    assert math.sqrt(y.var() - NMU ** 2 / 12) == pytest.approx(0.013, rel=0.05)  # noise + rounding
