"""Free loopback ports, for tests and benchmarks that start servers of their own (other runs
share this machine, so no fixed port is assumed free)."""
from __future__ import annotations

import socket


def free_udp_ports(n: int) -> list[int]:
    """n distinct UDP ports on 127.0.0.1 that nothing was bound to a moment ago (all n are held
    at once while they are picked, so they differ)."""
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()
