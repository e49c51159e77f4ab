"""The GCS link with pymavlink's mavutil as the ground station: telemetry of every vehicle,
companion HEARTBEATs passed on, signed commands only, every transport, a GCS that never reads."""
from __future__ import annotations

import socket
import time
from collections import Counter

import pytest
from pymavlink import mavutil

from amlink.codec import mav
from amlink.endpoint import parse_endpoint
from amlink.signing import gcs_key_from_passphrase
from simulator.fcstate import FcMode, FleetSnapshot, VehicleSnapshot
from simulator.gcs_link import GcsLink

PASSPHRASE = "a-test-passphrase"
KEY = gcs_key_from_passphrase(PASSPHRASE)


def _snapshot(t: float, mode=FcMode.OFFBOARD) -> FleetSnapshot:
    return FleetSnapshot(time_s=t, phase="approach", vehicles=tuple(
        VehicleSnapshot(sysid=s, p_WB=(0.1 * s, 0.0, 1.0 + t), quat_WB_wxyz=(1.0, 0.0, 0.0, 0.0), v_B=(0.0, 0.0, 1.0),
                        w_B=(0.0, 0.0, 0.0), mode=mode, armed=True, failsafe=False) for s in (4, 5)))


def _gcs(device: str, key: bytes | None = None):
    conn = mavutil.mavlink_connection(device, source_system=255, source_component=190, dialect="common")
    if key is not None:
        conn.setup_signing(key, sign_outgoing=True)
    return conn


def _udpin_gcs(key: bytes | None = None):
    conn = _gcs("udpin:127.0.0.1:0", key)
    return conn, conn.port.getsockname()[1]


def _collect(conn, seconds: float, feed=None, until=None) -> list:
    """Messages the GCS receives within ``seconds`` (or until ``until(messages)``); ``feed(t)``
    is called in between."""
    out, t0 = [], time.monotonic()
    while (t := time.monotonic() - t0) < seconds and not (until is not None and until(out)):
        if feed is not None:
            feed(t)
        msg = conn.recv_match(blocking=True, timeout=0.02)
        if msg is not None and msg.get_type() != "BAD_DATA":
            out.append(msg)
    return out


def _both_heard(msgs) -> bool:
    return {(m.get_srcSystem(), m.get_type()) for m in msgs} >= {(4, "HEARTBEAT"), (5, "HEARTBEAT")}


@pytest.fixture
def opened(monkeypatch):
    # a GCS that signs speaks MAVLink 2 from the start (mavutil would start in MAVLink 1, switch
    # on the first MAVLink 2 frame it hears and lose its signing set-up doing so)
    monkeypatch.setenv("MAVLINK20", "1")
    links = []

    def open_link(endpoint, **kw) -> GcsLink:
        link = GcsLink(parse_endpoint(endpoint) if endpoint else None, (4, 5), **kw)
        link.open(_snapshot(0.0, FcMode.STANDBY))
        links.append(link)
        return link

    yield open_link
    for link in links:
        link.close()


def test_every_vehicle_reports_as_its_autopilot_and_companions_are_passed_on(opened, tmp_path):
    gcs, port = _udpin_gcs()
    link = opened(f"udpout:127.0.0.1:{port}", tlog=tmp_path / "gcs.tlog")
    companion_beat = mav.MAVLink_heartbeat_message(mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID, 0, 0,
                                                   mav.MAV_STATE_ACTIVE, 3)
    link.forward_heartbeat(4, mav.MAV_COMP_ID_ONBOARD_COMPUTER, companion_beat)
    link.statustext(5, mav.MAV_SEVERITY_CRITICAL, "failsafe: companion lost, holding position")
    msgs = _collect(gcs, 1.3, feed=lambda t: link.publish(_snapshot(t)))  # a new snapshot on every look
    n = Counter((m.get_srcSystem(), m.get_srcComponent(), m.get_type()) for m in msgs)
    for s in (4, 5):
        assert n[(s, 1, "HEARTBEAT")] >= 2 and n[(s, 1, "SYS_STATUS")] >= 2  # 1 Hz
        assert n[(s, 1, "ATTITUDE")] >= 13 and n[(s, 1, "LOCAL_POSITION_NED")] >= 13  # >= 10 Hz
    assert n[(4, 191, "HEARTBEAT")] == 1
    assert [m.text for m in msgs if m.get_type() == "STATUSTEXT"] == ["failsafe: companion lost, holding position"]
    beats = [m for m in msgs if m.get_type() == "HEARTBEAT" and m.get_srcComponent() == 1]
    assert mavutil.mode_string_v10(beats[-1]) == "OFFBOARD"  # from the newest snapshot
    pos = [m for m in msgs if m.get_type() == "LOCAL_POSITION_NED" and m.get_srcSystem() == 5][-1]
    assert pos.x == pytest.approx(0.0) and pos.y == pytest.approx(0.5) and pos.vz == pytest.approx(-1.0)
    link.close()
    log = mavutil.mavlink_connection(str(tmp_path / "gcs.tlog"), dialect="common")
    logged = Counter()
    while (m := log.recv_match()) is not None:
        logged[(m.get_srcSystem(), m.get_type())] += 1
    assert logged[(4, "HEARTBEAT")] == n[(4, 1, "HEARTBEAT")] + 1  # the companion's too
    assert logged[(5, "ATTITUDE")] >= n[(5, 1, "ATTITUDE")]


def test_only_commands_signed_with_the_gcs_key_are_executed(opened):
    gcs, port = _udpin_gcs(KEY)
    link = opened(f"udpout:127.0.0.1:{port}", key=KEY)
    assert _both_heard(_collect(gcs, 2.0, until=_both_heard))  # signed with the key: mavutil verified them
    gcs.mav.command_long_send(5, 1, mav.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0)
    cmds = []
    for _ in range(50):
        cmds += link.commands()
        if cmds:
            break
        time.sleep(0.02)
    assert [(c.command, c.target_system, c.source_system, c.source_component) for c in cmds] == [
        (mav.MAV_CMD_NAV_LAND, 5, 255, 190)]
    link.acknowledge(cmds[0], 5, mav.MAV_RESULT_ACCEPTED)
    ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=2.0)
    assert (ack.get_srcSystem(), ack.command, ack.result, ack.target_system) == (5, 21, mav.MAV_RESULT_ACCEPTED, 255)

    reply_to = gcs.port.getsockname()[1]
    for key, counter in ((None, "unsigned"), (gcs_key_from_passphrase("wrong"), "bad_signature")):
        intruder = _gcs(f"udpout:127.0.0.1:{link.local_address[1]}", key)
        intruder.mav.command_long_send(4, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 21196, 0, 0, 0, 0, 0)
        time.sleep(0.3)
        assert link.commands() == [] and getattr(link.link_stats, counter) == 1
        intruder.close()
    from pymavlink.dialects.v10 import common as v1  # MAVLink 1 cannot be signed at all

    old = v1.MAVLink(None, srcSystem=254, srcComponent=190)
    frame = old.command_long_encode(4, 1, mav.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0).pack(old)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(frame, ("127.0.0.1", link.local_address[1]))
    time.sleep(0.3)
    assert link.commands() == [] and link.link_stats.unsigned == 2
    assert reply_to


def test_a_gcs_that_listens_for_us_to_speak_first_and_one_that_speaks_first(opened):
    link = opened("udpin:127.0.0.1:0")  # the GCS sends first (MAVProxy --master=udpout:...)
    gcs = _gcs(f"udpout:127.0.0.1:{link.local_address[1]}")
    msgs = _collect(gcs, 2.0, feed=lambda t: gcs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID,
                                                                    0, 0, 0) if int(t * 10) % 5 == 0 else None,
                    until=_both_heard)
    assert _both_heard(msgs)
    assert link.link_stats.ignored >= 1  # its HEARTBEATs: heard, not commands


def test_tcp_gcs_and_one_that_never_reads_cost_nothing(opened):
    link = opened("tcpin:127.0.0.1:0")
    port = link.local_address[1]
    stuck = socket.create_connection(("127.0.0.1", port))  # connected, never reads
    stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    gcs = _gcs(f"tcp:127.0.0.1:{port}")
    t0 = time.monotonic()
    for i in range(2000):  # far more than a run says: the main loop's calls return at once
        link.statustext(4, mav.MAV_SEVERITY_INFO, f"text {i} " + "x" * 40)
        link.publish(_snapshot(i * 1e-3))
    assert time.monotonic() - t0 < 0.5
    assert _both_heard(_collect(gcs, 6.0, until=_both_heard))  # after the texts it is still reading
    t0 = time.monotonic()
    link.close()
    assert time.monotonic() - t0 < 1.5
    stuck.close()


def test_the_link_sleeps_while_there_is_nothing_new_to_send(opened):
    """The simulator runs on two cores with its companions: a link that polled would take one."""
    import resource

    gcs, port = _udpin_gcs()
    link = opened(f"udpout:127.0.0.1:{port}")
    cpu0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.monotonic()
    time.sleep(1.0)  # HEARTBEATs go out; no new snapshot
    cpu1 = resource.getrusage(resource.RUSAGE_SELF)
    used = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    assert used < 0.05 * (time.monotonic() - t0), f"{used:.3f} s of CPU in a second of waiting"
    assert _both_heard(_collect(gcs, 1.5, until=_both_heard))


def test_without_a_gcs_endpoint_the_tlog_is_written_all_the_same(opened, tmp_path):
    link = opened(None, tlog=tmp_path / "gcs.tlog")
    time.sleep(0.3)
    link.publish(_snapshot(0.1))
    time.sleep(0.2)
    link.close()
    log = mavutil.mavlink_connection(str(tmp_path / "gcs.tlog"), dialect="common")
    types = Counter()
    while (m := log.recv_match()) is not None:
        types[(m.get_srcSystem(), m.get_type())] += 1
    assert types[(4, "HEARTBEAT")] >= 1 and types[(5, "ATTITUDE")] >= 1
