"""MAVLink endpoint strings in pymavlink's ``mavutil`` conventions (pure: no I/O).

Every ``--bind``, ``--sim`` and ``--gcs`` option takes one of these forms:

* ``udpin:HOST:PORT`` -- listen for UDP datagrams on HOST:PORT (``udp:HOST:PORT`` is the
  same, as in mavutil); the far end's address is learned from what it sends;
* ``udpout:HOST:PORT`` -- send UDP datagrams to HOST:PORT (from a free local port);
* ``tcpin:HOST:PORT`` -- listen for TCP connections;
* ``tcp:HOST:PORT`` -- connect over TCP;
* ``DEVICE``, ``DEVICE:BAUD`` or ``DEVICE,BAUD`` -- a serial port (an absolute path such as
  ``/dev/ttyUSB0``, or ``COMn``), 115200 baud unless given.

HOST is a name, an IPv4 address or, beyond mavutil (which has no IPv6), a bracketed IPv6
address (``udpin:[::1]:14550``).  PORT 0 (listening forms only) picks a free port.

One exception, kept for compatibility: the companion's ``--sim udp:HOST:PORT`` has always
meant *send to* the simulator; it is read as ``udpout:`` and the companion warns
(:attr:`Endpoint.alias` says which scheme was written).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

UDP_IN, UDP_OUT, TCP_IN, TCP_OUT, SERIAL = "udpin", "udpout", "tcpin", "tcp", "serial"
SIM_BIND = "udpin:127.0.0.1:14550"  # the simulator's default --bind
COMPANION_SIM = "udpout:127.0.0.1:14550"  # the companion's default --sim
DEFAULT_GCS = "udpout:127.0.0.1:14551"  # the simulator's default --gcs: not the companions' 14550
DEFAULT_BAUD = 115200
# the termios rates Linux offers; a serial endpoint with another rate is refused when parsed
BAUD_RATES = (1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600,
              1000000, 1152000, 1500000, 2000000, 2500000, 3000000, 3500000, 4000000)
_SCHEMES = {"udp": UDP_IN, "udpin": UDP_IN, "udpout": UDP_OUT, "tcp": TCP_OUT, "tcpin": TCP_IN}
_DEVICE = re.compile(r"^(?P<dev>/[^:,]+|COM\d+)(?:[:,](?P<baud>\d+))?$", re.IGNORECASE)

ACCEPTED_FORMS = """accepted forms (mavutil's):
  udpin:HOST:PORT    listen for UDP (udp:HOST:PORT is the same)
  udpout:HOST:PORT   send UDP to HOST:PORT
  tcpin:HOST:PORT    listen for TCP connections
  tcp:HOST:PORT      connect over TCP
  DEVICE[:BAUD] or DEVICE,BAUD   serial port, e.g. /dev/ttyUSB0:921600 (default 115200 baud)
  HOST: a name, an IPv4 address or a bracketed IPv6 address such as [::1]"""

# a companion's --sim: udp:HOST:PORT has always meant "send to the simulator" there
COMPANION_SIM_FORMS = ACCEPTED_FORMS.replace(
    "  udpin:HOST:PORT    listen for UDP (udp:HOST:PORT is the same)\n",
    "  udpin:HOST:PORT    listen for UDP (for a flight controller that sends first)\n")
COMPANION_SIM_FORMS = COMPANION_SIM_FORMS.replace(
    "  udpout:HOST:PORT   send UDP to HOST:PORT\n",
    "  udpout:HOST:PORT   send UDP to HOST:PORT (udp:HOST:PORT is read as this here, with a warning;\n"
    "                     in mavutil udp: listens)\n")


class EndpointError(ValueError):
    """A malformed endpoint string; the message names it and lists the accepted forms."""

    def __init__(self, text: str, why: str) -> None:
        self.text, self.why = text, why
        super().__init__(f"endpoint {text!r}: {why}\n{ACCEPTED_FORMS}")


@dataclass(frozen=True)
class Endpoint:
    """One parsed endpoint. ``kind`` is one of udpin, udpout, tcpin, tcp, serial."""

    kind: str
    host: str = ""
    port: int = 0
    device: str = ""
    baud: int = 0
    alias: str = ""  # the scheme as written when it differs from ``kind`` ("udp")

    @property
    def listens(self) -> bool:
        """Waits for the far end to speak first (udpin, tcpin)."""
        return self.kind in (UDP_IN, TCP_IN)

    @property
    def stream(self) -> bool:
        """A byte stream (TCP, serial) rather than datagrams."""
        return self.kind in (TCP_IN, TCP_OUT, SERIAL)

    @property
    def address(self) -> tuple[str, int]:
        return self.host, self.port

    def with_port(self, port: int) -> Endpoint:
        return Endpoint(self.kind, self.host, port, self.device, self.baud)

    def __str__(self) -> str:
        if self.kind == SERIAL:
            return f"{self.device}:{self.baud}"
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.kind}:{host}:{self.port}"


def parse_endpoint(text: str) -> Endpoint:
    """Parse an endpoint string (see the module docstring); EndpointError if malformed."""
    if not isinstance(text, str) or not text.strip():
        raise EndpointError(str(text), "empty")
    text = text.strip()
    scheme, sep, rest = text.partition(":")
    if sep and scheme.lower() in _SCHEMES:
        kind = _SCHEMES[scheme.lower()]
        host, port = _host_port(text, rest)
        ep = Endpoint(kind, host, port, alias=scheme.lower() if scheme.lower() != kind else "")
        return as_destination(ep, text) if kind in (UDP_OUT, TCP_OUT) else ep
    m = _DEVICE.match(text)
    if m is None:
        if sep and scheme.isalpha():
            raise EndpointError(text, f"unknown scheme {scheme!r}")
        raise EndpointError(text, "not SCHEME:HOST:PORT, and not a serial device (an absolute path or COMn)")
    baud = int(m["baud"]) if m["baud"] else DEFAULT_BAUD
    if baud not in BAUD_RATES:
        raise EndpointError(text, f"baud rate {baud} is not one of {', '.join(map(str, BAUD_RATES))}")
    return Endpoint(SERIAL, device=m["dev"], baud=baud)


def as_destination(ep: Endpoint, text: str | None = None) -> Endpoint:
    """``ep`` as a sending endpoint (udpout, or a ``udp:`` read as udpout): EndpointError if its
    port is 0 or its host cannot be one peer (unspecified 0.0.0.0 / ::, broadcast, multicast)."""
    import ipaddress

    text = str(ep) if text is None else text
    if ep.port == 0:
        raise EndpointError(text, "port 0 only makes sense for a listening endpoint")
    try:
        ip = ipaddress.ip_address(ep.host)
    except ValueError:  # a host name: resolved when opened
        ip = None
    if ip is not None and (ip.is_unspecified or ip.is_multicast or ip == ipaddress.IPv4Address("255.255.255.255")):
        raise EndpointError(text, f"{ep.host} is not one host (unspecified, broadcast or multicast); "
                                  f"send to the peer's own address")
    if ep.kind in (UDP_OUT, TCP_OUT):
        return ep
    return Endpoint(UDP_OUT, ep.host, ep.port, alias=ep.alias or ep.kind)


def listen_address(text: str, kind: str, name: str) -> tuple[str, int]:
    """The (host, port) a device server called ``name`` binds, from its endpoint ``text``, which
    must be of ``kind`` (``udpin`` or ``tcpin``): ValueError naming the server and the endpoint
    otherwise."""
    try:
        ep = parse_endpoint(text)
    except EndpointError as e:
        raise ValueError(f"{name}: {e}") from None
    if ep.kind != kind:
        raise ValueError(f"{name} endpoint {text!r}: must be {kind}:HOST:PORT (it listens)")
    return ep.address


def _host_port(text: str, rest: str) -> tuple[str, int]:
    if rest.startswith("["):  # [IPv6]:PORT
        host, close, tail = rest[1:].partition("]")
        if not close or not tail.startswith(":") or ":" not in host:
            raise EndpointError(text, "a bracketed IPv6 host is [ADDRESS]:PORT")
        port_text = tail[1:]
    else:
        host, sep, port_text = rest.rpartition(":")
        if not sep or ":" in host:
            raise EndpointError(text, "expected HOST:PORT (an IPv6 address goes in brackets)")
    if not host:
        raise EndpointError(text, "no host")
    if not port_text.isdigit() or not 0 <= int(port_text) < 65536:
        raise EndpointError(text, f"port {port_text!r} is not a number in 0..65535")
    return host, int(port_text)
