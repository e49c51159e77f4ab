"""telemetry.wire: samples batched into one message come back out whole and in order; a cut or
garbled message gives up exactly the damaged frames, never raises."""
from __future__ import annotations

import random
import struct

from hypothesis import given, strategies as st

from telemetry import wire
from telemetry.auth import seal
from telemetry.binary import header
from telemetry.schema import Keys

KEYS = Keys()


def _sample(t: float, n: int) -> bytes:
    """A binary sample: the t/seq header (seq 0) and n bytes of body."""
    return struct.pack("<dQ", t, 0) + bytes(i % 251 for i in range(n))


samples = st.lists(st.builds(_sample, st.floats(0, 100), st.integers(0, 600)), min_size=0, max_size=20)


@given(samples)
def test_binary_batches_split_back_into_their_samples_with_seq_stamped(ss):
    seqs = list(range(100, 100 + len(ss)))
    msg = wire.binary_message(ss, seqs)
    batch = wire.split(msg)
    assert batch.binary and batch.error == "" and len(batch.samples) == len(ss)
    for got, sent, seq in zip(batch.samples, ss, seqs):
        assert header(got) == (header(sent)[0], seq) and got[16:] == sent[16:]
    assert wire.split(wire.binary_message(ss)).samples == ss  # without seqs: as they are
    assert wire.count(msg) == max(1, len(ss))


@given(samples.filter(bool), st.data())
def test_a_cut_message_keeps_its_complete_frames(ss, data):
    msg = wire.binary_message(ss)
    cut = data.draw(st.integers(len(wire.MAGIC), len(msg) - 1))
    batch = wire.split(msg[:cut])
    ends = [len(wire.MAGIC)]
    for s in ss:
        ends.append(ends[-1] + 4 + len(s))
    complete = sum(1 for e in ends[1:] if e <= cut)
    assert batch.samples == ss[:complete]
    assert bool(batch.error) == (cut not in ends)  # the cut fell inside a frame


def test_sealed_messages_split_as_unsealed_ones():
    ss = [_sample(0.1, 40), _sample(0.2, 3)]
    key = bytes(range(32))
    for msg in (wire.binary_message(ss), wire.json_message([b'{"t":0.1,"seq":0}', b'{"t":0.2,"seq":1}'])):
        sealed = seal(key, KEYS.object, msg)
        assert wire.split(sealed) == wire.split(msg)
        assert wire.count(sealed) == 2
    assert wire.split(b'{"t":0.1,"seq":0}') == wire.Batch(False, [b'{"t":0.1,"seq":0}'])


def test_junk_after_the_magic_never_raises():
    rng = random.Random(3)
    for _ in range(3000):
        junk = wire.MAGIC + rng.randbytes(rng.randrange(0, 64))
        batch = wire.split(junk)
        assert batch.binary and all(isinstance(s, bytes) for s in batch.samples)
        assert sum(4 + len(s) for s in batch.samples) <= len(junk) - len(wire.MAGIC)
    assert not wire.is_binary(b"{") and not wire.is_binary(b"") and wire.is_binary(wire.MAGIC)


@given(st.lists(st.tuples(st.sampled_from(["a/x", "a/y", "a/ü", "b"]), st.integers(0, 300)), max_size=30), st.data())
def test_batches_of_several_keys_split_back_into_keyed_samples_and_cuts_keep_a_prefix(items, data):
    keys = [k for k, _ in items]
    ss = [_sample(0.5, n) for _, n in items]
    msg = wire.batch_message(keys, ss, list(range(len(ss))))
    batch = wire.split(msg)
    assert batch.binary and batch.error == "" and batch.keys == keys
    assert [header(s)[1] for s in batch.samples] == list(range(len(ss)))
    assert [s[16:] for s in batch.samples] == [s[16:] for s in ss]
    assert wire.split(seal(bytes(32), KEYS.batch("simulator"), msg)) == batch
    table_end = len(wire.BATCH_MAGIC) + 2 + sum(2 + len(k.encode()) for k in dict.fromkeys(keys))
    ends = [table_end]
    for s in ss:
        ends.append(ends[-1] + 6 + len(s))
    cut = data.draw(st.integers(len(wire.BATCH_MAGIC), len(msg)))
    part = wire.split(msg[:cut])
    complete = sum(1 for e in ends[1:] if e <= cut)
    assert part.keys == keys[:complete] and part.samples == batch.samples[:complete]
    assert (part.error == "") == (cut in ends)  # a cut inside the table or a frame is reported


def test_junk_batches_never_raise():
    rng = random.Random(5)
    for _ in range(3000):
        batch = wire.split(wire.BATCH_MAGIC + rng.randbytes(rng.randrange(0, 80)))
        assert batch.binary and len(batch.keys) == len(batch.samples)


@given(st.integers(16, 600), st.integers(2, 30), st.integers(0, 2**64 - 40))
def test_samples_of_one_length_are_framed_as_one_by_one(size, k, seq0):
    """Equal-length samples take the array path: the same bytes as framing them one at a time."""
    ss = [_sample(i * 0.5, size - 16) for i in range(k)]
    seqs = list(range(seq0, seq0 + k))
    one_by_one = wire.MAGIC + b"".join(struct.pack("<I", size) + s[:8] + struct.pack("<Q", q) + s[16:]
                                       for s, q in zip(ss, seqs))
    assert wire.binary_message(ss, seqs) == one_by_one
    assert wire.binary_message(ss) == wire.MAGIC + b"".join(struct.pack("<I", size) + s for s in ss)
