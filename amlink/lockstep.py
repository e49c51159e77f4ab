"""Lockstep link between the simulator and N companions (sockets and serial ports only).

Protocol (MAVLink 2, amstack dialect; UDP on the fast path, or TCP and serial byte
streams, :mod:`amlink.transport`; the simulator may serve several endpoints at once):

1. Handshake.  Each companion (sysid s, compid 191 = MAV_COMP_ID_ONBOARD_COMPUTER)
   sends HEARTBEAT at 2 Hz to the simulator.  The simulator (sysid 1, compid 1 =
   MAV_COMP_ID_AUTOPILOT1: it plays every vehicle's flight controller) learns
   the companion's address from that datagram and answers with AM_SCENARIO.
   A companion that listens (udpin) waits for the simulator's HEARTBEAT first.
   Once connected, a companion says HEARTBEAT once a second (each answered with
   AM_SCENARIO, which it ignores); the simulator passes them on to its GCS link.
2. Optional arming: COMMAND_LONG(MAV_CMD_COMPONENT_ARM_DISARM) -> COMMAND_ACK.
3. Each control step the simulator sends every companion ONE datagram
   ``ODOMETRY, AM_JOINT_STATE, AM_WRENCH, AM_SIM_STEP`` (all N first), then waits
   until every companion has answered with ``[SET_ATTITUDE_TARGET,]
   AM_TORQUE_SETPOINT`` (torque mode) or ``SET_ATTITUDE_TARGET,
   AM_JOINT_TORQUE_SETPOINT`` (attitude mode) for that same step.  A control
   step is every physics step, or every rate_hz / control_rate_hz of them.  Loss: the simulator re-sends an
   unanswered batch after ``retry_s`` (backing off); a companion answers a
   batch it already answered with its cached setpoint, so the controller sees
   each step once and the setpoint sequence does not depend on loss.
4. :meth:`SimServer.close` sends ``STATUSTEXT, AM_SIM_STEP(SHUTDOWN)`` (3 copies).

Faults and attackers:

* Every receive path drops and counts (:class:`amlink.protocol.LinkStats`) junk,
  truncated or corrupt frames, unknown sysids, wrong steps, and setpoints or
  sensor frames that are non-finite or outside :mod:`amlink.types`; none of
  these raises or reaches the caller.
* MAVLink 2 signing (:mod:`amlink.signing`, :mod:`amlink.wire`): one 32-byte key
  per companion, link id = its sysid.  Off at this API level (``signing_keys=None``
  / ``signing_key=None``); the process mains turn it on from the scenario.  With
  signing on, unsigned, wrongly signed and replayed packets are dropped and
  counted, and only authentic packets can move a peer's address.  With signing
  off nothing is authenticated (see :class:`SimServer` for what that allows);
  use it only for tools that cannot sign.
* Dead companions: ``SimServer.exchange(..., partial=True)`` (see there).

Running with signing off (tools that cannot sign, e.g. a plain MAVLink
inspector): put ``[link] signing = false`` in the scenario, and the mains pass
``signing_keys=None`` / ``signing_key=None``.  Both ends must agree: a signing
end drops every unsigned packet (counted as ``unsigned``), and an unsigned end
accepts signed packets without checking them.

Companions on one simulator endpoint share it; the simulator tells them apart by the
packet's sysid.  Neither object is thread-safe; use one per thread.
"""

from amlink.client import CompanionClient
from amlink.server import SimServer

__all__ = ["CompanionClient", "SimServer"]
