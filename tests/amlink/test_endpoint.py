"""Endpoint strings: mavutil's forms parse to what they mean; anything else is refused with the list."""

from __future__ import annotations

import pytest

from amlink.endpoint import (ACCEPTED_FORMS, DEFAULT_BAUD, TCP_IN, UDP_IN, Endpoint, EndpointError, listen_address,
                             parse_endpoint)


@pytest.mark.parametrize("text,kind,host,port", [
    ("udpin:0.0.0.0:14550", "udpin", "0.0.0.0", 14550),
    ("udp:127.0.0.1:14550", "udpin", "127.0.0.1", 14550),  # mavutil: udp: listens
    ("udpout:10.0.0.2:14551", "udpout", "10.0.0.2", 14551),
    ("tcp:localhost:5760", "tcp", "localhost", 5760),
    ("tcpin:0.0.0.0:0", "tcpin", "0.0.0.0", 0),
    ("udpin:[::1]:14550", "udpin", "::1", 14550),
    ("tcp:[fe80::1%eth0]:5760", "tcp", "fe80::1%eth0", 5760),
    ("UDPOUT:sim.local:14550", "udpout", "sim.local", 14550),
])  # fmt: skip
def test_network_forms(text, kind, host, port):
    ep = parse_endpoint(text)
    assert (ep.kind, ep.host, ep.port) == (kind, host, port)
    assert parse_endpoint(str(ep)) == Endpoint(kind, host, port)  # the canonical form reads back


@pytest.mark.parametrize("text,device,baud", [
    ("/dev/ttyUSB0", "/dev/ttyUSB0", DEFAULT_BAUD),
    ("/dev/ttyUSB0:57600", "/dev/ttyUSB0", 57600),
    ("/dev/ttyACM0,921600", "/dev/ttyACM0", 921600),
    ("/dev/serial/by-id/usb-Hex_ProfiCNC_CubeOrange-if00:115200", "/dev/serial/by-id/usb-Hex_ProfiCNC_CubeOrange-if00",
     115200),
    ("COM3,57600", "COM3", 57600),
])  # fmt: skip
def test_serial_forms(text, device, baud):
    ep = parse_endpoint(text)
    assert (ep.kind, ep.device, ep.baud) == ("serial", device, baud)
    assert ep.stream and not ep.listens


def test_udp_is_an_alias_of_udpin_and_says_so():
    assert parse_endpoint("udp:127.0.0.1:1").alias == "udp"
    assert parse_endpoint("udpin:127.0.0.1:1").alias == ""


@pytest.mark.parametrize("text,why", [
    ("", "empty"),
    ("127.0.0.1", "serial device"),
    ("127.0.0.1:14550", "serial device"),
    ("udp:127.0.0.1", "HOST:PORT"),
    ("udp::14550", "no host"),
    ("udp:host:port", "not a number"),
    ("udp:h:70000", "not a number"),
    ("udpout:127.0.0.1:0", "port 0"),
    ("tcp:::1:5760", "brackets"),
    ("tcp:[::1]5760", "[ADDRESS]:PORT"),
    ("serial:/dev/ttyUSB0", "unknown scheme"),
    ("ws:host:1", "unknown scheme"),
    ("/dev/ttyUSB0:12345", "baud rate 12345"),
    ("/dev/ttyUSB0:fast", "serial device"),
])  # fmt: skip
def test_malformed_strings_name_the_problem_and_list_the_accepted_forms(text, why):
    with pytest.raises(EndpointError) as err:
        parse_endpoint(text)
    assert why in str(err.value) and ACCEPTED_FORMS in str(err.value)
    assert isinstance(err.value, ValueError)


def test_a_device_servers_listen_address_names_the_server_and_the_endpoint():
    assert listen_address("udpin:127.0.0.1:49152", UDP_IN, "Net F/T") == ("127.0.0.1", 49152)
    assert listen_address("tcpin:0.0.0.0:0", TCP_IN, "servo bus") == ("0.0.0.0", 0)
    with pytest.raises(ValueError, match=r"servo bus endpoint 'udpin:127.0.0.1:7200': must be tcpin:HOST:PORT"):
        listen_address("udpin:127.0.0.1:7200", TCP_IN, "servo bus")
    with pytest.raises(ValueError, match=r"^mocap stream: ") as e:
        listen_address("udpin:127.0.0.1:notaport", UDP_IN, "mocap stream")
    assert not isinstance(e.value, EndpointError)  # the server's ValueError, naming it

