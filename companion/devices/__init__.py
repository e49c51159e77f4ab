"""The companion's device clients: the arm's servo bus, the wrist F/T sensor and the motion
capture's pose stream, each behind its real protocol, the same against the simulator and
against the hardware.

- `companion.devices.arm`: DYNAMIXEL Protocol 2.0 through ROBOTIS's dynamixel-sdk
  (``--arm /dev/ttyUSB0:4000000`` or ``--arm tcp:127.0.0.1:7200``), current control.
- `companion.devices.netft`: ATI Net F/T RDT over UDP (``--ft udp:192.168.1.1:49152``).
- `companion.devices.mocap`: the pose stream of `amlink.mocap_protocol`
  (``--mocap udp:127.0.0.1:7400``).

Each has an explicit `open()` (nothing happens in a constructor), `read()` (the arm: one bus
transaction; the others: the latest sample, non-blocking after `poll()`), `close()`, counters
in `stats`, and errors derived from `DeviceError` that name the endpoint and what failed.
Samples carry `t_ns`, the client's `time.monotonic_ns()`-style clock (passed in) when they
were read.
"""
from __future__ import annotations

import select
import time


class DeviceError(Exception):
    """A device could not be reached or answered wrongly; the message names it."""


def wait_for_sample(dev, timeout_s: float, fail):
    """Poll a UDP device client (`poll()`, `_latest`, `_sock`) until it has a sample, waiting on its
    socket; after timeout_s [s] without one, raise `fail(elapsed_s)` (the client's own error)."""
    deadline = time.monotonic() + timeout_s
    while dev.poll() == 0 and dev._latest is None:
        left = deadline - time.monotonic()
        if left <= 0:
            raise fail(timeout_s)
        select.select([dev._sock], [], [], min(left, 0.05))
    return dev._latest
