"""The free-running simulator (`simulator --realtime`) flown by stock PX4 tooling, end to end.

1. A MAVSDK offboard program, written as PX4's offboard docs show it (first setpoint,
   offboard.start(), action.arm(), then attitude setpoints at 20 Hz with its own altitude loop),
   climbs vehicle 0 of a copy of two_am_comp_attitude to 1 m and hovers; then it stops
   streaming, and the vehicle leaves OFFBOARD COM_OF_LOSS_T after the last setpoint.
   MAVSDK >= 4 (pip `mavsdk`) is the native binding: it loads its bundled libcmavsdk.so through
   ctypes in this process (mavsdk/cmavsdk_loader.py); there is no mavsdk_server to start, and
   its API is `mavsdk.asyncio.Mavsdk` + plugins (the gRPC `System()` of mavsdk < 4 is gone).
2. Raw pymavlink on vehicle 1: COMMAND_ACK codes as PX4 gives them, and malformed or oversized
   datagrams counted, not fatal.
Each test runs its own simulator on free loopback ports (not PX4 SITL's 14540..: other runs
may use those), in real time, and stops it with SIGINT (the outcome is written either way).
"""
from __future__ import annotations

import asyncio
import math
import time

import pytest

from tests.ports import free_udp_ports
from tests.sitl.runner import FreeSim

mavsdk = pytest.importorskip("mavsdk", minversion="4", reason="needs MAVSDK >= 4 (pip install 'mavsdk>=4')")

from amlink import px4  # noqa: E402
from amlink.wire import Encoder, mav  # noqa: E402  (pymavlink's generated messages, the project's dialect)
from simulator.px4.commander import NavState, custom_mode_of  # noqa: E402

COM_OF_LOSS_T = 1.0  # the vehicle's (am3dof.toml keeps PX4's default)
HOLD_MODE = custom_mode_of(NavState.AUTO_LOITER)
OFFBOARD_MODE = custom_mode_of(NavState.OFFBOARD)


async def fly(port: int) -> dict:
    """The offboard program (MAVSDK's asyncio API); what it saw."""
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.offboard import Attitude, OffboardAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    seen: dict = {}
    config = Configuration.create_with_component_type(ComponentType.COMPANION_COMPUTER)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        drone = await sdk.first_autopilot(timeout_s=25.0)
        assert drone is not None, "no autopilot heartbeat within 25 s"
        seen["sysid"] = await drone.get_system_id()
        offboard, action, telemetry = OffboardAsync(drone), ActionAsync(drone), TelemetryAsync(drone)
        while True:  # LOCAL_POSITION_NED has arrived
            pv = await telemetry.position_velocity_ned()
            if math.isfinite(pv.position.down_m):
                break
            await asyncio.sleep(0.05)
        seen["down_start_m"] = pv.position.down_m
        yaw_deg = 90.0  # vehicle 0 faces +x (east)
        # PX4 docs' order: a setpoint first, then offboard.start(), then arm (each raises unless ACCEPTED)
        await offboard.set_attitude(Attitude(0.0, 0.0, yaw_deg, 0.0))
        await offboard.start()
        await action.arm()
        hover = 1.80 * 9.81 / 48.0  # am3dof: m g / (4 x 12 N)
        down_ref = -1.0
        t_end = time.monotonic() + 7.0
        while time.monotonic() < t_end:
            pv = await telemetry.position_velocity_ned()
            thrust = hover + 0.15 * (pv.position.down_m - down_ref) + 0.12 * pv.velocity.down_m_s
            await offboard.set_attitude(Attitude(0.0, 0.0, yaw_deg, min(max(thrust, 0.0), 0.8)))
            await asyncio.sleep(0.05)
        seen["down_hover_m"] = (await telemetry.position_velocity_ned()).position.down_m
        seen["offboard_active"] = await offboard.is_active()
    seen["stopped_at"] = time.monotonic()  # MAVSDK destroyed: no more setpoints
    return seen


def heartbeats(port: int, sysid: int, seconds: float) -> list[tuple[float, int]]:
    """(monotonic time, custom_mode) of the HEARTBEATs `sysid` sends to `port` for `seconds`."""
    from pymavlink import mavutil
    m = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
    out, t_end = [], time.monotonic() + seconds
    try:
        while time.monotonic() < t_end:
            hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
            if hb is not None and hb.get_srcSystem() == sysid:
                out.append((time.monotonic(), hb.custom_mode))
    finally:
        m.close()
    return out


def test_mavsdk_offboard_flight_and_failover(tmp_path):
    p0, p1 = free_udp_ports(2)
    sim = FreeSim(tmp_path, [p0, p1])
    try:
        try:
            seen = asyncio.run(asyncio.wait_for(fly(p0), timeout=30.0))
        except asyncio.TimeoutError:
            raise AssertionError("the MAVSDK program did not finish within 30 s; simulator:\n"
                                 + "".join(sim.lines)) from None
        beats = heartbeats(p0, seen["sysid"], 3.5)
    finally:
        code, err, outcome = sim.stop()
    assert outcome, f"no outcome.json; simulator stderr:\n{err}"
    assert seen["sysid"] == 4 and seen["offboard_active"]
    assert seen["down_start_m"] > -0.15  # it started on the ground
    assert seen["down_hover_m"] == pytest.approx(-1.0, abs=0.1), seen
    # after the stream stopped: HOLD (COM_OF_LOSS_T, then COM_OBL_RC_ACT after the hold)
    modes = [m for _, m in beats]
    assert modes and modes[-1] == HOLD_MODE, (modes, err[-2000:])
    v = outcome["vehicles"]["4"]
    events = {e["event"]: e for e in v["events"]}
    assert events["armed"]["mode"] == "OFFBOARD" and v["offboard_engaged_s"] is not None
    fs = events["failsafe"]
    assert fs["t_s"] - fs["last_setpoint_s"] == pytest.approx(COM_OF_LOSS_T, abs=0.0011)  # one physics step
    assert [(e["from"], e["to"]) for e in v["events"] if e["event"] == "mode"][-1] == ("OFFBOARD", "HOLD")
    link = v["link"]
    assert link["rx"]["SET_ATTITUDE_TARGET"] > 100 and link["rx"]["COMMAND_LONG"] >= 2
    assert link["tx"]["COMMAND_ACK"] >= 2 and link["handler_errors"] == link["bad_frames"] == 0
    assert outcome["mission_t0_s"] == pytest.approx(v["offboard_engaged_s"] + 3.0)
    assert outcome["speed"] == 1.0 and outcome["timing"]["steps"] > 0
    assert len(outcome["ports"]) == 2 and f"127.0.0.1:{p0}" in outcome["ports"][0]
    assert code == 130 and outcome["status"].startswith("interrupted")


def test_raw_mavlink_acks_and_bad_input(tmp_path):
    from pymavlink import mavutil
    p0, p1 = free_udp_ports(2)
    sim = FreeSim(tmp_path, [p0, p1])
    m = mavutil.mavlink_connection(f"udpin:127.0.0.1:{p1}", source_system=5, source_component=px4.ONBOARD_COMPID)
    try:
        hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=25)
        assert hb is not None and hb.get_srcSystem() == 5 and hb.custom_mode == HOLD_MODE

        enc = Encoder(5, px4.ONBOARD_COMPID)  # MAVLink 2 (pymavlink's mavutil sends MAVLink 1 unless MAVLINK20 is set)

        def command(cmd: int, *params: float) -> int:
            p = (list(params) + [0.0] * 7)[:7]
            m.write(enc.pack([mav.MAVLink_command_long_message(5, 1, cmd, 0, *p)]))
            t_end = time.monotonic() + 3.0
            while time.monotonic() < t_end:
                ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=1.0)
                if ack is not None and ack.command == cmd:
                    return ack.result
            raise AssertionError(f"no COMMAND_ACK for {cmd}")

        offboard = (mav.MAV_CMD_DO_SET_MODE, 1.0, float(px4.MAIN_OFFBOARD), 0.0)
        assert command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == mav.MAV_RESULT_ACCEPTED  # in Hold, on the ground
        assert command(*offboard) == mav.MAV_RESULT_TEMPORARILY_REJECTED  # armed, no setpoint stream
        assert command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0.0) == mav.MAV_RESULT_ACCEPTED  # landed
        assert command(*offboard) == mav.MAV_RESULT_ACCEPTED  # disarmed: any mode (UserModeIntention)
        assert command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1.0) == mav.MAV_RESULT_TEMPORARILY_REJECTED  # no signal
        # bad input, from the partner's own socket
        m.write(b"\x00not mavlink at all" * 8)
        m.write(b"\xfd" * 9000)  # longer than PX4's 8000-byte buffer
        good = enc.pack([mav.MAVLink_command_long_message(5, 1, mav.MAV_CMD_REQUEST_MESSAGE, 0, 242, 0, 0, 0, 0, 0, 0)])
        m.write(good[:-3])  # cut short
        m.write(good[:-2] + bytes([good[-2] ^ 0xFF, good[-1]]))  # bad CRC
        assert command(mav.MAV_CMD_REQUEST_MESSAGE, 242) == mav.MAV_RESULT_ACCEPTED  # still serving
        assert m.recv_match(type="HOME_POSITION", blocking=True, timeout=3) is not None
    finally:
        m.close()
        code, err, outcome = sim.stop()
    assert outcome, f"no outcome.json; simulator stderr:\n{err}"
    link = outcome["vehicles"]["5"]["link"]
    assert link["oversized"] == 1 and link["junk_bytes"] > 0 and link["handler_errors"] == 0
    events = [e["event"] for e in outcome["vehicles"]["5"]["events"]]
    assert events.count("armed") == 1 and "arming denied" in events
    assert outcome["vehicles"]["4"]["offboard_engaged_s"] is None
    assert code == 130


async def gcs_view(port: int) -> dict:
    """MAVSDK as a ground station on the GCS port: both vehicles, vehicle 4's health, arm and disarm."""
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

    seen: dict = {}
    async with Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION)) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        t_end = time.monotonic() + 25.0
        drones = {}
        while len(drones) < 2 and time.monotonic() < t_end:
            for d in await sdk.get_systems():
                drones[await d.get_system_id()] = d
            await asyncio.sleep(0.2)
        seen["sysids"] = sorted(drones)
        drone = drones[4]
        telemetry, action = TelemetryAsync(drone), ActionAsync(drone)
        await asyncio.sleep(2.5)  # HOME_POSITION comes at 0.5 Hz
        seen["health"] = await telemetry.health()
        seen["position"] = await telemetry.position()
        await action.arm()  # raises unless ACCEPTED
        t_end = time.monotonic() + 2.5  # the armed flag comes with the next HEARTBEAT (1 Hz)
        while not (armed := await telemetry.armed()) and time.monotonic() < t_end:
            await asyncio.sleep(0.1)
        seen["armed"] = armed
        await action.disarm()
    return seen


def test_the_gcs_port_is_px4_sitls_and_signing_is_per_link(tmp_path):
    """Each vehicle's GCS instance (simulator.px4.port, role gcs): with --gcs-unsigned, MAVSDK as a
    ground station sees both vehicles, their health as a PX4's indoors, and arms and disarms;
    a companion's HEARTBEAT on the onboard port reaches the GCS (PX4's forwarding). With a
    --gcs-key-file the same port executes only commands signed with it."""
    from pymavlink import mavutil
    p0, p1, pg = free_udp_ports(3)
    sim = FreeSim(tmp_path, [p0, p1], gcs=("--gcs", f"udpout:127.0.0.1:{pg}", "--gcs-unsigned", "--instance", "50"))
    companion = mavutil.mavlink_connection(f"udpin:127.0.0.1:{p1}", source_system=5,
                                           source_component=px4.ONBOARD_COMPID)
    try:
        assert companion.recv_match(type="HEARTBEAT", blocking=True, timeout=25) is not None
        companion.write(Encoder(5, px4.ONBOARD_COMPID).pack([mav.MAVLink_heartbeat_message(
            mav.MAV_TYPE_ONBOARD_CONTROLLER, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)]))
        try:
            seen = asyncio.run(asyncio.wait_for(gcs_view(pg), timeout=40.0))
        except asyncio.TimeoutError:
            raise AssertionError("MAVSDK did not finish within 40 s; simulator:\n" + "".join(sim.lines)) from None
    finally:
        companion.close()
        code, err, outcome = sim.stop()
    assert "--gcs-unsigned" in err and "UNSIGNED" in err
    assert seen["sysids"] == [4, 5]
    h = seen["health"]
    assert h.is_gyrometer_calibration_ok and h.is_accelerometer_calibration_ok and h.is_armable, h
    assert h.is_home_position_ok and h.is_local_position_ok, h
    assert seen["position"].latitude_deg == pytest.approx(47.397742, abs=1e-3)
    assert seen["armed"]
    v4 = outcome["vehicles"]["4"]
    assert [e["event"] for e in v4["events"]].count("armed") == 1 and "disarmed" in [e["event"] for e in v4["events"]]
    g5 = outcome["vehicles"]["5"]["gcs"]
    assert g5["port"].startswith("udp 127.0.0.1:18621") and g5["signing"] is False
    assert g5["link"]["tx"].get("HEARTBEAT (forwarded)", 0) >= 1  # the companion's, to the GCS
    assert outcome["gcs_ports"] and code == 130


def test_a_signed_gcs_port_takes_only_signed_commands(tmp_path):
    from amlink.signing import gcs_key_from_passphrase
    from pymavlink import mavutil
    p0, p1, pg = free_udp_ports(3)
    key_file = tmp_path / "gcs.key"
    key_file.write_text("a passphrase for MAVProxy\n")
    key_file.chmod(0o600)
    sim = FreeSim(tmp_path, [p0, p1], gcs=("--gcs", f"udpout:127.0.0.1:{pg}", "--gcs-key-file", str(key_file),
                                           "--instance", "50"))
    m = mavutil.mavlink_connection(f"udpin:127.0.0.1:{pg}", source_system=255, source_component=190)
    key = gcs_key_from_passphrase("a passphrase for MAVProxy")

    def arm(enc: Encoder, sysid: int) -> int | None:
        m.write(enc.pack([mav.MAVLink_command_long_message(sysid, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                           1, 0, 0, 0, 0, 0, 0)]))
        t_end = time.monotonic() + 2.0
        while time.monotonic() < t_end:
            ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.5)
            if ack is not None and ack.get_srcSystem() == sysid:
                return ack.result
        return None

    try:
        hb = m.recv_match(type="HEARTBEAT", blocking=True, timeout=25)
        assert hb is not None
        assert arm(Encoder(255, 190), 4) is None  # unsigned: dropped, no answer
        assert arm(Encoder(255, 190, signing_key=key), 5) == mav.MAV_RESULT_ACCEPTED
    finally:
        m.close()
        code, err, outcome = sim.stop()
    assert outcome, f"no outcome.json; simulator stderr:\n{err}"
    assert outcome["vehicles"]["4"]["gcs"]["link"]["unsigned"] >= 1
    assert outcome["vehicles"]["4"]["armed_at_end"] is False and outcome["vehicles"]["5"]["armed_at_end"] is True
    assert outcome["vehicles"]["5"]["gcs"]["signing"] is True
