"""A pair of pseudo-terminals wired back to back: a null-modem cable between two serial ports.

Each side is a pty whose device (``/dev/pts/N``) a process opens as a serial port; a thread
copies bytes between the two masters (what ``socat pty,raw pty,raw`` does, without socat).
"""
from __future__ import annotations

import contextlib
import os
import select
import threading
import tty


@contextlib.contextmanager
def pty_pair():
    """Yields ``(device_a, device_b)``; bytes written to one are read from the other."""
    (ma, sa), (mb, sb) = os.openpty(), os.openpty()
    for fd in (sa, sb):
        tty.setraw(fd)  # no echo, no line editing before either end opens its device
    stop_r, stop_w = os.pipe()

    def relay() -> None:
        peer = {ma: mb, mb: ma}
        while True:
            ready, _, _ = select.select([ma, mb, stop_r], [], [])
            if stop_r in ready:
                return
            for fd in ready:
                try:
                    data = os.read(fd, 1 << 16)
                except OSError:  # EIO while no process holds that side's device open
                    continue
                view = memoryview(data)
                while view:
                    try:
                        view = view[os.write(peer[fd], view):]
                    except BlockingIOError:
                        select.select([], [peer[fd]], [], 0.1)

    t = threading.Thread(target=relay, daemon=True)
    t.start()
    try:
        yield os.ttyname(sa), os.ttyname(sb)
    finally:
        os.write(stop_w, b"x")
        t.join(2.0)
        for fd in (ma, mb, sa, sb, stop_r, stop_w):
            os.close(fd)
