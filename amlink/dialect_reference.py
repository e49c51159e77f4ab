"""The MAVLink message reference (docs/reference/mavlink_messages.md), written from the
dialect file every process imports (amlink/dialect/amstack.xml): each message of the amstack
dialect with its id, its fields, units and descriptions, its enums and commands, and the
standard messages the stack uses. tests/test_docs.py checks that the committed page is what
this writes.

    python -m amlink.dialect_reference > docs/reference/mavlink_messages.md
"""
from __future__ import annotations

import sys
import xml.etree.ElementTree as ET
from pathlib import Path

DIALECT = Path(__file__).resolve().parent / "dialect" / "amstack.xml"

# the standard (common.xml) messages the stack sends or reads, with who sends them and why
STANDARD = (
    ("HEARTBEAT", "every process", "presence, mode and arming (PX4's custom-mode encoding)"),
    ("ODOMETRY", "simulator (flight controller) -> companion", "the estimated base pose and twist each control step"),
    ("SET_ATTITUDE_TARGET", "companion -> flight controller", "attitude mode: attitude, body-rate feed-forward, thrust"),
    ("ATTITUDE_TARGET", "flight controller -> companion", "attitude mode: the target the autopilot flies"),
    ("COMMAND_LONG / COMMAND_ACK", "companion or GCS -> flight controller", "arming, OFFBOARD, landing, the mission abort"),
    ("TIMESYNC", "companion <-> autopilot", "free-running: the offboard link's clock offset and latency"),
    ("SYS_STATUS", "flight controller -> GCS", "sensors present and healthy"),
    ("ATTITUDE, LOCAL_POSITION_NED", "flight controller -> GCS", "the vehicle as a ground station shows it"),
    ("STATUSTEXT", "flight controller -> GCS and companions", "mission phases, failsafes, the verdict"),
)

HEADER = """# MAVLink messages

Every process speaks MAVLink 2 with the `amstack` dialect, `amlink/dialect/amstack.xml`. It
includes ArduPilot's dialect (and with it `common.xml`), as stock ground stations expect of a
vehicle, and adds the messages below in the id block 24000-24099, which no dialect shipped
with pymavlink uses. Stock tools load it by name once this package is installed
(`mavlogdump.py --dialect amstack`); for MAVProxy in an environment of its own, see
[mavlink.md](../mavlink.md), "MAVProxy". Endpoints, signing and the GCS link: [mavlink.md](../mavlink.md).

This page is written by `python -m amlink.dialect_reference` from the dialect file.

## Standard messages the stack uses

| message | from -> to | what for |
|---|---|---|
"""


def _text(el) -> str:
    return " ".join((el.text or "").split()) if el is not None else ""


def render(path: Path = DIALECT) -> str:
    root = ET.parse(path).getroot()
    out = [HEADER.rstrip("\n")]
    out += [f"| `{m}` | {who} | {why} |" for m, who, why in STANDARD]
    out.append("\n## amstack messages\n")
    for msg in root.iter("message"):
        out.append(f"### {msg.get('name')} ({msg.get('id')})\n")
        out.append(_text(msg.find("description")) + "\n")
        out.append("| field | type | units | meaning |\n|---|---|---|---|")
        for f in msg.iter("field"):
            enum = f" (enum `{f.get('enum')}`)" if f.get("enum") else ""
            out.append(f"| `{f.get('name')}` | {f.get('type')} | {f.get('units') or ''} | "
                       f"{' '.join((f.text or '').split()).replace('|', '/')}{enum} |")
        out.append("")
    out.append("## amstack enums and commands\n")
    for enum in root.iter("enum"):
        kind = " (bitmask)" if enum.get("bitmask") == "true" else ""
        out.append(f"### {enum.get('name')}{kind}\n")
        desc = _text(enum.find("description"))
        if desc:
            out.append(desc + "\n")
        out.append("| value | name | meaning |\n|---|---|---|")
        for e in enum.iter("entry"):
            out.append(f"| {e.get('value')} | `{e.get('name')}` | {_text(e.find('description')).replace('|', '/')} |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


def main() -> int:
    sys.stdout.write(render())
    return 0


if __name__ == "__main__":
    sys.exit(main())
