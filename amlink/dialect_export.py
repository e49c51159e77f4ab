"""Put the amstack dialect into another Python environment's pymavlink, so that tools installed
there on their own (MAVProxy, MAVExplorer) find it by name:

    .venv/bin/python -m amlink.dialect_export ~/mavproxy-venv/bin/python
    ~/mavproxy-venv/bin/mavproxy.py --master=udpin:127.0.0.1:14551 --dialect=amstack

In an environment where amstack itself is installed nothing is needed (amlink.pymavlink_dialect
answers the dialect's module names). Elsewhere pymavlink looks for ``amstack.xml`` beside its
own dialects and generates the module from it on first use; this copies ``amstack.xml`` there
(``pymavlink/dialects/v20``, where the ``ardupilotmega.xml`` it includes lives), generates the
MAVLink 2 module at once (so a mistake shows now, and a stale one from an older amstack is
replaced), and makes the MAVLink 1 name (``v10``) load that same module: the amstack messages
exist in MAVLink 2 only. It then checks, with that interpreter, what MAVProxy relies on:
``MAV_CMD_AM_ABORT_MISSION`` (``long AM_ABORT_MISSION``) and ``MAVLINK_MSG_ID_RADIO`` (its
signing code). Run it again after updating amstack or that environment's pymavlink.

Exit codes: 0 done, 2 the interpreter or its pymavlink cannot be used, 1 writing there failed.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from amcore import cliargs

from .dialect import DIALECT_NAME, XML_PATH, _includes

# a MAVLink 1 name for the MAVLink 2 module: the amstack message ids do not fit MAVLink 1
V10_ALIAS = f'''"""amstack exists in MAVLink 2 only (message ids above 255): this name loads the MAVLink 2
module. Written by amstack's amlink.dialect_export."""
import sys

from pymavlink.dialects.v20 import {DIALECT_NAME} as _v20

sys.modules[__name__] = _v20
'''

_WHERE = "import json, os, pymavlink.dialects.v20 as d; print(json.dumps(os.path.dirname(os.path.abspath(d.__file__))))"
_CHECK = (f"from pymavlink import mavutil; mavutil.set_dialect({DIALECT_NAME!r}); m = mavutil.mavlink; "
          "print(m.MAV_CMD_AM_ABORT_MISSION, m.MAVLINK_MSG_ID_RADIO, m.MAVLINK_MSG_ID_AM_SIM_STEP)")


class ExportError(Exception):
    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code


def _run(python: str, code: str, **env: str) -> str:
    try:
        p = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=300,
                           env={**os.environ, **env})
    except OSError as exc:
        raise ExportError(f"{python}: cannot run it: {exc.strerror or exc}", 2) from None
    if p.returncode != 0:
        last = (p.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise ExportError(f"{python}: {last}", 2)
    return p.stdout


def export(python: str) -> dict:
    """Install the dialect into the pymavlink of interpreter `python`; what was written and checked."""
    v20 = Path(json.loads(_run(python, _WHERE).strip().splitlines()[-1]))
    v10 = v20.parent / "v10"
    missing = [n for n in _includes(XML_PATH) if not (v20 / n).is_file()]
    if missing:
        raise ExportError(f"{python}: its pymavlink has no {', '.join(missing)} in {v20} (amstack.xml includes it); "
                          f"upgrade pymavlink there", 2)
    try:
        for stale in (v20 / f"{DIALECT_NAME}.py", v10 / f"{DIALECT_NAME}.py", v10 / f"{DIALECT_NAME}.xml"):
            stale.unlink(missing_ok=True)
        (v20 / f"{DIALECT_NAME}.xml").write_bytes(XML_PATH.read_bytes())
        v10.mkdir(exist_ok=True)
        (v10 / f"{DIALECT_NAME}.py").write_text(V10_ALIAS)
    except OSError as exc:
        raise ExportError(f"cannot write into {v20.parent}: {exc.strerror or exc} (a system-wide pymavlink: run this "
                          f"as its owner, or install MAVProxy in a virtual environment)", 1) from None
    cmd, radio, step = (int(x) for x in _run(python, _CHECK, MAVLINK20="1").split())  # generates v20/amstack.py
    _run(python, _CHECK)  # and the MAVLink 1 name loads it
    return {"xml": str(v20 / f"{DIALECT_NAME}.xml"), "module": str(v20 / f"{DIALECT_NAME}.py"),
            "MAV_CMD_AM_ABORT_MISSION": cmd, "MAVLINK_MSG_ID_RADIO": radio, "MAVLINK_MSG_ID_AM_SIM_STEP": step}


def main(argv: list[str] | None = None) -> int:
    ap = cliargs.ArgumentParser(prog="python -m amlink.dialect_export",
                                description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("python", help="the Python interpreter of the environment MAVProxy (or another pymavlink tool) "
                                   "runs in, e.g. ~/mavproxy-venv/bin/python")
    a = ap.parse_args(argv)
    try:
        done = export(a.python)
    except ExportError as exc:
        print(f"{ap.prog}: error: {exc}", file=sys.stderr)
        return exc.code
    print(f"amstack dialect installed for {a.python}: {done['xml']} (module generated: {done['module']}); "
          f"MAV_CMD_AM_ABORT_MISSION = {done['MAV_CMD_AM_ABORT_MISSION']}, "
          f"MAVLINK_MSG_ID_RADIO = {done['MAVLINK_MSG_ID_RADIO']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
