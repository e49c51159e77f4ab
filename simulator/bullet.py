"""PyBullet, imported once per process, with its C library's start-up line ("pybullet build
time: ...", written to standard error) shown only on a terminal: a run's logs, a campaign's
workers and redirected output stay clean. Every module of the simulator imports `pb` from here.
"""
from __future__ import annotations

import os
import sys


def _import_quietly():
    if "pybullet" in sys.modules or os.isatty(2):
        import pybullet
        return pybullet
    try:
        sys.stderr.flush()
        saved, null = os.dup(2), os.open(os.devnull, os.O_WRONLY)
    except (OSError, ValueError, AttributeError):  # no fd 2: import as is
        import pybullet
        return pybullet
    try:
        os.dup2(null, 2)  # C's stderr is unbuffered: the line is written (away) during the import
        import pybullet
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)
    return pybullet


pb = _import_quietly()
