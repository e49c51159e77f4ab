"""The wrist F/T sensor through ATI Net F/T's RDT over UDP (`amlink.rdt_protocol`: the
manual, commands, layouts, counts); the same client reads the simulator's emulated sensor
(`simulator.netft`) and a real Net F/T.

Endpoint: ``udp:HOST:PORT`` (or ``udpout:``), the sensor's address, e.g.
``udp:192.168.1.1:49152`` (a Net F/T's factory address and RDT port) or
``udp:127.0.0.1:49152`` (the simulator's vehicle 0).

`open()` sends "start high-speed real-time streaming" (or buffered) with sample_count 0 (until
stopped). `poll()` reads every datagram that arrived (non-blocking) and keeps the latest
record: `read()` returns it as an `FtSample` (wrench_E [Fx, Fy, Fz [N], Tx, Ty, Tz [N m]] on
the end-effector frame {e}, its rdt_sequence / ft_sequence / status, t_ns when it was
received), or None when none arrived or it is older than `max_age_s`. Lost records are
counted from gaps in rdt_sequence (`stats.dropped`), records not newer than the last are
counted and ignored (`stats.out_of_order`). `bias()` sends "set software bias" (the sensor
zeroes its present reading), `reset_latch()` "reset threshold latch". `wait(timeout_s)`
polls until a record arrives, or raises FtError saying whether the sensor refused
(nothing listens there) or stayed silent. `close()` sends "stop" and closes the socket.
"""
from __future__ import annotations

import socket
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from amlink import rdt_protocol as rdt
from amlink.endpoint import UDP_IN, UDP_OUT, EndpointError, as_destination, parse_endpoint

from . import DeviceError, wait_for_sample

_MAX_DRAIN = 512


class FtError(DeviceError):
    pass


@dataclass(frozen=True)
class FtSample:
    """One RDT record: wrench_E (6,) [N; N m] on {e}; t_ns the client's clock at receipt."""

    wrench_E: np.ndarray
    t_ns: int
    rdt_sequence: int
    ft_sequence: int
    status: int


@dataclass
class FtStats:
    datagrams: int = 0
    records: int = 0
    dropped: int = 0  # records missing from the rdt_sequence
    out_of_order: int = 0  # records not newer than the last (duplicates, reordering)
    malformed: int = 0  # datagrams that are not a whole number of records
    refused: int = 0  # ICMP port unreachable: nothing listens at the endpoint
    nonzero_status: int = 0
    commands: int = 0


def parse_ft_endpoint(text: str) -> tuple[str, int]:
    """The sensor's (host, port) from ``udp:HOST:PORT`` / ``udpout:HOST:PORT``."""
    try:
        ep = parse_endpoint(text)
        if ep.kind not in (UDP_IN, UDP_OUT):
            raise EndpointError(text, "the Net F/T speaks UDP: udp:HOST:PORT")
        ep = as_destination(ep, text)
    except EndpointError as e:
        raise ValueError(f"--ft {text!r}: {e.why}") from None
    return ep.address


class NetFtClient:
    """RDT client (module doc). counts_per_force / counts_per_torque: the sensor's
    calibration (its netftapi2.xml cfgcpf / cfgcpt), 1,000,000 per N and per N m by default."""

    def __init__(self, endpoint: str, *, counts_per_force: float = rdt.COUNTS_PER_FORCE,
                 counts_per_torque: float = rdt.COUNTS_PER_TORQUE, buffered: bool = False,
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        self.endpoint = endpoint
        self.address = parse_ft_endpoint(endpoint)
        self.cpf, self.cpt = counts_per_force, counts_per_torque
        self.buffered, self.clock = buffered, clock
        self.stats = FtStats()
        self._sock: socket.socket | None = None
        self._latest: FtSample | None = None
        self._last_seq: int | None = None

    def open(self) -> None:
        host, port = self.address
        try:
            infos = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except socket.gaierror as e:
            raise FtError(f"Net F/T {self.endpoint}: cannot resolve {host!r}: {e}") from None
        family, _, _, _, addr = infos[0]
        s = socket.socket(family, socket.SOCK_DGRAM)
        try:
            s.connect(addr)  # only the sensor's datagrams; ICMP errors reported on this socket
        except OSError as e:
            s.close()
            raise FtError(f"Net F/T {self.endpoint} unreachable: {e}") from None
        s.setblocking(False)
        self._sock = s
        self.start()

    def _command(self, command: int, count: int = 0) -> None:
        if self._sock is None:
            raise FtError(f"Net F/T {self.endpoint}: not open")
        for _ in range(2):  # a refusal reported here is an earlier datagram's; this one was not sent
            try:
                self._sock.send(rdt.pack_request(command, count))
            except ConnectionRefusedError:
                self.stats.refused += 1
                continue
            except OSError as e:
                raise FtError(f"Net F/T {self.endpoint}: cannot send: {e}") from None
            self.stats.commands += 1
            return

    def start(self, sample_count: int = 0) -> None:
        """Start streaming (sample_count 0: until stopped); a new stream's rdt_sequence starts at 1."""
        self._last_seq = None
        self._command(rdt.CMD_START_BUFFERED if self.buffered else rdt.CMD_START_REALTIME, sample_count)

    def bias(self) -> None:
        """Set software bias: the sensor's present reading becomes zero."""
        self._command(rdt.CMD_SET_SOFTWARE_BIAS)

    def reset_latch(self) -> None:
        self._command(rdt.CMD_RESET_THRESHOLD_LATCH)

    def poll(self) -> int:
        """Read what arrived (never blocks); the number of new records kept."""
        if self._sock is None:
            return 0
        new = 0
        newest = None  # (record, its datagram's arrival): only the newest becomes the sample
        for _ in range(_MAX_DRAIN):
            try:
                data = self._sock.recv(rdt.RECORD_SIZE * 40)
            except (BlockingIOError, InterruptedError):
                break
            except ConnectionRefusedError:
                self.stats.refused += 1
                continue
            t_ns = self.clock()
            self.stats.datagrams += 1
            try:
                records = rdt.unpack_records(data)
            except ValueError:
                self.stats.malformed += 1
                continue
            for rec in records:
                self.stats.records += 1
                if self._last_seq is not None:
                    gap = rdt.sequence_gap(self._last_seq, rec.rdt_sequence)
                    if gap < 0:
                        self.stats.out_of_order += 1
                        continue
                    self.stats.dropped += gap
                self._last_seq = rec.rdt_sequence
                if rec.status:
                    self.stats.nonzero_status += 1
                newest = (rec, t_ns)
                new += 1
        if newest is not None:
            rec, t_ns = newest
            self._latest = FtSample(np.array(rdt.from_counts(rec.counts, self.cpf, self.cpt)), t_ns,
                                    rec.rdt_sequence, rec.ft_sequence, rec.status)
        return new

    def read(self, max_age_s: float | None = None) -> FtSample | None:
        """The latest record, or None (none yet, or older than max_age_s [s])."""
        s = self._latest
        if s is None or (max_age_s is not None and self.clock() - s.t_ns > max_age_s * 1e9):
            return None
        return s

    def wait(self, timeout_s: float) -> FtSample:
        """Poll until a record arrives; FtError after timeout_s [s] without one."""
        why = lambda: "refused (nothing listens there)" if self.stats.refused else "no record arrived"  # noqa: E731
        return wait_for_sample(self, timeout_s, lambda t: FtError(f"Net F/T {self.endpoint}: {why()} within {t:g} s"))

    def fileno(self) -> int:
        return -1 if self._sock is None else self._sock.fileno()

    def close(self) -> None:
        if self._sock is None:
            return
        try:
            self._command(rdt.CMD_STOP)
        except FtError:
            pass
        self._sock.close()
        self._sock = None
