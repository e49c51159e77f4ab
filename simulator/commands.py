"""What each flight controller does with a GCS command, and what it answers (no I/O).

Executed by the simulator's main loop between two steps (`execute`), on `SitlCore`:

* MAV_CMD_COMPONENT_ARM_DISARM -- param1 1: arm (undoes a GCS disarm; the companion's
  setpoints apply again), ACCEPTED.  param1 0: disarm (motors off, joints limp), ACCEPTED
  once the vehicle has landed; in the air DENIED unless param2 is PX4's force magic 21196.
* MAV_CMD_NAV_LAND -- that vehicle lands with the failsafe's landing (no hold; arm
  compliant, so it lets go; motors off on the ground), its companion ignored: ACCEPTED.
  DENIED while it is disarmed.
* MAV_CMD_AM_ABORT_MISSION (amstack dialect) -- the whole team's mission is aborted: every
  vehicle lands as for NAV_LAND, whichever vehicle it was sent to; each one it was sent to
  answers ACCEPTED.
* anything else: UNSUPPORTED.

A command to target_system 0 goes to every vehicle, and every vehicle answers.
"""
from __future__ import annotations

from dataclasses import dataclass

from amlink.codec import mav

from .core import SitlCore
from .gcs_link import GcsCommand

FORCE_DISARM_MAGIC = 21196.0  # PX4 (and ArduPilot): param2 of ARM_DISARM that disarms in flight


@dataclass(frozen=True)
class Answer:
    sysid: int
    result: int  # MAV_RESULT
    text: str = ""  # a STATUSTEXT to send with it ("" for none)


def targets(cmd: GcsCommand, sysids) -> list[int]:
    return list(sysids) if cmd.target_system == 0 else [s for s in sysids if s == cmd.target_system]


def execute(core: SitlCore, cmd: GcsCommand) -> tuple[list[Answer], str]:
    """Carry out ``cmd`` on the flight controllers it is for: one answer per vehicle, and news
    for the whole team ("" if none; every vehicle says it)."""
    to = targets(cmd, core.sysids)
    if cmd.command == mav.MAV_CMD_AM_ABORT_MISSION:
        for s in core.sysids:
            core.land(s, by="mission abort")
        return [Answer(s, mav.MAV_RESULT_ACCEPTED) for s in to], "mission aborted (GCS): every vehicle lands"
    return [_one(core, cmd, s) for s in to], ""


def _one(core: SitlCore, cmd: GcsCommand, s: int) -> Answer:
    p = cmd.params
    if cmd.command == mav.MAV_CMD_COMPONENT_ARM_DISARM:
        if p[0] >= 0.5:
            core.arm(s)
            return Answer(s, mav.MAV_RESULT_ACCEPTED)
        if core.disarm(s, force=p[1] == FORCE_DISARM_MAGIC):
            return Answer(s, mav.MAV_RESULT_ACCEPTED)
        return Answer(s, mav.MAV_RESULT_DENIED, "disarm denied: in the air (force: param2 = 21196)")
    if cmd.command == mav.MAV_CMD_NAV_LAND:
        if s in core.disarmed:
            return Answer(s, mav.MAV_RESULT_DENIED, "land denied: disarmed")
        core.land(s)
        return Answer(s, mav.MAV_RESULT_ACCEPTED)
    return Answer(s, mav.MAV_RESULT_UNSUPPORTED)
