"""How samples ride in one zenoh message: JSON lines or length-prefixed binary frames (pure).

A message carries one or more samples, in publish order, in one of three forms:

    JSON:    text \\n text \\n ...                 samples of the message's key: compact JSON
                                                   texts (no raw newline inside)
    binary:  MAGIC (len sample)...                 samples of the message's key; len: uint32
                                                   little-endian; sample: a ROS 1 message of
                                                   telemetry.binary
    batch:   BATCH_MAGIC n (klen key)*n            on <p>/batch/<name>: binary samples of several
             (index len sample)...                 keys; n, klen, index: uint16; key: UTF-8; index:
                                                   the sample's key in the table

A publisher whose binary samples interleave keys (the simulator: truth, contact of each AM,
then the object, every step) sends them as one batch per wake-up instead of a message per
sample: zenoh's cost is per message. The magics start with a NUL byte, which no JSON text
starts with, so the first bytes tell the forms apart. A sealed message (telemetry.auth) ends
with one more line, `\\n#hmac-sha256:<tag>`: `split` skips it for a recorder without a key; a
keyed recorder unseals (and removes it) first.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from .auth import TAG, TAG_HEX_CHARS

MAGIC = b"\x00AM\x01"  # NUL, "AM", layout version 1
BATCH_MAGIC = b"\x00AB\x01"
_LEN = struct.Struct("<I")
_U16 = struct.Struct("<H")
_INDEX_LEN = struct.Struct("<HI")
_SEQ = struct.Struct("<Q")
_SEQ_OFFSET = 8  # telemetry.binary: every binary sample starts with float64 t, uint64 seq
_TRAILER = len(b"\n" + TAG) + TAG_HEX_CHARS


@dataclass
class Batch:
    """The samples of one message. keys: each sample's key (a batch message), or None (the
    samples of the message's own key). error: why the rest of a binary message was unusable
    (truncated or garbled framing); the samples before that point are kept."""

    binary: bool
    samples: list[bytes] = field(default_factory=list)
    error: str = ""
    keys: list[str] | None = None


def json_message(texts: Sequence[bytes]) -> bytes:
    return b"\n".join(texts)


def binary_message(samples: Sequence[bytes], seqs: Sequence[int] | None = None) -> bytes:
    """Frame binary samples into one message; with `seqs`, each sample's seq field is set on
    the way (the publisher owns the counters; the builders leave seq at 0). Samples of one
    length (a companion's ~100 controller samples of a wake-up) are framed as the rows of
    one array, without a Python step per sample."""
    if seqs is not None and len(seqs) != len(samples):
        raise ValueError(f"{len(samples)} samples and {len(seqs)} seq numbers")
    size = len(samples[0]) if samples else 0
    if len(samples) > 1 and size >= _SEQ_OFFSET + _SEQ.size and all(len(d) == size for d in samples):
        frames = np.empty((len(samples), _LEN.size + size), np.uint8)
        frames[:, :_LEN.size] = np.frombuffer(_LEN.pack(size), np.uint8)
        frames[:, _LEN.size:] = np.frombuffer(b"".join(samples), np.uint8).reshape(len(samples), size)
        if seqs is not None:
            at = _LEN.size + _SEQ_OFFSET
            frames[:, at:at + _SEQ.size] = np.asarray(seqs, "<u8").view(np.uint8).reshape(-1, _SEQ.size)
        return MAGIC + frames.tobytes()
    buf = bytearray(MAGIC)
    if seqs is None:
        for data in samples:
            buf += _LEN.pack(len(data))
            buf += data
        return bytes(buf)
    for data, seq in zip(samples, seqs, strict=True):
        buf += _LEN.pack(len(data))
        at = len(buf)
        buf += data
        _SEQ.pack_into(buf, at + _SEQ_OFFSET, seq)
    return bytes(buf)


def batch_message(keys: Sequence[str], samples: Sequence[bytes], seqs: Sequence[int]) -> bytes:
    """Binary samples of several keys (keys[i] is samples[i]'s) in one batch message, each
    sample's seq field set on the way."""
    table: dict[str, int] = {}
    for k in keys:
        table.setdefault(k, len(table))
    buf = bytearray(BATCH_MAGIC)
    buf += _U16.pack(len(table))
    for k in table:
        kb = k.encode("utf-8")
        buf += _U16.pack(len(kb))
        buf += kb
    for k, data, seq in zip(keys, samples, seqs, strict=True):
        buf += _INDEX_LEN.pack(table[k], len(data))
        at = len(buf)
        buf += data
        _SEQ.pack_into(buf, at + _SEQ_OFFSET, seq)
    return bytes(buf)


def is_binary(message: bytes) -> bool:
    """A binary message of one key or a batch (not JSON)."""
    return message[:len(MAGIC)] in (MAGIC, BATCH_MAGIC)


def split(message: bytes) -> Batch:
    """The samples of a message (the tag line of a sealed one skipped)."""
    head = message[:len(MAGIC)]
    if head == BATCH_MAGIC:
        return _split_batch(message)
    if head != MAGIC:
        return Batch(False, [line for line in message.split(b"\n") if not line.startswith(TAG)])
    out = Batch(True)
    off, end = len(MAGIC), len(message)
    while off < end:
        if _is_trailer(message, off):
            break
        if end - off < _LEN.size:
            out.error = f"{end - off} bytes after the last frame"
            break
        (n,) = _LEN.unpack_from(message, off)
        off += _LEN.size
        if n > end - off:
            out.error = f"a frame of {n} bytes, {end - off} left: truncated"
            break
        out.samples.append(message[off:off + n])
        off += n
    return out


def _is_trailer(message: bytes, off: int) -> bool:
    """A sealed message's tag line starts at `off` and ends the message."""
    return len(message) - off == _TRAILER and message[off:off + 1 + len(TAG)] == b"\n" + TAG


def _split_batch(message: bytes) -> Batch:
    out = Batch(True, keys=[])
    off, end = len(BATCH_MAGIC), len(message)
    table = []
    try:
        (n,) = _U16.unpack_from(message, off)
        off += _U16.size
        for _ in range(n):
            (k,) = _U16.unpack_from(message, off)
            off += _U16.size
            if k > end - off:
                raise ValueError("a key longer than the message")
            table.append(bytes(message[off:off + k]).decode("utf-8"))
            off += k
    except (struct.error, ValueError) as exc:  # UnicodeDecodeError is a ValueError
        out.error = f"a garbled key table: {exc}"
        return out
    while off < end:
        if _is_trailer(message, off):
            break
        if end - off < _INDEX_LEN.size:
            out.error = f"{end - off} bytes after the last frame"
            break
        i, size = _INDEX_LEN.unpack_from(message, off)
        off += _INDEX_LEN.size
        if size > end - off or i >= len(table):
            out.error = (f"a frame of {size} bytes, {end - off} left: truncated" if size > end - off
                         else f"key index {i} of a table of {len(table)}")
            break
        out.keys.append(table[i])
        out.samples.append(message[off:off + size])
        off += size
    return out


def count(message: bytes) -> int:
    """How many samples a message carries as far as its framing says (at least 1): for
    counting the samples of a rejected message."""
    return max(1, len(split(message).samples))
