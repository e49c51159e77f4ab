"""What both ends of the lockstep link agree on besides the messages: ids, timing constants and
the counters of an endpoint (no I/O; the protocol is :mod:`amlink.lockstep`'s, the sockets
:mod:`amlink.transport`'s)."""

from __future__ import annotations

from dataclasses import dataclass

from amlink.codec import mav

SIM_SYSID = 1
SIM_COMPID = mav.MAV_COMP_ID_AUTOPILOT1
COMPANION_COMPID = mav.MAV_COMP_ID_ONBOARD_COMPUTER
HEARTBEAT_PERIOD_S = 0.5  # the companion's HEARTBEAT while it connects [s]
RUN_HEARTBEAT_PERIOD_S = 1.0  # ... and once connected, as a companion computer does [s]
COMMAND_RETRY_S = 0.25
SENSOR_RETRY_S = 0.025  # first re-send of an unanswered sensor batch [s wall]; doubles up to 4x
REJOIN_QUIET_S = 1.0  # signing off: a HEARTBEAT moves a peer only after this long silent [s]
SHUTDOWN_COPIES = 3  # the last datagram of a run is sent this many times (loss)
STATUSTEXT_MAX = 50  # bytes in STATUSTEXT.text
# While the simulator gathers its companions (HEARTBEAT, then ARM from every sysid), it tells
# those already there whom it waits for, every WAITING_NOTICE_PERIOD_S, in a STATUSTEXT that
# begins with WAITING_NOTICE_PREFIX; a companion waits for its first frame as long as these come.
WAITING_NOTICE_PERIOD_S = 2.0
WAITING_NOTICE_PREFIX = "waiting "


@dataclass
class LinkStats:
    """Counters of one endpoint (MAVLink packets unless noted)."""

    datagrams_rx: int = 0
    datagrams_tx: int = 0
    bad_frames: int = 0  # CRC errors, unknown message ids, truncated frames, junk
    unknown_sysid: int = 0  # packets from a sysid we do not talk to
    stale_setpoints: int = 0  # setpoint for a step older than the one awaited
    duplicate_setpoints: int = 0  # second setpoint for the awaited step
    wrong_step_setpoints: int = 0  # setpoint for a step not yet sent
    ignored: int = 0  # valid packets of types this endpoint does not use
    # bad values (amlink.types): counted, never returned or applied
    rejected_setpoints: int = 0  # server: non-finite, out of range or wrong joint count
    rejected_frames: int = 0  # companion: sensor batch / AM_SCENARIO invalid, wrong scenario_id
    nonfinite_values: int = 0  # of the two above, those rejected for a NaN or infinity
    # signing on (amlink.wire.Decoder)
    unsigned: int = 0  # unsigned packets
    bad_signature: int = 0  # signed with another key, or altered after signing
    replayed: int = 0  # not newer than its stream's last authentic packet (checked before the signature)
    # addresses and peers
    wrong_address: int = 0  # signing off: a known sysid from an address other than its peer's
    address_changes: int = 0  # server: a peer moved to a new address (rejoin or NAT rebinding)
    rejoins: int = 0  # server: HEARTBEAT from a known peer at a new address
    peers_lost: int = 0  # server, exchange(partial=True): a peer missed a step and was marked lost
    # loss recovery
    retransmits: int = 0  # server: batches re-sent; companion: cached setpoints re-sent
    duplicate_frames: int = 0  # companion: sensor frames for a step already seen
    skipped_frames: int = 0  # companion: frames passed over for a newer one already queued (a backlog)
    # byte streams (TCP, serial) and sending
    junk_bytes: int = 0  # stream bytes skipped while finding the next whole frame (noise, a cut-off frame)
    send_drops: int = 0  # datagrams not sent: no route to the address, or a stream's backlog full or closed
