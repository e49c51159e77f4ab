"""The emulated ATI Net F/T (simulator.netft, amlink.rdt_protocol): the RDT layouts byte for
byte, records at the stated rate on a driven clock whatever the poll period, counts converted
exactly, sample counts, stop, bias, buffered mode and a second client taking over."""
from __future__ import annotations

import select
import socket

import pytest

from amlink import rdt_protocol as rdt
from simulator.netft import NetFtServer


def test_layouts_are_the_manuals():
    assert rdt.pack_request(rdt.CMD_START_REALTIME, 0) == bytes.fromhex("1234000200000000")
    assert rdt.pack_request(rdt.CMD_SET_SOFTWARE_BIAS, 0) == bytes.fromhex("1234004200000000")
    rec = rdt.Record(1, 0x01020304, 0, (1, -1, 2**31 - 1, -(2**31), 0, 256))
    data = rdt.pack_record(rec)
    assert len(data) == 36 and data[:12] == bytes.fromhex("00000001" "01020304" "00000000")
    assert data[12:20] == bytes.fromhex("00000001" "FFFFFFFF")
    assert rdt.unpack_records(data + data) == [rec, rec]
    with pytest.raises(ValueError, match="header"):
        rdt.unpack_request(bytes.fromhex("4321000200000000"))
    with pytest.raises(ValueError, match="whole number"):
        rdt.unpack_records(data[:-1])
    assert rdt.sequence_gap(4, 5) == 0 and rdt.sequence_gap(4, 7) == 2
    assert rdt.sequence_gap(0xFFFFFFFF, 0) == 0 and rdt.sequence_gap(5, 5) < 0 and rdt.sequence_gap(5, 4) < 0


@pytest.fixture
def server():
    s = NetFtServer(rate_hz=1000.0, endpoint="udpin:127.0.0.1:0")
    s.open()
    yield s
    s.close()


def _client(server, command=rdt.CMD_START_REALTIME, count=0) -> socket.socket:
    c = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    c.bind(("127.0.0.1", 0))
    c.connect(server.address)
    c.send(rdt.pack_request(command, count))
    assert select.select(server.fds(), [], [], 2.0)[0]
    return c


def _drain(c: socket.socket) -> list[list[rdt.Record]]:
    out = []
    while select.select([c], [], [], 0.05)[0]:
        out.append(rdt.unpack_records(c.recv(2048)))
    return out


@pytest.mark.parametrize("poll_every_ms", [1, 3, 7])
def test_records_go_out_at_the_rate_whatever_the_poll_period(server, poll_every_ms):
    c = _client(server)
    server.publish(0.0, [0.0] * 6)
    for k in range(0, 100, poll_every_ms):
        server.poll(k * 1e-3)
    server.poll(0.0995)
    recs = [r for d in _drain(c) for r in d]
    assert [r.rdt_sequence for r in recs] == list(range(1, 100 + 1))
    assert [r.ft_sequence for r in recs] == list(range(100))
    assert server.stats.late_slots == 0


def test_a_late_poll_skips_slots_in_ft_sequence_not_in_rdt_sequence(server):
    c = _client(server)
    server.publish(0.0, [0.0] * 6)
    server.poll(0.0)
    server.poll(0.050)  # 50 slots due at once; at most max_burst (10) go out
    recs = [r for d in _drain(c) for r in d]
    assert [r.rdt_sequence for r in recs] == list(range(1, 12))
    assert [r.ft_sequence for r in recs] == [0] + list(range(41, 51))
    assert server.stats.late_slots == 40


def test_counts_are_converted_exactly(server):
    c = _client(server)
    w = [1.2345678, -0.5, 3.00000049, 0.0123456789, -2e-7, -145.0]
    server.publish(0.0, w)
    server.poll(0.0)
    (rec,), = _drain(c)
    assert rec.counts == (1234568, -500000, 3000000, 12346, 0, -145000000)
    back = rdt.from_counts(rec.counts)
    assert back == tuple(k / 1e6 for k in rec.counts)
    assert all(abs(b - x) <= 0.5e-6 for b, x in zip(back, w))
    assert rdt.to_counts([3000.0, -3000.0, 0, 0, 0, 0])[:2] == (2**31 - 1, -(2**31))  # int32 saturation


def test_sample_count_stop_and_bias(server):
    c = _client(server, count=5)
    w1 = [1.0, 2.0, -3.0, 0.1, -0.2, 0.3]
    server.publish(0.0, w1)
    for k in range(20):
        server.poll(k * 1e-3)
    assert [r.rdt_sequence for d in _drain(c) for r in d] == [1, 2, 3, 4, 5]
    assert server.streaming_to is None
    c.send(rdt.pack_request(rdt.CMD_SET_SOFTWARE_BIAS))
    c.send(rdt.pack_request(rdt.CMD_START_REALTIME))
    select.select(server.fds(), [], [], 2.0)
    server.poll(0.020)
    ((rec,),) = _drain(c)
    assert rec.counts == (0,) * 6 and rec.rdt_sequence == 1  # biased; a new stream counts from 1
    w2 = [1.5, 2.0, -3.0, 0.1, -0.2, 0.35]
    server.publish(0.021, w2)
    server.poll(0.021)
    ((rec,),) = _drain(c)
    assert rec.counts == tuple(a - b for a, b in zip(rdt.to_counts(w2), rdt.to_counts(w1)))
    c.send(rdt.pack_request(rdt.CMD_STOP))
    select.select(server.fds(), [], [], 2.0)
    for k in range(22, 40):
        server.poll(k * 1e-3)
    assert _drain(c) == []


def test_buffered_mode_packs_records_and_a_new_client_takes_over(server):
    a = _client(server, rdt.CMD_START_BUFFERED)
    server.publish(0.0, [0.0] * 6)
    for k in range(8):
        server.poll(k * 1e-3)
    assert [len(d) for d in _drain(a)] == [4, 4]
    b = _client(server)
    for k in range(8, 12):
        server.poll(k * 1e-3)
    assert _drain(a) == [] and len(_drain(b)) == 4
    a.send(b"\x12\x34\x00")  # a short request: ignored, counted
    select.select(server.fds(), [], [], 2.0)
    server.poll(0.012)
    assert server.stats.bad_requests == 1 and server.streaming_to == b.getsockname()
