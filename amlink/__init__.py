"""amlink: the wire protocol between the simulator and the companions, defined once.

* :mod:`amlink.dialect` -- the amstack MAVLink 2 dialect (XML in ``amlink/dialect/``),
  generated with pymavlink's mavgen into a cache on first use.
* :mod:`amlink.types` -- value types (numpy only): SensorFrame, TorqueSetpoint,
  AttitudeTarget, AttitudeSetpoint, ScenarioInfo; and the plausibility bounds
  (SetpointLimits, SensorLimits) a value must keep to cross the link.
* :mod:`amlink.codec` -- value types <-> MAVLink payloads: the lockstep batches with
  precompiled structs (payload layouts derived from the generated dialect), and
  the messages sent once a run as pymavlink message objects.
* :mod:`amlink.wire` -- datagram <-> frames (strict framing, MAVLink 2 signatures and
  their timestamp clock).
* :mod:`amlink.signing` -- signing keys: formats, derivation, key files, scenario keys.
* :mod:`amlink.lockstep` -- SimServer / CompanionClient (retransmission, partial
  exchange, rejoin); :mod:`amlink.server`, :mod:`amlink.client`; :mod:`amlink.protocol`:
  the ids, timing constants and counters both ends share.
* :mod:`amlink.endpoint` -- endpoint strings in mavutil's forms (udpin, udpout, tcp,
  tcpin, serial); :mod:`amlink.transport` -- UDP, TCP and serial behind one interface
  (:mod:`amlink.stream`: the TCP and serial byte streams).
* :mod:`amlink.tlog` -- .tlog files as MAVProxy writes them.
* :mod:`amlink.pymavlink_dialect` -- lets stock pymavlink tools load the dialect by name.
* :mod:`amlink.impair` -- deterministic sim-time impairment of the control path.
* :mod:`amlink.shim` -- seeded lossy send shim for the real sockets (tests).

Importing this package does no I/O; the dialect is generated when
:mod:`amlink.codec` (or anything that needs it) is first imported.
"""

from amlink.types import (
    MAX_JOINTS,
    AttitudeSetpoint,
    AttitudeTarget,
    ScenarioInfo,
    SensorFrame,
    SetpointFlag,
    StepFlag,
    TorqueSetpoint,
)

__all__ = [
    "MAX_JOINTS",
    "AttitudeSetpoint",
    "AttitudeTarget",
    "ScenarioInfo",
    "SensorFrame",
    "SetpointFlag",
    "StepFlag",
    "TorqueSetpoint",
]
