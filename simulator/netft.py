"""One vehicle's wrist F/T sensor as an ATI Net F/T answering RDT over UDP
(`amlink.rdt_protocol`: the manual, the packet layouts, the counts).

The sensor frame is the end-effector frame {e}: `publish(now_s, wrench_E)` takes the wrench
the environment applies on the end effector, expressed in {e} ([N; N m], as
amlink.types.SensorFrame.wrench_E), as the gauges read it: the exact wrench, or a reading
with `simulator.devices.ForceTorque`'s noise, offset and drift and no tare of its own
(tare_at_s < 0): the tare is now the client's "set software bias" command, which makes the
reading at that moment zero until the next bias.

Streaming: a start command (0x0002 real time, 0x0003 buffered) from any address makes that
address the one streamed to (the manual: a command from another client takes precedence);
records go out at `rate_hz` on a drift-free schedule (next deadline = last + 1 / rate_hz) as
`poll(now_s)` finds them due, each carrying the latest published wrench: rdt_sequence counts
1, 2, ... within the stream; ft_sequence is the sample slot (now_s - t_open) x rate_hz, so a
slot `poll` came too late to send (more than `max_burst` behind) shows as a jump in
ft_sequence while rdt_sequence stays gapless (counted in `stats.late_slots`). Buffered mode
sends `rdt_buffer_size` records per datagram. sample_count > 0 stops after that many records.
Status is 0 (no saturation or monitor conditions are emulated; "reset threshold latch" is
accepted and does nothing). Counts saturate at the int32 range.

Default rate 1000 Hz: the rate the project's F/T model samples at (every physics step of
[scenario].rate_hz = 1000 Hz); a Net F/T's RDT output rate is a setting (up to 7000 Hz).
"""
from __future__ import annotations

from dataclasses import dataclass

from amlink import rdt_protocol as rdt
from amlink.transport import UdpListener


def default_endpoint(index: int) -> str:
    """The Net F/T endpoint of vehicle `index` (0-based [[am]] order)."""
    return f"udpin:127.0.0.1:{rdt.netft_port(index)}"


@dataclass
class NetFtStats:
    requests: int = 0
    bad_requests: int = 0  # wrong size or header, or an unknown / unsupported command
    records_tx: int = 0
    datagrams_tx: int = 0
    late_slots: int = 0  # sample slots skipped because poll came too late
    send_errors: int = 0
    biases: int = 0


class NetFtServer(UdpListener):
    """The emulated Net F/T (module doc). endpoint: ``udpin:HOST:PORT`` (port 0: a free one,
    see `address`)."""

    def __init__(self, *, rate_hz: float = 1000.0, counts_per_force: float = rdt.COUNTS_PER_FORCE,
                 counts_per_torque: float = rdt.COUNTS_PER_TORQUE, rdt_buffer_size: int = 4, max_burst: int = 10,
                 endpoint: str = "udpin:127.0.0.1:49152") -> None:
        if not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz!r}")
        if not 1 <= rdt_buffer_size <= 40:
            raise ValueError(f"rdt_buffer_size must be in 1..40, got {rdt_buffer_size!r}")
        super().__init__(endpoint, "Net F/T")
        self.period_s = 1.0 / rate_hz
        self.cpf, self.cpt = counts_per_force, counts_per_torque
        self.buffer_size, self.max_burst = rdt_buffer_size, max_burst
        self.stats = NetFtStats()
        self._t0: float | None = None
        self._wrench = (0.0,) * 6  # the latest published wrench (converted to counts when a record needs it)
        self._counts: tuple[int, ...] | None = (0,) * 6  # its counts (None: not converted yet)
        self._bias = (0,) * 6
        self._record_counts: tuple[int, ...] | None = None  # the records' counts (raw less bias), None: to form
        self._client: tuple | None = None
        self._buffered = False
        self._remaining = 0  # records left of a counted request (0: unlimited)
        self._rdt_seq = 0
        self._next_slot = 0  # the next sample slot to send
        self._pending: list[bytes] = []

    def _forget(self) -> None:
        self._client = None

    @property
    def streaming_to(self) -> tuple | None:
        """The client's address while streaming, else None."""
        return self._client

    def publish(self, now_s: float, wrench_E) -> None:
        """The gauges' reading now: wrench_E [Fx, Fy, Fz [N], Tx, Ty, Tz [N m]] on {e}."""
        if self._t0 is None:
            self._t0 = now_s
        self._wrench, self._counts = wrench_E, None  # converted when a record or a bias needs it
        self._record_counts = None

    def _raw_counts(self) -> tuple[int, ...]:
        """The latest published wrench as counts (`rdt.to_counts`), converted once per publish."""
        if self._counts is None:
            self._counts = rdt.to_counts(self._wrench, self.cpf, self.cpt)
        return self._counts

    def poll(self, now_s: float) -> None:
        """Take the requests that arrived, send the records due by now_s [s]. Never blocks."""
        if self._sock is None:
            return
        if self._t0 is None:
            self._t0 = now_s
        while True:
            try:
                data, addr = self._sock.recvfrom(64)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # an ICMP error from an earlier send: the client went away
                self.stats.send_errors += 1
                continue
            self._request(data, addr, now_s)
        if self._client is not None:
            self._stream(now_s)

    def _slot(self, now_s: float) -> int:
        return int((now_s - self._t0) / self.period_s + 1e-9)

    def _request(self, data: bytes, addr, now_s: float) -> None:
        self.stats.requests += 1
        try:
            req = rdt.unpack_request(data)
        except ValueError:
            self.stats.bad_requests += 1
            return
        c = req.command
        if c in (rdt.CMD_START_REALTIME, rdt.CMD_START_BUFFERED):
            self._client, self._buffered = addr, c == rdt.CMD_START_BUFFERED
            self._remaining = req.sample_count
            self._rdt_seq = 0
            self._next_slot = self._slot(now_s)
            self._pending.clear()
        elif c == rdt.CMD_STOP:
            self._flush()
            self._client = None
        elif c == rdt.CMD_SET_SOFTWARE_BIAS:
            self._bias = self._raw_counts()  # the raw reading now reads zero
            self._record_counts = None
            self.stats.biases += 1
        elif c == rdt.CMD_RESET_THRESHOLD_LATCH:
            pass
        else:  # multi-unit streaming and unknown codes
            self.stats.bad_requests += 1

    def _stream(self, now_s: float) -> None:
        due = self._slot(now_s)
        if due - self._next_slot >= self.max_burst:
            skip = due - self._next_slot - self.max_burst + 1
            self.stats.late_slots += skip
            self._next_slot += skip
        if self._next_slot > due:
            return  # nothing due: no conversion
        if self._record_counts is None:  # once per published wrench (or bias)
            self._record_counts = tuple(max(min(c - b, 2 ** 31 - 1), -(2 ** 31))
                                        for c, b in zip(self._raw_counts(), self._bias))
        counts = self._record_counts
        while self._next_slot <= due and self._client is not None:
            self._rdt_seq += 1
            rec = rdt.Record(self._rdt_seq, self._next_slot, 0, counts)
            self._next_slot += 1
            self._pending.append(rdt.pack_record(rec))
            self.stats.records_tx += 1
            done = self._remaining and self._rdt_seq >= self._remaining
            if not self._buffered or len(self._pending) >= self.buffer_size or done:
                self._flush()
            if done:
                self._client = None

    def _flush(self) -> None:
        if not self._pending or self._client is None:
            self._pending.clear()
            return
        try:
            self._sock.sendto(b"".join(self._pending), self._client)
            self.stats.datagrams_tx += 1
        except OSError:
            self.stats.send_errors += 1
        self._pending.clear()
