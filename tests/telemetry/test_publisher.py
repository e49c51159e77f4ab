"""TelemetryPublisher never blocks its caller and accounts for every sample it does not send.

"Never blocks" is checked without timing: the publishing loop runs in a thread that must
finish within a generous deadline while zenoh cannot deliver (a timeout, not a benchmark;
benchmarks/bench_telemetry.py measures the cost)."""
from __future__ import annotations

import json
import os
import signal
import struct
import threading
import time

import pytest
import zenoh

from telemetry import binary, wire
from telemetry.publisher import TelemetryPublisher, TelemetryStateError
from telemetry.schema import Keys, samples_of
from telemetry.session import ZenohOptions, build_config

from .zenoh_testing import free_endpoint, start_subscriber

KEYS = Keys()
PAYLOAD_FLOATS = [0.123456789012345] * 120  # ~2 kB encoded, like a controller sample


def _publish_in_thread(pub, n: int, key: str, deadline_s: float = 30.0, pause_every: int = 0) -> list[bool]:
    """publish() n samples from another thread, pausing 1 ms every pause_every (a control
    loop's pace, which lets the sender thread run)."""
    results: list[bool] = []

    def loop():
        for i in range(n):
            results.append(pub.publish(key, {"t": i * 1e-3, "seq": 0, "x": PAYLOAD_FLOATS}))
            if pause_every and i % pause_every == 0:
                time.sleep(1e-3)

    th = threading.Thread(target=loop, daemon=True)
    th.start()
    th.join(deadline_s)
    assert not th.is_alive(), "publish() blocked"
    return results


def test_no_subscriber_no_logger_nothing_blocks_and_everything_is_counted():
    pub = TelemetryPublisher(ZenohOptions(connect=(free_endpoint(),)), queue_size=1000)
    pub.open()
    ok = _publish_in_thread(pub, 5000, KEYS.controller(4))
    st = pub.close(timeout_s=10.0)
    assert st.published == sum(ok) and st.dropped_queue_full == len(ok) - sum(ok)
    assert st.published + st.dropped_queue_full == 5000
    assert st.sent + st.dropped_no_session + st.dropped_at_close == st.published
    assert st.encode_errors == st.send_errors == 0 and st.queued == 0


def test_client_mode_without_router_opens_retries_and_drops_counted():
    pub = TelemetryPublisher(ZenohOptions(mode="client", connect=(free_endpoint(),)), queue_size=100,
                             reopen_period_s=0.05)
    pub.open()
    ok = _publish_in_thread(pub, 300, KEYS.controller(4))
    assert sum(ok) == 100  # the bounded queue holds the first 100, the rest are dropped
    time.sleep(0.2)
    st = pub.close(timeout_s=5.0)
    assert not st.connected and st.session_open_failures >= 2
    assert st.sent == 0 and st.dropped_no_session == 100 and st.dropped_queue_full == 200


def test_live_subscriber_receives_every_sample_in_order():
    ep = free_endpoint()
    got: list[bytes] = []
    messages = [0]
    done = threading.Event()
    n = 3000
    with zenoh.open(build_config(ZenohOptions(role="recorder", listen=(ep,)))) as s:
        def on_sample(sample):
            if str(sample.key_expr) == KEYS.controller(4):
                messages[0] += 1
                got.extend(samples_of(sample.payload.to_bytes()))
            if len(got) == n:
                done.set()

        sub = s.declare_subscriber(KEYS.everything, on_sample)
        pub = TelemetryPublisher(ZenohOptions(connect=(ep,)), queue_size=n)
        pub.open()
        assert pub.wait_for_subscriber(KEYS.controller(4), 10.0)
        _publish_in_thread(pub, n, KEYS.controller(4))
        st = pub.close(timeout_s=10.0)
        assert done.wait(10.0), f"received {len(got)} of {n}"
        sub.undeclare()
    assert st.sent == n and st.dropped == 0
    assert [json.loads(g)["seq"] for g in got] == list(range(n))
    assert messages[0] < n  # a burst goes out batched, several samples per message


def test_binary_and_json_samples_arrive_framed_batched_and_in_publish_order():
    """Binary samples (bytes) go out as length-prefixed frames with the publisher's seq stamped
    in, interleaved keys as one batch message; a key's samples change form mid-stream and the
    order across keys and forms is kept."""
    ep = free_endpoint()
    got: list[tuple[str, bool, int]] = []  # key, binary, seq
    batches, forms = [], set()
    n = 600
    done = threading.Event()
    with zenoh.open(build_config(ZenohOptions(role="recorder", listen=(ep,)))) as s:
        def on_sample(sample):
            key = str(sample.key_expr)
            if key == KEYS.publisher("mixed"):
                return
            batch = wire.split(sample.payload.to_bytes())
            batches.append(len(batch.samples))
            forms.add("batch" if batch.keys is not None else "binary" if batch.binary else "json")
            assert not batch.error and (batch.keys is not None) == (key == KEYS.batch("mixed"))
            for k, d in zip(batch.keys or [key] * len(batch.samples), batch.samples):
                got.append((k, batch.binary, binary.header(d)[1] if batch.binary else json.loads(d)["seq"]))
            if len(got) == n:
                done.set()

        sub = s.declare_subscriber(KEYS.everything, on_sample)
        pub = TelemetryPublisher(ZenohOptions(connect=(ep,)), name="mixed", queue_size=n)
        pub.open()
        assert pub.wait_for_subscriber(KEYS.controller(4), 10.0)
        sent = []
        for i in range(n):
            key = KEYS.controller(4) if i % 3 or 300 <= i < 400 else KEYS.object  # one key only in 300..399
            as_binary = not (key == KEYS.controller(4) and 200 <= i < 260) and i not in (299, 400)  # JSON there
            data = struct.pack("<dQ", i * 1e-3, 0) + b"x" * (i % 50) if as_binary else {"t": i * 1e-3, "seq": 0}
            if as_binary and i % 2:  # half of them as the sender's to finish (telemetry.capture)
                data = (lambda pre: pre[:-1], data + b"!")
            pub.publish(key, data)
            sent.append((key, as_binary))
        st = pub.close(timeout_s=10.0)
        assert done.wait(10.0), f"received {len(got)} of {n}"
        sub.undeclare()
    assert st.sent == n and st.dropped == 0 and st.encode_errors == 0
    per_key: dict[str, int] = {}
    expected = []
    for key, as_binary in sent:
        expected.append((key, as_binary, per_key.setdefault(key, 0)))
        per_key[key] += 1
    assert got == expected
    assert max(batches) > 1 and forms == {"batch", "binary", "json"}  # batched, in every form


def test_a_payload_that_is_neither_json_nor_binary_is_an_encode_error():
    pub = TelemetryPublisher(ZenohOptions(connect=(free_endpoint(),)))
    pub.open()
    pub.publish(KEYS.object, b"short")  # not even a t/seq header
    pub.publish(KEYS.object, (lambda pre: pre[99], b"\0" * 16))  # a capture whose finish fails
    pub.publish(KEYS.object, "text")
    st = pub.close(5.0)
    assert st.encode_errors == 3 and "neither" in st.last_error


@pytest.mark.skipif(not hasattr(signal, "SIGSTOP"), reason="needs SIGSTOP")
def test_stalled_subscriber_fills_the_bounded_queue_without_blocking_the_caller():
    """A subscriber process frozen with SIGSTOP: zenoh's BLOCK congestion control holds
    the sender thread, the queue fills, publish() keeps returning and counts the drops."""
    ep = free_endpoint()
    sub = start_subscriber(ep)
    try:
        pub = TelemetryPublisher(ZenohOptions(connect=(ep,)), queue_size=256)
        pub.open()
        assert pub.wait_for_subscriber(KEYS.controller(4), 10.0)
        os.kill(sub.pid, signal.SIGSTOP)
        ok = _publish_in_thread(pub, 40000, KEYS.controller(4), pause_every=40)  # 80 MB: far beyond any buffer
        st = pub.stats()
        assert st.queued <= 256
        assert st.dropped_queue_full > 0 and st.published + st.dropped_queue_full == 40000 == len(ok)
        # the sender fills the socket buffers, then the frozen subscriber holds it: it stops
        # making progress with the queue still full
        sent, stable_since, deadline = -1, time.monotonic(), time.monotonic() + 4.0
        while time.monotonic() < deadline and time.monotonic() - stable_since < 0.5:
            now = pub.stats().sent
            if now != sent:
                sent, stable_since = now, time.monotonic()
            time.sleep(0.05)
        later = pub.stats()
        assert later.sent == sent < st.published and later.queued == st.queued > 0
        assert pub.publish(KEYS.controller(4), {"t": 0.0, "seq": 0}) is False
        st = pub.close(timeout_s=1.0)  # the sender is stuck in a blocking put: close gives up, never hangs
        in_flight = later.published - later.sent - later.queued  # the batch the stuck put holds
        assert 1 <= in_flight <= 256
        assert st.sent == later.sent and st.dropped_at_close == later.queued + in_flight
        assert st.published == st.sent + st.dropped_at_close and st.queued == 0
    finally:
        os.kill(sub.pid, signal.SIGCONT)
        sub.kill()
        sub.wait(10)


def test_lifecycle_errors_and_disabled_publisher():
    pub = TelemetryPublisher(ZenohOptions(connect=(free_endpoint(),)))
    with pytest.raises(TelemetryStateError):
        pub.publish(KEYS.object, {"t": 0.0, "seq": 0})
    pub.open()
    with pytest.raises(TelemetryStateError):
        pub.open()
    assert pub.publish(KEYS.object, {"t": 0.0, "seq": 0, "x": object()})  # encoded later, on the sender thread
    st = pub.close(5.0)
    assert st.encode_errors == 1 and "cannot encode" in st.last_error
    assert pub.close().encode_errors == 1  # idempotent
    with pytest.raises(TelemetryStateError):
        pub.publish(KEYS.object, {"t": 0.0, "seq": 0})
    off = TelemetryPublisher(ZenohOptions(enabled=False))
    off.open()
    assert off.publish(KEYS.object, {"t": 0.0, "seq": 0}) is False
    assert off.close().published == 0


def test_seq_is_per_key_and_stamped_by_publish():
    pub = TelemetryPublisher(ZenohOptions(connect=(free_endpoint(),)), queue_size=10)
    pub.open()
    a = [{"t": 0.0, "seq": 99} for _ in range(3)]
    b = [{"t": 0.0, "seq": 99} for _ in range(15)]
    for p in a:
        pub.publish(KEYS.controller(4), p)
    for p in b:
        pub.publish(KEYS.controller(5), p)  # the queue overflows: dropped samples still use up a seq
    pub.close(5.0)
    assert [p["seq"] for p in a] == [0, 1, 2] and [p["seq"] for p in b] == list(range(15))


def test_final_stats_let_the_recorder_count_tail_drops_exactly():
    """A burst into a small queue drops the newest samples: no later sample shows their
    gap, but the publisher's final stats do. A Translator fed by a live subscriber must
    count exactly the publisher's drops."""
    from ground_station.contract import Translator

    ep = free_endpoint()
    tr = Translator(KEYS, scene_rate_hz=0.0)
    lock = threading.Lock()
    final = threading.Event()
    with zenoh.open(build_config(ZenohOptions(role="recorder", listen=(ep,)))) as s:
        def on_sample(sample):
            key = str(sample.key_expr)
            for data in samples_of(sample.payload.to_bytes()):
                with lock:
                    tr.translate(key, data)
                if key == KEYS.publisher("burst") and json.loads(data)["final"]:
                    final.set()

        sub = s.declare_subscriber(KEYS.everything, on_sample)
        pub = TelemetryPublisher(ZenohOptions(connect=(ep,)), name="burst", queue_size=50, stats_period_s=0.05)
        pub.open()
        assert pub.wait_for_subscriber(KEYS.controller(4), 10.0)
        for i in range(400):
            pub.publish(KEYS.controller(4 + i % 2), {"t": i * 1e-3, "seq": 0})
        st = pub.close(timeout_s=10.0)
        assert final.wait(10.0)
        sub.undeclare()
    assert st.dropped_queue_full > 0 and st.dropped == st.dropped_queue_full
    with lock:
        missing = sum(tr.stats[KEYS.controller(s)].missing for s in (4, 5))
        received = sum(tr.stats[KEYS.controller(s)].received for s in (4, 5))
    assert received == st.sent and missing == st.dropped_queue_full
    assert tr.stats[KEYS.publisher("burst")].missing == 0


def test_publisher_started_before_the_recorder_reaches_it_once_it_listens():
    ep = free_endpoint()
    pub = TelemetryPublisher(ZenohOptions(connect=(ep,)), name="early")
    pub.open()
    assert pub.wait_connected(5.0)  # the session opens with nobody to connect to
    for i in range(10):
        pub.publish(KEYS.controller(4), {"t": i * 1e-3, "seq": 0})  # nobody listens: gone, not an error
    deadline = time.monotonic() + 5.0
    while pub.stats().sent < 10 and time.monotonic() < deadline:
        time.sleep(0.01)
    got: list[int] = []
    with zenoh.open(build_config(ZenohOptions(role="recorder", listen=(ep,)))) as s:
        sub = s.declare_subscriber(KEYS.controller(4), lambda x: got.extend(json.loads(d)["seq"] for d in samples_of(x.payload.to_bytes())))
        assert pub.wait_for_subscriber(KEYS.controller(4), 10.0)  # the background retry found the recorder
        for i in range(10, 20):
            pub.publish(KEYS.controller(4), {"t": i * 1e-3, "seq": 0})
        st = pub.close(5.0)
        deadline = time.monotonic() + 5.0
        while len(got) < 10 and time.monotonic() < deadline:
            time.sleep(0.02)
        sub.undeclare()
    assert got == list(range(10, 20)) and st.sent == 20 and st.dropped == 0


def test_await_recorder_waits_for_a_subscriber_only_where_one_can_come():
    key = KEYS.controller(4)
    alone = TelemetryPublisher(ZenohOptions(connect=(), listen=()))
    alone.open()
    t0 = time.monotonic()
    assert alone.await_recorder(key, 5.0) and time.monotonic() - t0 < 1.0  # no endpoint: nothing to wait for
    alone.close()
    ep = free_endpoint()
    pub = TelemetryPublisher(ZenohOptions(connect=(ep,)))
    pub.open()
    t0 = time.monotonic()
    assert not pub.await_recorder(key, 0.5) and time.monotonic() - t0 >= 0.5  # nobody listens
    assert pub.await_recorder(key, 0.0)  # 0: do not wait
    got: list[int] = []
    with zenoh.open(build_config(ZenohOptions(role="recorder", listen=(ep,)))) as s:
        sub = s.declare_subscriber(key, lambda x: got.extend(json.loads(d)["seq"] for d in samples_of(x.payload.to_bytes())))
        assert pub.await_recorder(key, 10.0)
        pub.publish(key, {"t": 0.0, "seq": 0})  # the first sample reaches the subscriber
        pub.close(5.0)
        deadline = time.monotonic() + 5.0
        while not got and time.monotonic() < deadline:
            time.sleep(0.02)
        sub.undeclare()
    assert got == [0]
