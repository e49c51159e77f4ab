"""simulator.px4.port in its GCS role: PX4 SITL's GCS instance (px4-rc.mavlink, MAVLINK_MODE_NORMAL),
per-link signing, and the HEARTBEAT forwarding between a vehicle's two instances."""
from __future__ import annotations

import math
import socket

import pytest

from amlink import px4
from amlink.endpoint import UDP_OUT, Endpoint, parse_endpoint
from amlink.signing import gcs_key_from_passphrase
from amlink.wire import Decoder, Encoder, mav
from simulator.px4 import commander as cm
from simulator.px4.port import GCS_RATES_HZ, PortError, Px4Port, gcs_endpoint

from .test_port import REPORT, SYSID, Client, acks, counts, run_streams

KEY = gcs_key_from_passphrase("a passphrase for the test")


class Gcs(Client):
    """A ground station (255, 190) on its own loopback port, signing with `key` if given."""

    def __init__(self, key: bytes | None = None) -> None:
        super().__init__()
        self.enc = Encoder(255, 190, signing_key=key)
        self.dec = Decoder(None if key is None else {SYSID: key, **{s: key for s in range(256)}})


def gcs_port(client: Client, **kw) -> Px4Port:
    port = Px4Port(0, SYSID, cm.Commander(), parse_endpoint(f"udpout:127.0.0.1:{client.port}"), role="gcs",
                   local_port=0, **kw)
    port.open()
    return port


def arm(client: Client, port: Px4Port) -> list:
    client.send(port, mav.MAVLink_command_long_message(SYSID, 1, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0,
                                                        1, 0, 0, 0, 0, 0, 0))
    port.poll(0.0)
    return client.drain()


def test_default_gcs_endpoint_is_px4_sitls():
    """PX4 SITL instance i's GCS link: -u 18570+i, sending to 127.0.0.1:14550."""
    assert gcs_endpoint(0) == Endpoint(UDP_OUT, "127.0.0.1", 14550)
    assert px4.gcs_local_port(3) == 18573
    assert gcs_endpoint(1, "udpout:10.0.0.5:14560") == Endpoint(UDP_OUT, "10.0.0.5", 14560)
    for bad in ("udpin:0.0.0.0:14550", "tcp:127.0.0.1:5760", "udpout:host"):
        with pytest.raises(PortError, match="--gcs"):
            gcs_endpoint(0, bad)
    with pytest.raises(ValueError, match="role"):
        Px4Port(0, SYSID, cm.Commander(), role="telemetry")


def test_gcs_streams_at_the_normal_modes_rates_with_px4_sitls_raised_ones():
    """MAVLINK_MODE_NORMAL's defaults with px4-rc.mavlink's 50 Hz streams, over 2 s of autopilot
    time: what QGroundControl sees of a PX4 SITL vehicle; no onboard-only stream (ODOMETRY)."""
    client = Gcs()
    port = gcs_port(client, require_signed=False)
    try:
        n = counts(run_streams(port, 0.0, 2.0, client))
    finally:
        port.close()
        client.close()
    for name, rate in GCS_RATES_HZ.items():
        if name in ("STATUSTEXT", "ATTITUDE_TARGET"):
            continue  # nothing to say, nothing flown
        assert abs(n.get(name, 0) - 2.0 * rate) <= 1, (name, n.get(name), 2.0 * rate)
    assert not {"ODOMETRY", "HIGHRES_IMU", "TIMESYNC"} & set(n)


def test_global_position_is_the_local_one_about_px4_sitls_home():
    """GLOBAL_POSITION_INT: the NED position about SIM_GZ_HOME's lat/lon (1 m north is 1/111195
    deg), altitude AMSL, relative to home, velocity in cm/s NED, heading in cdeg."""
    client = Gcs()
    port = gcs_port(client, require_signed=False)
    try:
        got = run_streams(port, 0.0, 0.1, client)
    finally:
        port.close()
        client.close()
    g = [m for m in got if m.get_type() == "GLOBAL_POSITION_INT"][-1]
    # REPORT: ENU (1, 2, 3) m -> NED (2, 1, -3); at 47.4 deg a degree of longitude is cos(lat) shorter
    assert (g.lat * 1e-7 - 47.397742) * math.radians(6371000.0) == pytest.approx(2.0, abs=0.02)
    lon_m = (g.lon * 1e-7 - 8.545594) * math.radians(6371000.0) * math.cos(math.radians(47.397742))
    assert lon_m == pytest.approx(1.0, abs=0.02)
    assert g.alt == 488000 + 3000 and (g.vx, g.vy, g.vz) == (20, 10, -30)
    assert g.hdg == 9000  # ENU yaw 0 (facing east) is a heading of 90 deg
    # home is where the vehicle stood (it is on the ground, disarmed): relative altitude 0
    assert g.relative_alt == 0


def test_a_signed_gcs_port_reads_only_frames_signed_with_its_key():
    """require_signed with a key: an unsigned ARM and one signed with another key are dropped and
    counted; the signed one is executed and its ACK comes back signed."""
    plain, stranger, gcs = Gcs(), Gcs(gcs_key_from_passphrase("not the key")), Gcs(KEY)
    port = gcs_port(gcs, require_signed=True, signing_key=KEY)
    try:  # the GCS is heard first: the partner (the first sender, whatever it sends, as PX4's)
        gcs.send(port, mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        port.poll(0.0)
        assert acks(arm(plain, port)) == [] and not port.commander.armed
        assert acks(arm(stranger, port)) == [] and not port.commander.armed
        assert port.stats.unsigned == 1 and port.stats.bad_signature == 1
        got = arm(gcs, port)
        assert acks(got) == [(mav.MAV_CMD_COMPONENT_ARM_DISARM, cm.ACCEPTED)] and port.commander.armed
        gcs.sock.settimeout(0.2)
        port.publish(0.0, REPORT)
        data, _ = gcs.sock.recvfrom(65536)
        assert data[2] & 0x01  # MAVLink 2 incompat flag: signed
    finally:
        port.close()
        for c in (plain, stranger, gcs):
            c.close()


def test_signing_on_without_a_key_is_telemetry_only_and_off_takes_anything():
    keyless = Gcs(KEY)
    port = gcs_port(keyless, require_signed=True)
    try:
        assert acks(arm(keyless, port)) == [] and not port.commander.armed
        assert port.stats.unknown_sysid + port.stats.bad_signature >= 1
        keyless.dec = Decoder(None)  # what it sends is unsigned (it has no key to sign with)
        n = counts(run_streams(port, 0.0, 1.1, keyless))
        assert n.get("HEARTBEAT", 0) >= 1  # the streams still go out
    finally:
        port.close()
        keyless.close()
    for client in (Gcs(), Gcs(KEY)):  # signing off: unsigned and signed frames are both read
        client.dec = Decoder(None)  # the port answers unsigned
        port = gcs_port(client, require_signed=False)
        try:
            assert acks(arm(client, port)) == [(mav.MAV_CMD_COMPONENT_ARM_DISARM, cm.ACCEPTED)]
        finally:
            port.close()
            client.close()


def test_the_companions_heartbeat_reaches_the_gcs_as_px4_forwards_it():
    """Mavlink::forward_message: a HEARTBEAT received on the onboard instance goes out on the GCS
    one as from its source (SYSID, 191), signed when that link signs; the autopilot's own are
    not forwarded."""
    companion, gcs = Client(), Gcs(KEY)
    c = cm.Commander()
    onboard = Px4Port(0, SYSID, c, parse_endpoint(f"udpout:127.0.0.1:{companion.port}"))
    g = Px4Port(0, SYSID, c, parse_endpoint(f"udpout:127.0.0.1:{gcs.port}"), role="gcs", local_port=0,
                require_signed=True, signing_key=KEY)
    onboard.forward, g.forward = g.forwarded, onboard.forwarded
    onboard.open()
    g.open()
    try:
        companion.send(onboard, mav.MAVLink_heartbeat_message(mav.MAV_TYPE_ONBOARD_CONTROLLER,
                                                              mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        onboard.poll(0.0)
        got = gcs.drain()
        hb = [m for m in got if m.get_type() == "HEARTBEAT"]
        assert [(m.get_srcSystem(), m.get_srcComponent(), m.type) for m in hb] == [
            (SYSID, 191, mav.MAV_TYPE_ONBOARD_CONTROLLER)]
        assert g.stats.tx.get("HEARTBEAT (forwarded)") == 1
        # the GCS's own HEARTBEAT goes the other way, to the companion
        gcs.send(g, mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        g.poll(0.0)
        assert [(m.get_srcSystem(), m.get_srcComponent()) for m in companion.drain()
                if m.get_type() == "HEARTBEAT"] == [(255, 190)]
    finally:
        onboard.close()
        g.close()
        companion.close()
        gcs.close()


def test_a_keyed_onboard_port_and_the_companions_link_sign_each_other():
    """simulator --onboard-key-file and companion --fc-key-file: the companion's Px4Link, signing
    with the port's key, is heard (its setpoint reaches the commander) and hears the autopilot;
    an unsigned link's setpoint is dropped and counted, and it hears nothing it can read."""
    from amlink.px4link import Px4Link
    c = cm.Commander()
    port = Px4Port(0, SYSID, c, parse_endpoint("udpin:127.0.0.1:0"), signing_key=KEY, require_signed=True)
    port.open()
    target = f"udpout:127.0.0.1:{port.local_address[1]}"
    try:
        with Px4Link(SYSID, target, signing_key=KEY, timesync_rate_hz=0) as link:
            link.send_heartbeat()
            link.send_attitude_target((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)
            port.poll(0.0)
            assert port.stats.setpoints == 1 and port.stats.rx["HEARTBEAT"] == 1
            port.publish(0.0, REPORT)
            link.poll(0.2)
            assert link.autopilot_heard
        with Px4Link(SYSID, target, timesync_rate_hz=0) as plain:
            plain.send_attitude_target((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)
            port.poll(0.0)
            assert port.stats.setpoints == 1 and port.stats.unsigned >= 1
    finally:
        port.close()
