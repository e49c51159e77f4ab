"""Helpers of the zenoh tests: free loopback ports, a subscriber process to stall."""
from __future__ import annotations

import socket
import subprocess
import sys
import textwrap


def free_endpoint() -> str:
    """A loopback TCP endpoint nobody listens on (other test runs share this machine)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


SUBSCRIBER = textwrap.dedent("""
    import sys, time
    import zenoh
    from telemetry.session import ZenohOptions, build_config
    s = zenoh.open(build_config(ZenohOptions(role="recorder", listen=(sys.argv[1],))))
    n = [0]
    sub = s.declare_subscriber("amstack/**", lambda x: n.__setitem__(0, n[0] + 1))
    print("ready", flush=True)
    sys.stdin.readline()  # the test says when to stop
    print(n[0], flush=True)
""")


def start_subscriber(endpoint: str) -> subprocess.Popen:
    """A zenoh subscriber process listening on `endpoint`; prints 'ready', then the count
    it received once a line arrives on its stdin."""
    p = subprocess.Popen([sys.executable, "-c", SUBSCRIBER, endpoint], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
    line = p.stdout.readline().strip()
    if line != "ready":
        p.kill()
        raise RuntimeError(f"subscriber did not start: {line!r}")
    return p
