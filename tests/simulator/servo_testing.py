"""Running the simulator's device servers on a thread while a test talks to them as a client.

`serving(*devices)` polls each device (anything with `fds()` and `poll(now_s)`) whenever one
of its descriptors is readable (and at least every 2 ms), and yields a lock: a test holds it
while it touches a device's state (observe, joint_torques_nm, publish) from its own thread.
"""
from __future__ import annotations

import contextlib
import select
import threading
import time


@contextlib.contextmanager
def serving(*devices, period_s: float = 0.002):
    lock = threading.Lock()
    stop = threading.Event()

    def loop() -> None:
        while not stop.is_set():
            fds = [fd for d in devices for fd in d.fds()]
            select.select(fds, [], [], period_s)
            with lock:
                now = time.monotonic()
                for d in devices:
                    d.poll(now)

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    try:
        yield lock
    finally:
        stop.set()
        t.join(2.0)
