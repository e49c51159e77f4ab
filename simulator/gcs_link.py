"""The simulator's GCS port: every vehicle's flight controller as a ground station sees it.

Like PX4 SITL's GCS port, on one endpoint (mavutil's forms, :mod:`amlink.endpoint`; the
simulator's default is ``udpout:127.0.0.1:14551``), each vehicle speaks as (its sysid,
MAV_COMP_ID_AUTOPILOT1): HEARTBEAT and SYS_STATUS at 1 Hz and at once when a vehicle's
mode or arming changes, ATTITUDE and LOCAL_POSITION_NED
at up to 25 Hz of wall time from the newest snapshot (the main loop publishes one every
``snapshot_every`` steps, 50 Hz of simulation time), STATUSTEXT when the main loop queues
one.  Each companion's HEARTBEAT (MAV_COMP_ID_ONBOARD_COMPUTER) is passed on as
mavlink-router would (re-framed, and re-signed when the link is signed).  COMMAND_LONG and
COMMAND_INT for a vehicle (or all, target_system 0) are queued for the main loop, which
executes them (:mod:`simulator.commands`) and queues the COMMAND_ACKs.

Everything runs on a thread of its own, off the lockstep's path: the main loop only
stores a reference (:meth:`GcsLink.publish`) and appends to or pops from deques.  Sockets
never block (:mod:`amlink.transport`): a GCS that is slow, never reads or is absent costs
the run nothing, and no telemetry ever flows back into it.

Signing.  With a GCS key (32 bytes, MAVProxy's SHA-256 of a passphrase,
:func:`amlink.signing.gcs_key_from_passphrase`) everything sent is signed with it and only
commands signed with it are executed; unsigned, wrongly signed and replayed ones are
dropped and counted.  ``accept_unsigned=True`` (the link's signing is off) executes
unsigned commands too.  Without a key and with signing on, the link is telemetry only.

The link writes everything it sends and every whole frame it receives to a .tlog
(:class:`amlink.tlog.TlogWriter`), with or without a GCS attached.
"""
from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from amlink import codec
from amlink.codec import mav
from amlink.endpoint import DEFAULT_GCS, UDP_IN, Endpoint  # noqa: F401  (DEFAULT_GCS: the mains' default)
from amlink.protocol import LinkStats
from amlink.tlog import TlogWriter
from amlink.transport import open_transport
from amlink.wire import StreamFramer

from . import gcs_messages
from .fcstate import FleetSnapshot

HEARTBEAT_PERIOD_S = 1.0
TELEMETRY_PERIOD_S = 0.04  # ATTITUDE and LOCAL_POSITION_NED at most 25 Hz of wall time
GCS_TIMEOUT_S = 10.0  # udpin: keep sending to a GCS address this long after it was last heard
_COMMANDS = (mav.MAVLINK_MSG_ID_COMMAND_LONG, mav.MAVLINK_MSG_ID_COMMAND_INT)
_OUTBOX_MAX = 10_000
_MAVLINK1 = b"\xfe"


@dataclass(frozen=True)
class GcsCommand:
    """A command from the GCS (COMMAND_LONG or COMMAND_INT; COMMAND_INT's x, y as given)."""

    command: int
    target_system: int
    target_component: int
    params: tuple[float, ...]  # param1..param7
    source_system: int
    source_component: int


@dataclass
class GcsStats:
    """Counters of the GCS link (the transport's and the decoder's are in ``LinkStats``)."""

    messages_tx: int = 0  # MAVLink messages sent (or, without a GCS endpoint, only logged)
    commands: int = 0  # authentic commands for our vehicles, queued for the main loop
    not_for_us: int = 0  # commands for another system or component
    acks: int = 0
    statustexts: int = 0
    forwarded: int = 0  # companion HEARTBEATs passed on
    outbox_drops: int = 0  # main-loop messages dropped because the thread fell far behind


class GcsLink:
    """The GCS port of the simulator's flight controllers; nothing opens before :meth:`open`.

    Args:
        endpoint: where the GCS is, or None: no GCS endpoint, the .tlog only.
        sysids: the vehicles.
        key: GCS signing key (32 bytes) or None.
        accept_unsigned: execute unsigned commands (the link's signing is off).
        tlog: path of the .tlog to write, or None.
    """

    def __init__(self, endpoint: Endpoint | None, sysids: Sequence[int], *, key: bytes | None = None,
                 accept_unsigned: bool = False, tlog: Path | None = None) -> None:  # fmt: skip
        self.endpoint = endpoint
        self.sysids = tuple(sysids)
        self.key = key
        self.accept_unsigned = accept_unsigned
        self.stats = GcsStats()
        self.link_stats = LinkStats()
        self.error = ""  # why the link's thread stopped early, if it did
        self._tlog = TlogWriter(tlog) if tlog is not None else None
        self._transport = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._latest: FleetSnapshot | None = None
        self._commands: deque[GcsCommand] = deque()
        self._outbox: deque[tuple] = deque()  # ("ack", cmd, sysid, result) | ("text", sysid, severity, text) | ("fwd", sysid, compid, msg)
        self._encoders: dict[tuple[int, int], codec.Encoder] = {}
        self._heard: dict[tuple, float] = {}  # udpin: GCS address -> time.monotonic() last heard
        self._chunk_id = 0
        keys = {s: key for s in range(256)} if key is not None and not accept_unsigned else None
        self._decoder = codec.Decoder(keys, accept=_COMMANDS, counters=self.link_stats)
        self._v1 = mav.MAVLink(None)  # MAVLink 1 input (see _on_mavlink1)
        self._v1.robust_parsing = True

    # -- main-loop side --------------------------------------------------------
    def open(self, snapshot: FleetSnapshot) -> None:
        """Open the endpoint and the .tlog and start the thread (HEARTBEATs from ``snapshot``).
        OSError if the endpoint cannot be opened."""
        self._latest = snapshot
        if self.endpoint is not None:
            self._transport = open_transport(self.endpoint, self.link_stats)
            sock = getattr(self._transport, "sock", None)
            if sock is not None:
                sock.setblocking(False)  # UDP: a full send buffer drops, never waits
        if self._tlog is not None:
            self._tlog.open()
        self._thread = threading.Thread(target=self._run, name="gcs-link", daemon=True)
        self._thread.start()

    @property
    def is_open(self) -> bool:
        return self._thread is not None

    @property
    def local_address(self) -> tuple | None:
        """The endpoint's local ``(host, port)`` (a listening one's port 0 resolved), if it has one."""
        local = getattr(self._transport, "local_address", None)
        return None if local is None else tuple(local[:2])

    @property
    def bound_endpoint(self) -> Endpoint | None:
        """The endpoint as opened: a listening one's port 0 replaced by the port it was given, so
        that a GCS can be told where to connect."""
        if self.endpoint is None or not self.endpoint.listens or self.endpoint.port != 0:
            return self.endpoint
        local = self.local_address
        return self.endpoint if local is None else self.endpoint.with_port(local[1])

    def publish(self, snapshot: FleetSnapshot) -> None:
        """The newest state of every vehicle (the thread sends from it); returns at once."""
        self._latest = snapshot

    def commands(self) -> list[GcsCommand]:
        """Commands received since the last call, oldest first."""
        out = []
        while self._commands:
            out.append(self._commands.popleft())
        return out

    def acknowledge(self, cmd: GcsCommand, sysid: int, result: int) -> None:
        self._post(("ack", cmd, sysid, result))

    def statustext(self, sysid: int, severity: int, text: str) -> None:
        self._post(("text", sysid, severity, text))

    def announce(self, text: str, severity: int = mav.MAV_SEVERITY_NOTICE) -> None:
        """STATUSTEXT from every vehicle (team-level news: the mission verdict, an abort)."""
        for s in self.sysids:
            self.statustext(s, severity, text)

    def forward_heartbeat(self, sysid: int, compid: int, msg) -> None:
        """A companion's HEARTBEAT from the lockstep link (SimServer.on_heartbeat)."""
        self._post(("fwd", sysid, compid, msg))

    def close(self, timeout_s: float = 2.0) -> None:
        """Send what is queued, stop the thread, close the endpoint and the .tlog."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join(timeout_s)
            self._thread = None
        if self._transport is not None:
            self._transport.close()
            self._transport = None
        if self._tlog is not None:
            self._tlog.close()

    def _post(self, item: tuple) -> None:
        if len(self._outbox) >= _OUTBOX_MAX:
            self.stats.outbox_drops += 1
            return
        self._outbox.append(item)

    # -- the thread --------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # the run goes on without its GCS link; say why once
            self.error = f"{type(exc).__name__}: {exc}"
            print(f"simulator: warning: the GCS link stopped: {self.error}", file=sys.stderr, flush=True)

    def _loop(self) -> None:
        next_beat = next_telemetry = 0.0
        sent: FleetSnapshot | None = None
        beat_state: tuple = ()  # (mode, armed, failsafe) of every vehicle in the last HEARTBEATs
        while True:
            stopping = self._stop.is_set()
            now = time.monotonic()
            due = min(next_beat, next_telemetry) if self._latest is not sent else next_beat
            wait = min(0.05, max(0.0, due - now))  # a new snapshot waits at most 50 ms
            if self._transport is not None:
                for data, addr in self._transport.recv(0.0 if stopping else wait):
                    self._on_input(data, addr)
            elif not stopping:
                self._stop.wait(wait)
            self._drain_outbox()
            snap, now = self._latest, time.monotonic()
            state = tuple((v.mode, v.armed, v.failsafe) for v in snap.vehicles)
            if now >= next_beat or state != beat_state:  # a new mode or arming is told at once
                next_beat, beat_state = now + HEARTBEAT_PERIOD_S, state
                for v in snap.vehicles:
                    self._send(v.sysid, mav.MAV_COMP_ID_AUTOPILOT1,
                               [gcs_messages.heartbeat(v), gcs_messages.sys_status(v)])
            if now >= next_telemetry and snap is not sent:
                next_telemetry, sent = now + TELEMETRY_PERIOD_S, snap
                t_ms = gcs_messages.time_boot_ms(snap)
                for v in snap.vehicles:
                    self._send(v.sysid, mav.MAV_COMP_ID_AUTOPILOT1,
                               [gcs_messages.attitude(v, t_ms), gcs_messages.local_position_ned(v, t_ms)])
            if stopping:
                self._drain_outbox()
                self._flush()
                return

    def _drain_outbox(self) -> None:
        while self._outbox:
            item = self._outbox.popleft()
            kind = item[0]
            if kind == "ack":
                _, cmd, sysid, result = item
                self._send(sysid, mav.MAV_COMP_ID_AUTOPILOT1, [mav.MAVLink_command_ack_message(
                    command=cmd.command, result=result, progress=0, result_param2=0,
                    target_system=cmd.source_system, target_component=cmd.source_component)])
                self.stats.acks += 1
            elif kind == "text":
                _, sysid, severity, text = item
                self._chunk_id = self._chunk_id % 0xFFFF + 1
                self._send(sysid, mav.MAV_COMP_ID_AUTOPILOT1,
                           gcs_messages.statustexts(text, severity, self._chunk_id))
                self.stats.statustexts += 1
            else:
                _, sysid, compid, msg = item
                self._send(sysid, compid, [msg])
                self.stats.forwarded += 1

    def _encoder(self, sysid: int, compid: int) -> codec.Encoder:
        enc = self._encoders.get((sysid, compid))
        if enc is None:
            signing_key = self.key if not self.accept_unsigned else None
            enc = self._encoders[(sysid, compid)] = codec.Encoder(sysid, compid, signing_key=signing_key)
        return enc

    def _send(self, sysid: int, compid: int, msgs) -> None:
        data = self._encoder(sysid, compid).pack(msgs)
        self.stats.messages_tx += len(msgs)
        if self._tlog is not None:
            self._tlog.write(data)
        t = self._transport
        if t is None:
            return
        for addr in self._destinations():
            t.send(addr, data)

    def _destinations(self) -> list:
        t = self._transport
        if self.endpoint.kind != UDP_IN:
            return t.peers()
        now = time.monotonic()
        for addr in [a for a, last in self._heard.items() if now - last > GCS_TIMEOUT_S]:
            del self._heard[addr]
        return list(self._heard)

    def _on_input(self, data: bytes, addr) -> None:
        if self.endpoint.kind == UDP_IN:
            if addr not in self._heard and len(self._heard) >= 16:  # a few GCSes, not every port that says something
                return
            self._heard[addr] = time.monotonic()
        if data[:1] == _MAVLINK1:
            self._on_mavlink1(data)
            return
        if self._tlog is not None:
            whole = StreamFramer().feed(data)  # datagrams and stream chunks both end on a frame boundary here
            if whole:
                self._tlog.write(whole)
        self._queue(self._decoder.feed(data))

    def _on_mavlink1(self, data: bytes) -> None:
        """A GCS that has not switched to MAVLink 2 yet (mavutil, MAVProxy start in MAVLink 1).
        MAVLink 1 cannot be signed: its commands count as unsigned unless the link accepts those."""
        try:
            msgs = [m for m in (self._v1.parse_buffer(bytes(data)) or []) if m.get_type() != "BAD_DATA"]
        except Exception:  # pymavlink's MAVError on junk
            self.link_stats.bad_frames += 1
            return
        if self._tlog is not None:
            for m in msgs:
                self._tlog.write_frame(m.get_msgbuf())
        commands = [m for m in msgs if m.get_msgId() in _COMMANDS]
        self.link_stats.ignored += len(msgs) - len(commands)
        if self.accept_unsigned:
            self._queue(commands)
        else:
            self.link_stats.unsigned += len(commands)

    def _queue(self, msgs) -> None:
        for msg in msgs:
            if msg.target_system not in (0, *self.sysids) or msg.target_component not in (0, mav.MAV_COMP_ID_AUTOPILOT1):
                self.stats.not_for_us += 1
                continue
            params = (msg.param1, msg.param2, msg.param3, msg.param4)
            if msg.get_msgId() == mav.MAVLINK_MSG_ID_COMMAND_LONG:
                params += (msg.param5, msg.param6, msg.param7)
            else:
                params += (float(msg.x), float(msg.y), msg.z)
            self.stats.commands += 1
            self._commands.append(GcsCommand(msg.command, msg.target_system, msg.target_component, params,
                                             msg.get_srcSystem(), msg.get_srcComponent()))

    def _flush(self) -> None:
        t = self._transport
        if t is None:
            return
        deadline = time.monotonic() + 0.5
        while t.wfds() and time.monotonic() < deadline:
            t.recv(0.01)
