"""Recorder: subscribe to <prefix>/** on Zenoh and write one MCAP log (adapter).

    rec = Recorder(out_path, ZenohOptions(role="recorder"))
    rec.open()                      # file created, zenoh session open, subscribed
    summary = rec.run(duration_s=None, stop=threading.Event())
    rec.close()                     # stats + metadata written, file finished

Zenoh delivers samples on its own threads; the callback only appends (key, bytes) to an
inbox. `run` drains the inbox on the calling thread, translates per ground_station.contract
and writes. Every flush_period_s of wall time it writes /recorder/stats and flushes the
MCAP writer (closing the chunk), so a SIGKILL loses at most that much. `run` returns when
`stop` is set (signal handler), after duration_s of wall time, or linger_s after the
simulator's run_end event (late samples of other processes still get in).

In client mode a router that is not there yet is waited for, as the publishers do: `open`
creates the file and returns, a thread retries the session (every retry_init_ms, backing
off to retry_max_ms) and subscribes once the router answers; `waiting_for_router` says
why meanwhile. Once connected, zenoh reconnects by itself to a router that restarts.
"""
from __future__ import annotations

import collections
import json
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from telemetry import wire
from telemetry.auth import publisher_of, unseal
from telemetry.session import ZenohOptions, build_config, check_tls_files

from .contract import Translator
from .mcap_io import McapLogWriter


def _zenoh_text(exc: Exception) -> str:
    """zenoh's error message without the Rust source location it ends with."""
    return str(exc).split(" at /", 1)[0].strip()


class RecorderError(RuntimeError):
    """The recorder could not start (output not writable, zenoh session refused)."""


@dataclass(frozen=True)
class RecorderSummary:
    path: str
    stop_reason: str
    wall_s: float
    received: int  # samples taken from zenoh
    written: int  # MCAP messages (derived ones included)
    missing: int  # seq gaps summed over keys
    reordered: int
    inbox_overflow: int
    rejected: int  # samples dropped unauthenticated (telemetry.auth: no tag, a wrong one, a key nobody may write)
    malformed: int
    unknown: int
    keys: int
    sim_time_s: float
    bytes: int
    connected: bool  # the zenoh session opened (False: a client whose router never answered)

    def as_dict(self) -> dict:
        return asdict(self)


class Recorder:
    def __init__(self, out_path: str | Path, options: ZenohOptions, *, scene_rate_hz: float = 20.0,
                 flush_period_s: float = 1.0, compression: str = "zstd", chunk_size: int = 4 * 1024 * 1024,
                 inbox_limit: int = 2_000_000, linger_s: float = 0.5, notify=None):
        """notify(text): told, from the retry thread, when a client reaches its router after
        waiting for it (the CLI prints it)."""
        self.out_path = Path(out_path)
        self.options = options
        self.keys = options.keys
        self.flush_period_s = flush_period_s
        self.linger_s = linger_s
        self.inbox_limit = inbox_limit
        self.translator = Translator(self.keys, scene_rate_hz=scene_rate_hz)
        self.writer = McapLogWriter(self.out_path, compression=compression, chunk_size=chunk_size)
        self._inbox: collections.deque = collections.deque()
        self._overflow = 0
        self._received = 0
        self._rejected = 0
        self._master = options.auth_key  # telemetry.auth: keep only what the run's publishers sealed
        self._session = None
        self._subscriber = None
        self._session_lock = threading.Lock()  # the retry thread sets the session, close() takes it
        self._closing = threading.Event()
        self._retry_thread: threading.Thread | None = None
        self._notify = notify
        self.connected = False  # the session opened (at open, or later by the retry thread)
        self.waiting_for_router: str | None = None  # client mode: the last connection error while waiting
        self._t0 = 0.0
        self._stop_reason = ""
        self._run_start_written = False

    # ------------------------------------------------------------------ lifecycle
    def open(self) -> None:
        """Create the file, open the zenoh session and subscribe. A client whose router does
        not answer yet keeps retrying in the background (`waiting_for_router`); any other
        failure raises RecorderError (TelemetryConfigError: a TLS file the config names is missing)."""
        check_tls_files(self.options)
        try:
            self.writer.open()
        except OSError as exc:
            raise RecorderError(f"cannot create {self.out_path}: {exc.strerror or exc}") from exc
        try:
            self._connect()
        except Exception as exc:
            if not self._router_missing(exc):
                self.writer.close()
                raise RecorderError(f"zenoh: {_zenoh_text(exc)}") from exc
            self.waiting_for_router = _zenoh_text(exc)
            self._retry_thread = threading.Thread(target=self._retry, name="recorder-connect", daemon=True)
            self._retry_thread.start()
        self._t0 = time.monotonic()

    def _connect(self) -> None:
        """Open the session and subscribe (raises what zenoh raises). A session that opens
        after close() began is closed again at once."""
        import zenoh

        session = zenoh.open(build_config(self.options))
        try:
            subscriber = session.declare_subscriber(self.keys.everything, self._on_sample)
        except Exception:
            session.close()
            raise
        with self._session_lock:
            if not self._closing.is_set():
                self._session, self._subscriber = session, subscriber
                self.connected = True
                return
        subscriber.undeclare()
        session.close()

    def _router_missing(self, exc: Exception) -> bool:
        """A client's session that failed only because its router does not answer (zenoh opens
        a client only once connected; a peer or router opens at once and connects later)."""
        return self.options.mode == "client" and "Unable to connect" in str(exc)

    def _retry(self) -> None:
        """Thread: retry the client's session, backing off as zenoh's own connect retry."""
        period_s = self.options.retry_init_ms / 1e3
        while not self._closing.wait(period_s):
            try:
                self._connect()
            except Exception as exc:
                self.waiting_for_router = _zenoh_text(exc)
                period_s = min(2.0 * period_s, self.options.retry_max_ms / 1e3)
                continue
            if self.connected:
                self.waiting_for_router = None
                if self._notify is not None:
                    self._notify(f"zenoh: connected to {', '.join(self.options.connect_endpoints) or 'the router'}")
            return

    def _on_sample(self, sample) -> None:
        # zenoh's thread: keep it minimal
        if len(self._inbox) >= self.inbox_limit:
            self._overflow += 1
            return
        self._inbox.append((str(sample.key_expr), sample.payload.to_bytes()))

    def run(self, duration_s: float | None = None, stop: threading.Event | None = None) -> str:
        """Record until stopped; returns the stop reason."""
        stop = stop or threading.Event()
        next_flush = time.monotonic() + self.flush_period_s
        end_at = None
        while True:
            now = time.monotonic()
            if stop.is_set():
                self._stop_reason = "signal"
                break
            if duration_s is not None and now - self._t0 >= duration_s:
                self._stop_reason = "duration"
                break
            if end_at is None and self.translator.run_end is not None:
                end_at = now + self.linger_s
            if end_at is not None and now >= end_at:
                self._stop_reason = "run_end"
                break
            if not self._drain(max_items=5000):
                stop.wait(0.002)
            if now >= next_flush:
                self._flush()
                next_flush = now + self.flush_period_s
        return self._stop_reason

    def _drain(self, max_items: int | None = None) -> int:
        n = 0
        pop, translate, write = self._inbox.popleft, self.translator.translate, self.writer.write
        samples = 0
        while self._inbox and (max_items is None or n < max_items):
            key, message = pop()
            n += 1
            if self._master is not None:
                body = unseal(self._master, self.keys, key, message)
                if body is None:  # forged, or not of this run: counted, never written
                    self._rejected += wire.count(message)
                    continue
                message = body
            batch = wire.split(message)  # JSON lines or binary frames (without a key: the tag line skipped)
            if batch.error:  # a truncated or garbled binary message: the frames before the damage are kept
                self.translator.malformed += 1
                self.translator.last_error = f"{key}: {batch.error}"
            for key_i, data in self._samples(key, batch):
                samples += 1
                try:
                    outs = translate(key_i, data, batch.binary)
                except Exception as exc:  # a payload the contract did not foresee: count it, never stop recording
                    self.translator.malformed += 1
                    self.translator.last_error = f"{key}: {type(exc).__name__}: {exc}"
                    outs = ()
                for out in outs:
                    write(out)
        self._received += samples
        if not self._run_start_written and self.translator.run_start is not None:
            self.writer.add_metadata("run_start", {"json": json.dumps(self.translator.run_start)})
            self._run_start_written = True
        return n

    def _samples(self, key: str, batch: wire.Batch):
        """(key, sample) of a message's samples. A batch (on <p>/batch/<name>) names each
        sample's key; with a run key each must be one that <name> may write (telemetry.auth),
        the others are counted as rejected."""
        name = self.keys.batch_name(key)
        if (batch.keys is None) != (name is None):  # a batch on another key, or a plain message on a batch key
            if batch.samples:
                self.translator.malformed += len(batch.samples)
                self.translator.last_error = f"{key}: {'a batch on a key' if name is None else 'not a batch'}"
            return
        if batch.keys is None:
            for data in batch.samples:
                yield key, data
            return
        for key_i, data in zip(batch.keys, batch.samples):
            if self._master is not None and publisher_of(self.keys, key_i) != name:
                self._rejected += 1  # sealed by <name>, but not a key <name> may write
                continue
            yield key_i, data

    def _flush(self) -> None:
        self.writer.write(self.translator.stats_out(time.monotonic() - self._t0, self._overflow, self._rejected))
        self.writer.flush()

    def close(self) -> RecorderSummary:
        """Stop listening, write what arrived, the final stats and summary; finish the file."""
        self._closing.set()
        if self._retry_thread is not None:
            # an attempt under way ends within zenoh's open timeout; its session is then closed at once
            self._retry_thread.join(1.0)
        with self._session_lock:
            session, subscriber = self._session, self._subscriber
            self._subscriber = None
        if subscriber is not None:
            try:
                subscriber.undeclare()
            except Exception:
                pass
        self._drain()
        if session is not None:
            try:
                session.close()
            except Exception:
                pass
            with self._session_lock:
                self._session = None
        self._drain()
        self.writer.write(self.translator.stats_out(time.monotonic() - self._t0, self._overflow, self._rejected))
        self.writer.flush()  # every message is in the file: `written` and `bytes` below count them all
        summary = self.summary(size=self.writer.size())
        self.writer.add_metadata("recorder_summary", {k: str(v) for k, v in summary.as_dict().items()})
        self.writer.close()
        return self.summary(size=self.out_path.stat().st_size if self.out_path.exists() else 0)

    def summary(self, size: int = 0) -> RecorderSummary:
        """written: every MCAP message so far; bytes: `size` (in the log's recorder_summary the
        file up to that record, every message included; after close, the whole file)."""
        st = self.translator.stats.values()
        return RecorderSummary(
            path=str(self.out_path), stop_reason=self._stop_reason or "closed", wall_s=time.monotonic() - self._t0,
            received=self._received, written=self.writer.messages, missing=sum(s.missing for s in st),
            reordered=sum(s.reordered for s in st), inbox_overflow=self._overflow, rejected=self._rejected,
            malformed=self.translator.malformed, unknown=self.translator.unknown, keys=len(self.translator.stats),
            sim_time_s=self.translator.latest_t, bytes=size,
            connected=self.connected)
