"""TelemetryPublisher: put telemetry on Zenoh without ever blocking the caller.

    tele = TelemetryPublisher(options)      # stores only
    tele.open()                             # starts the sender thread; returns at once
    tele.publish(key, payload)              # stamps seq, enqueues; never blocks
    tele.close()                            # sends what is queued (bounded wait), closes

A payload is a dict (a JSON sample: the sender encodes it), bytes (a binary sample of
telemetry.binary) or a (finish, pre-sample) pair of telemetry.capture (the sender calls
finish.many(pre-samples) once per finisher for a wake-up's samples, or finish(pre-sample)). The caller only takes the per-key
`seq` and appends to a bounded deque (~1 us; no lock, no wake-up of another thread). A
sender thread opens the zenoh session (retrying if it cannot, e.g. client mode with no
router), wakes every poll_period_s, encodes what is queued and puts it: one message per run
of consecutive samples of a key, carrying them as JSON texts separated by newlines or as
length-prefixed binary frames (telemetry.wire; docs/telemetry.md). At 1 kHz per AM that is
some twenty samples per message instead of a message per sample, whose cost in zenoh, in the
subscriber's callback and in the recorder is per message. When the queue is full the sample
is dropped and counted; its seq number is used up, so the recorder sees the gap too.

The sender's zenoh puts use congestion control BLOCK by default: a slow recorder slows
the sender (zenoh releases the GIL while it waits, so the caller is not held), the queue
fills and the drops are counted here, at their source. With "drop" zenoh discards what
its transmission queue cannot take, which this process cannot count (the recorder still
sees seq gaps). benchmarks/bench_telemetry.py measures the alternatives.

Every stats_period_s, and once more at close after the queue is drained, the sender
puts the publisher's own accounting on <prefix>/telemetry/<name> (PublisherStats: seq
numbers issued per key, counters). From the final one the recorder also counts samples
lost at the tail of a key, which leave no gap.
"""
from __future__ import annotations

import collections
import logging
import math
import os
import re
import socket
import threading
import time
from dataclasses import dataclass
from typing import Iterable, Mapping

from .auth import seal
from .binary import HEADER
from .schema import encode, publisher_stats_sample
from .session import ZenohOptions, build_config, check_tls_files
from . import wire

log = logging.getLogger(__name__)


class TelemetryStateError(RuntimeError):
    """publish() or open() called in the wrong state (before open, after close, twice)."""


@dataclass(frozen=True)
class PublisherStats:
    """Counters of one publisher since open() [samples]. Once closed:
    published == sent + dropped_no_session + dropped_at_close + encode_errors + send_errors."""

    published: int  # accepted by publish() (queued)
    sent: int  # handed to zenoh
    dropped_queue_full: int  # publish() found the queue full
    dropped_no_session: int  # queued, but the session never opened before close()
    dropped_at_close: int  # still queued (or in a put) when close() gave up waiting
    encode_errors: int  # payload not JSON-serialisable, nor binary (programming error; see last_error)
    send_errors: int  # zenoh put raised
    nonfinite: int  # JSON payloads whose NaN/inf were sent as null (binary samples carry them as they are)
    session_open_failures: int
    connected: bool  # the zenoh session is open (not: a subscriber is listening)
    queued: int
    last_error: str

    @property
    def dropped(self) -> int:
        return (self.dropped_queue_full + self.dropped_no_session + self.dropped_at_close + self.encode_errors
                + self.send_errors)


def _time_of(payload, default: float) -> float:
    """A queued sample's simulation time "t" (for the stats sample's own t)."""
    t = default
    if type(payload) is dict:
        t = payload.get("t", default)
    else:
        data = payload[1] if type(payload) is tuple and len(payload) == 2 else payload  # a pre-sample starts so too
        if isinstance(data, (bytes, bytearray)) and len(data) >= HEADER.size:
            t = HEADER.unpack_from(data)[0]
    return t if isinstance(t, (int, float)) and math.isfinite(t) else default


def _finished(payloads: list) -> list:
    """The binary samples of queued binary payloads, in order: bytes as they are, and each
    telemetry.capture pre-sample finished, one call per finisher for all of its pre-samples
    (`finish.many`, one compiled call for a wake-up's ~100) where it has one. What cannot be
    finished (or is not a binary sample) is left as an exception in its place."""
    out = list(payloads)
    groups: dict = {}
    for i, p in enumerate(payloads):
        if type(p) is tuple and len(p) == 2:
            try:
                groups.setdefault(p[0], []).append(i)
            except TypeError as exc:  # not hashable
                out[i] = exc
        elif not isinstance(p, (bytes, bytearray)) or len(p) < HEADER.size:
            out[i] = TypeError(f"{type(p).__name__} is neither a dict nor a binary sample")
        else:
            out[i] = bytes(p)
    for finish, at in groups.items():
        many = getattr(finish, "many", None)
        if many is not None:
            try:
                done = many([payloads[i][1] for i in at])
                if len(done) == len(at):
                    for i, d in zip(at, done):
                        out[i] = d
                    continue
            except Exception:  # one at a time below: only those that fail are lost
                pass
        for i in at:
            try:
                d = finish(payloads[i][1])
                if not isinstance(d, (bytes, bytearray)) or len(d) < HEADER.size:
                    raise TypeError(f"{type(d).__name__} is not a binary sample")
                out[i] = bytes(d)
            except Exception as exc:
                out[i] = exc
    return out


class TelemetryPublisher:
    """One process's telemetry sender. See the module docstring."""

    def __init__(self, options: ZenohOptions | None = None, *, name: str | None = None, queue_size: int = 8192,
                 congestion: str = "block", poll_period_s: float = 0.1, reopen_period_s: float = 1.0,
                 stats_period_s: float = 1.0, max_batch: int = 256):
        """name: this process in <prefix>/telemetry/<name> ('am4', 'simulator'; default host-pid).
        poll_period_s: how often the sender wakes; zenoh's cost is per message (~100 us of CPU
        per put here, whatever its size), so at 1 kHz 0.1 s costs ~1 us per sample, 0.02 s ~5 us."""
        if congestion not in ("block", "drop"):
            raise ValueError(f"congestion {congestion!r} must be 'block' or 'drop'")
        if queue_size < 1:
            raise ValueError("queue_size must be positive")
        self.options = options or ZenohOptions()
        if self.options.enabled:
            check_tls_files(self.options)  # a missing certificate named now, not retried for ever
        self.keys = self.options.keys
        self._key = self.options.auth_key  # telemetry.auth: seal every message
        self.name = name or re.sub(r"[^A-Za-z0-9_\-]", "-", f"{socket.gethostname()}-{os.getpid()}")
        self._stats_key = self.keys.publisher(self.name)  # validates the name
        self._batch_key = self.keys.batch(self.name)
        self._stats_period_s = stats_period_s
        self._last_t = 0.0
        self._queue_size = queue_size
        self._congestion = congestion
        self._poll_s = poll_period_s
        self._max_batch = max(1, max_batch)
        self._reopen_period_s = reopen_period_s
        self._q: collections.deque = collections.deque()
        self._seq: dict[str, int] = {}
        self._thread: threading.Thread | None = None
        self._state = "new"  # new -> open -> closed
        self._session = None
        self._cc = None
        self._publishers: dict = {}
        self._connected = threading.Event()
        self._stopping = threading.Event()
        self._lock = threading.Lock()  # sender thread vs close(): counters, in-flight, abandon
        self._n = dict(published=0, sent=0, dropped_queue_full=0, dropped_no_session=0, dropped_at_close=0,
                       encode_errors=0, send_errors=0, nonfinite=0, session_open_failures=0)
        self._last_error = ""
        self._in_flight = 0  # samples the sender took from the queue and has not yet counted
        self._abandoned = False

    # ------------------------------------------------------------------ lifecycle
    @property
    def enabled(self) -> bool:
        return self.options.enabled

    def open(self) -> None:
        """Start the sender thread (which opens the zenoh session). Returns at once."""
        if self._state != "new":
            raise TelemetryStateError(f"open() on a publisher that is {self._state}")
        self._state = "open"
        if not self.enabled:
            return
        self._thread = threading.Thread(target=self._run, name="telemetry-publisher", daemon=True)
        self._thread.start()

    def close(self, timeout_s: float = 2.0) -> PublisherStats:
        """Send what is queued (waiting at most timeout_s), close the session, return the
        final counters. Idempotent. If the sender is stuck (a frozen subscriber holding a
        blocking put), what it has not sent is counted as dropped_at_close and the daemon
        thread is left behind."""
        if self._state == "open":
            self._state = "closed"
            if self._thread is not None:
                self._stopping.set()
                self._thread.join(timeout_s)
                if self._thread.is_alive():
                    with self._lock:
                        self._abandoned = True
                        n = len(self._q) + self._in_flight
                        self._q.clear()
                        self._n["dropped_at_close"] += n
                    log.warning("telemetry: close() gave up after %.1f s, %d samples not sent", timeout_s, n)
        self._state = "closed"
        return self.stats()

    def __enter__(self) -> "TelemetryPublisher":
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ caller side
    def publish(self, key: str, payload: dict | bytes) -> bool:
        """Take this key's next seq number and queue the sample. Never blocks.

        payload: a dict (JSON; payload["seq"] is stamped here), the bytes of a binary sample
        (telemetry.binary) or a (finish, pre-sample) pair (telemetry.capture); the sender
        stamps seq into a binary sample's frame. Returns False if
        the sample was dropped (queue full, telemetry disabled). A dict must not be modified
        afterwards (the sender thread encodes it later)."""
        if self._state != "open" or not self.options.enabled:
            if not self.options.enabled:
                return False
            raise TelemetryStateError(f"publish() on a publisher that is {self._state}; call open() first")
        seq = self._seq  # key -> seq numbers issued so far (the next one)
        n = seq.get(key, 0)
        seq[key] = n + 1
        if type(payload) is dict:
            payload["seq"] = n
        q = self._q
        if len(q) >= self._queue_size:
            self._n["dropped_queue_full"] += 1
            return False
        q.append((key, payload, n))
        self._n["published"] += 1
        return True

    def publish_many(self, items: Iterable[tuple[str, dict | bytes]]) -> int:
        """publish() each (key, payload); returns how many were queued."""
        return sum(self.publish(k, p) for k, p in items)

    def wait_connected(self, timeout_s: float) -> bool:
        """Wait until the zenoh session is open (not the same as a subscriber listening)."""
        return self._connected.wait(timeout_s)

    def await_recorder(self, key: str, timeout_s: float) -> bool:
        """Before a run's first sample: wait (at most timeout_s) until a subscriber matches
        `key`, as zenoh drops what is put before the route to a subscriber exists. True if one
        matched; also True when there is nothing to wait for (telemetry off, no endpoint to
        reach a recorder through, timeout_s <= 0)."""
        o = self.options
        if not self.enabled or timeout_s <= 0.0 or not (o.connect_endpoints or o.listen_endpoints
                                                         or o.config_file is not None):
            return True
        return self.wait_for_subscriber(key, timeout_s)

    def wait_for_subscriber(self, key: str, timeout_s: float) -> bool:
        """Wait until some subscriber (e.g. the recorder) matches `key`: lets a simulator
        hold its first step until the recorder listens. False on timeout."""
        deadline = time.monotonic() + timeout_s
        if not self.wait_connected(timeout_s):
            return False
        try:
            probe = self._session.declare_publisher(key)
            try:
                while not probe.matching_status.matching:
                    if time.monotonic() >= deadline:
                        return False
                    time.sleep(0.02)
                return True
            finally:
                probe.undeclare()
        except Exception as exc:  # the session closed underneath us
            self._last_error = f"matching status: {exc}"
            return False

    def stats(self) -> PublisherStats:
        with self._lock:
            n = dict(self._n)
        return PublisherStats(**n, connected=self._connected.is_set(), queued=len(self._q),
                              last_error=self._last_error)

    # ------------------------------------------------------------------ sender thread
    def _count(self, name: str, k: int = 1) -> None:
        with self._lock:
            self._n[name] += k

    def _try_open(self) -> bool:
        import zenoh

        try:
            self._session = zenoh.open(build_config(self.options))
        except Exception as exc:
            self._count("session_open_failures")
            self._last_error = f"zenoh open: {exc}"
            if self._n["session_open_failures"] == 1:
                log.warning("telemetry: cannot open zenoh session (%s); retrying every %.1f s", exc,
                            self._reopen_period_s)
            return False
        self._cc = zenoh.CongestionControl.BLOCK if self._congestion == "block" else zenoh.CongestionControl.DROP
        self._connected.set()
        return True

    def _take(self):
        """Up to max_batch queued (key, payload, seq), oldest first; None if there are none."""
        with self._lock:
            if self._abandoned or not self._q:
                return None
            q = self._q
            items = [q.popleft() for _ in range(min(len(q), self._max_batch))]
            self._in_flight = len(items)
            return items

    def _send(self, items: list[tuple[str, Mapping | bytes, int]]) -> None:
        """Encode the samples and put them, in publish order (the recorder merges keys into
        shared topics such as /tf), as few messages as that order allows (telemetry.wire):
        each run of JSON samples of one key as one message; each run of binary samples
        between two JSON ones as one message of their key, or as one batch on this
        publisher's batch key when they are of several keys (the simulator's interleaved
        truth). A companion's stream is one key: one put per wake-up instead of one per
        sample; zenoh's, the subscriber's and the recorder's cost is per message."""
        counts = dict.fromkeys(("sent", "encode_errors", "send_errors", "nonfinite"), 0)
        messages: list[tuple[str, str, list, list[bytes], list[int]]] = []  # key, form, keys (batch), samples, seqs
        binary_run: tuple[list[str], list, list[int]] = ([], [], [])  # keys, payloads (bytes or (finish, pre)), seqs
        for key, payload, seq in items:
            if type(payload) is not dict:
                binary_run[0].append(key)
                binary_run[1].append(payload)
                binary_run[2].append(seq)
                continue
            try:
                data, replaced = encode(payload)
            except (TypeError, ValueError) as exc:
                counts["encode_errors"] += 1
                self._last_error = f"{key}: cannot encode payload: {exc}"
                continue
            counts["nonfinite"] += replaced
            if binary_run[0]:
                messages += self._binary_run(*binary_run, counts)
                binary_run = ([], [], [])
            if messages and messages[-1][0] == key and messages[-1][1] == "json":
                messages[-1][3].append(data)
                messages[-1][4].append(seq)
            else:
                messages.append((key, "json", [], [data], [seq]))
        if binary_run[0]:
            messages += self._binary_run(*binary_run, counts)
        if items:
            self._last_t = _time_of(items[-1][1], self._last_t)
        for key, form, keys, samples, seqs in messages:
            try:
                pub = self._publishers.get(key)
                if pub is None:
                    pub = self._publishers[key] = self._session.declare_publisher(key, congestion_control=self._cc)
                if form == "batch":
                    body = wire.batch_message(keys, samples, seqs)
                elif form == "binary":
                    body = wire.binary_message(samples, seqs)
                else:
                    body = wire.json_message(samples)
                pub.put(body if self._key is None else seal(self._key, key, body))
                counts["sent"] += len(samples)
            except Exception as exc:
                counts["send_errors"] += len(samples)
                self._last_error = f"{key}: put: {exc}"
        with self._lock:
            self._in_flight = 0
            if not self._abandoned:  # else close() counted them already
                for name, k in counts.items():
                    self._n[name] += k

    def _binary_run(self, keys: list[str], payloads: list, seqs: list[int], counts: dict) -> list[tuple]:
        """The message of a run of binary samples (none if none could be finished): on their
        key, or a batch if of several keys."""
        data = _finished(payloads)
        if any(type(d) is not bytes for d in data):
            ok = [i for i, d in enumerate(data) if type(d) is bytes]
            for d, key in zip(data, keys):
                if type(d) is not bytes:
                    counts["encode_errors"] += 1
                    self._last_error = f"{key}: cannot finish a binary sample: {d}"
            keys, data, seqs = [keys[i] for i in ok], [data[i] for i in ok], [seqs[i] for i in ok]
            if not keys:
                return []
        if keys.count(keys[0]) == len(keys):
            return [(keys[0], "binary", keys, data, seqs)]
        return [(self._batch_key, "batch", keys, data, seqs)]

    def _send_stats(self, final: bool) -> None:
        with self._lock:
            counters = dict(self._n)
        issued = dict(self._seq)  # one C-level copy: consistent under the GIL
        k = self._stats_key
        n = self._seq.get(k, 0)
        self._seq[k] = n + 1
        payload = publisher_stats_sample(self._last_t, self.name, final, issued, counters, seq=n)
        try:
            pub = self._publishers.get(k)
            if pub is None:
                pub = self._publishers[k] = self._session.declare_publisher(k, congestion_control=self._cc)
            body = encode(payload)[0]
            pub.put(body if self._key is None else seal(self._key, k, body))
        except Exception as exc:
            self._last_error = f"{k}: put: {exc}"

    def _run(self) -> None:
        try:
            while not self._try_open():
                # not connected (client mode without a router, bad config): samples wait in
                # the bounded queue; publish() drops and counts once it is full
                if self._stopping.wait(self._reopen_period_s):
                    return
            next_stats = time.monotonic() + self._stats_period_s
            while True:
                items = self._take()
                while items is not None:
                    self._send(items)
                    items = self._take()
                if self._stopping.is_set() or self._abandoned:
                    if not self._abandoned:
                        self._send_stats(final=True)
                    return
                if time.monotonic() >= next_stats:
                    self._send_stats(final=False)
                    next_stats = time.monotonic() + self._stats_period_s
                self._stopping.wait(self._poll_s)
        finally:
            self._shutdown()

    def _shutdown(self) -> None:
        with self._lock:
            left = 0 if self._abandoned else len(self._q)
            self._q.clear()
            if left:
                self._n["dropped_no_session" if self._session is None else "dropped_at_close"] += left
        if self._session is not None:
            for p in self._publishers.values():
                try:
                    p.undeclare()
                except Exception:
                    pass
            try:
                self._session.close()
            except Exception as exc:
                self._last_error = f"zenoh close: {exc}"
        self._connected.clear()
