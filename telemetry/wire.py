"""How samples ride in one zenoh message: JSON lines or length-prefixed binary frames (pure).

A message carries one or more samples of one key, in publish order, in one of two forms:

    JSON:    text \\n text \\n ...                       compact JSON texts (no raw newline inside)
    binary:  MAGIC (len sample) (len sample) ...         len: uint32 little-endian; sample: a ROS 1
                                                         message of telemetry.binary

MAGIC starts with a NUL byte, which no JSON text starts with, so the first bytes tell the two
apart. A sealed message (telemetry.auth) ends with one more line, `\\n#hmac-sha256:<tag>`:
`split` skips it for a recorder without a key; a keyed recorder unseals (and removes it) first.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Iterable, Sequence

from .auth import TAG, TAG_HEX_CHARS

MAGIC = b"\x00AM\x01"  # NUL, "AM", layout version 1
_LEN = struct.Struct("<I")
_SEQ = struct.Struct("<Q")
_SEQ_OFFSET = 8  # telemetry.binary: every binary sample starts with float64 t, uint64 seq
_TRAILER = len(b"\n" + TAG) + TAG_HEX_CHARS


@dataclass
class Batch:
    """The samples of one message. error: why the rest of a binary message was unusable
    (truncated or garbled framing); the samples before that point are kept."""

    binary: bool
    samples: list[bytes] = field(default_factory=list)
    error: str = ""


def json_message(texts: Sequence[bytes]) -> bytes:
    return b"\n".join(texts)


def binary_message(samples: Iterable[bytes], seqs: Iterable[int] | None = None) -> bytes:
    """Frame binary samples into one message; with `seqs`, each sample's seq field is set on
    the way (the publisher owns the counters; the builders leave seq at 0)."""
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


def is_binary(message: bytes) -> bool:
    return message[:len(MAGIC)] == MAGIC


def split(message: bytes) -> Batch:
    """The samples of a message (the tag line of a sealed one skipped)."""
    if not is_binary(message):
        return Batch(False, [line for line in message.split(b"\n") if not line.startswith(TAG)])
    out = Batch(True)
    off, end = len(MAGIC), len(message)
    while off < end:
        if end - off == _TRAILER and message[off:off + 1 + len(TAG)] == b"\n" + TAG:
            break  # a sealed message's tag line
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


def count(message: bytes) -> int:
    """How many samples a message carries as far as its framing says (at least 1): for
    counting the samples of a rejected message."""
    return max(1, len(split(message).samples))
