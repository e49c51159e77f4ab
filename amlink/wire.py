"""Byte level of the link: datagram <-> MAVLink 2 frames, with optional MAVLink 2 signing.

One datagram carries whole, concatenated MAVLink 2 frames (UDP never splits
them), so :class:`Decoder` frames strictly: the datagram must start with a frame
and each frame must end where the next begins.  Cheap checks run first so junk
costs a few microseconds: magic byte, incompatibility flags, length, known
message id, CRC (with CRC_EXTRA), then -- signing on -- signed at all, a key for
the claimed sysid, fresh, signature; only then the payload is unpacked.

Two ways out of the same checks.  :meth:`Decoder.feed` returns pymavlink
message objects (``MAVLink.decode``), for tools, tests and rare messages.
:meth:`Decoder.feed_records` returns ``(msgid, sysid, compid, body)`` records
whose ``body``, for the ids it was given *readers* for (the lockstep batches,
:mod:`amlink.codec`), is a plain tuple unpacked by a precompiled
``struct.Struct`` -- no message object on the 1 kHz path -- and a pymavlink
message otherwise.  Likewise :meth:`Encoder.pack` frames pymavlink messages and
:meth:`Encoder.pack_payloads` frames ready payloads, bit for bit as pymavlink
would (MAVLink 2 trailing-zero truncation, CRC_EXTRA, signing), sharing the
sequence number and signing timestamp of the same link.

Signing uses pymavlink's ``MAVLink.signing`` state (``secret_key``, ``link_id``,
``timestamp``, ``sign_outgoing``, ``stream_timestamps``); outgoing frames are
signed as pymavlink's ``sign_packet`` does, with one correction on the receive side:
:meth:`Decoder._authentic` replaces ``MAVLink.check_signature`` and records a
stream's timestamp only AFTER the signature verified.  pymavlink 2.4.x records
it first, so one forged packet carrying a far-future timestamp and a wrong
signature makes every later genuine packet of that stream look like a replay
(tests/amlink/test_signing.py shows it).

Timestamps follow the MAVLink 2 signing spec: units of 10 us since
2015-01-01T00:00:00Z; :func:`now_timestamp` is the wall clock in those units.  Both
ends must have clocks within 60 s of each other (NTP), or a new stream is taken as
a replay of old traffic and rejected.
Keys (formats, derivation, key files) are :mod:`amlink.signing`'s.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
import time
from collections.abc import Callable, Iterable, Mapping

from amlink import dialect
from amlink.signing import check_key

mav = dialect.load()

MAGIC_V2 = 0xFD
HEADER_LEN = 10  # MAVLink 2 header, magic included
CRC_LEN = 2
SIGNATURE_LEN = 13  # link id (1), timestamp (6), signature (6)
IFLAG_SIGNED = 0x01
_MIN_FRAME = HEADER_LEN + CRC_LEN
_CRC_EXTRA = {mid: bytes((cls.crc_extra,)) for mid, cls in mav.mavlink_map.items()}
# fastcrc's CRC-16/MCRF4XX when installed (a dependency), else dialect.mcrf4xx
_mcrf4xx = mav.mcrf4xx or dialect.mcrf4xx
_HEADER = struct.Struct("<BBBBBBBHB")  # magic, len, incompat, compat, seq, sysid, compid, msgid (24 bit)
_SIGN_PREFIX = struct.Struct("<BQ")  # link id, timestamp: the first 7 bytes are the signature block's
MAVLINK_EPOCH_UNIX_S = 1420070400  # 2015-01-01T00:00:00Z
NEW_STREAM_WINDOW = 6000 * 1000  # 60 s in 10 us units: as pymavlink and the MAVLink spec

Reader = Callable[[bytes, int, int], tuple]
"""``read(datagram, payload_start, payload_len) -> tuple`` (see :class:`amlink.codec.Reader`)."""


def now_timestamp() -> int:
    """MAVLink 2 signing timestamp of the wall clock now [10 us since 2015-01-01 UTC]."""
    return int((time.time() - MAVLINK_EPOCH_UNIX_S) * 1e5)


class CodecError(ValueError):
    """Base class of encode/decode errors."""


class EncodeError(CodecError):
    """A value cannot be put on the wire (non-finite, out of range)."""


def frame_crc(frame: bytes) -> int:
    """The CRC a MAVLink 2 frame (header + payload, CRC and signature optional) must carry."""
    msgid = frame[7] | frame[8] << 8 | frame[9] << 16
    plen = frame[1]
    return _mcrf4xx(bytes(frame[1 : HEADER_LEN + plen]) + _CRC_EXTRA[msgid])


def split_frames(datagram: bytes) -> list[bytes]:
    """Whole MAVLink 2 frames of a well-formed datagram (tests and tools; no checks)."""
    out, i = [], 0
    while i + _MIN_FRAME <= len(datagram):
        end = i + _MIN_FRAME + datagram[i + 1] + (SIGNATURE_LEN if datagram[i + 2] & IFLAG_SIGNED else 0)
        out.append(datagram[i:end])
        i = end
    return out


class StreamFramer:
    """Cuts a byte stream (TCP, serial) into whole MAVLink 2 frames.

    :meth:`feed` takes the bytes just read and returns the frames they complete,
    concatenated -- what :class:`Decoder` takes as one datagram; a partial frame waits
    for the next call.  Bytes that do not begin a frame whose CRC checks (line noise, a
    MAVLink 1 frame, a false magic byte) are skipped one at a time until the stream is in
    step again, and counted in :attr:`junk_bytes`.  A frame of a message id unknown to the
    dialect cannot be checked, so it counts as junk too: passing it on whole could swallow
    the genuine frames behind a false magic byte.  The CRC does not cover a signature: a
    frame cut off inside its signature is taken whole, with the first bytes of the next
    frame; the decoder rejects it, and that next frame is lost too.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.junk_bytes = 0

    def feed(self, data: bytes) -> bytes:
        buf = self._buf
        buf += data
        n, i, out = len(buf), 0, []
        while i < n:
            j = buf.find(MAGIC_V2, i)
            if j < 0:
                self.junk_bytes += n - i
                i = n
                break
            self.junk_bytes += j - i
            i = j
            if n - i < HEADER_LEN:
                break  # the header is not all here yet
            if buf[i + 2] & ~IFLAG_SIGNED:
                self.junk_bytes += 1
                i += 1
                continue
            crc_at = i + HEADER_LEN + buf[i + 1]
            end = crc_at + CRC_LEN + (SIGNATURE_LEN if buf[i + 2] & IFLAG_SIGNED else 0)
            if end > n:
                break  # the rest of the frame is still on its way
            extra = _CRC_EXTRA.get(buf[i + 7] | buf[i + 8] << 8 | buf[i + 9] << 16)
            if extra is None or _mcrf4xx(bytes(buf[i + 1 : crc_at]) + extra) != buf[crc_at] | buf[crc_at + 1] << 8:
                self.junk_bytes += 1
                i += 1
                continue
            out.append(bytes(buf[i:end]))
            i = end
        del buf[:i]
        return b"".join(out)


class _Sink:
    """File-like target for MAVLink.send that collects frames for one datagram."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []

    def write(self, data: bytes) -> None:
        self.parts.append(data)


class Encoder:
    """Packs messages as (sysid, compid) on one link; owns the MAVLink sequence number.

    With ``signing_key`` (32 bytes) every frame is signed on link ``link_id``
    (0..255); the signing timestamp never falls behind the wall clock, so a
    restarted process continues its stream where the old one stopped.
    """

    def __init__(self, sysid: int, compid: int, *, signing_key: bytes | None = None, link_id: int = 0) -> None:
        self._sink = _Sink()
        self.mavlink = mav.MAVLink(self._sink, srcSystem=sysid, srcComponent=compid)
        if signing_key is not None:
            s = self.mavlink.signing
            s.secret_key = check_key(signing_key)
            s.link_id = link_id & 0xFF
            s.sign_outgoing = True
            s.timestamp = now_timestamp()

    @property
    def signing(self) -> bool:
        return self.mavlink.signing.sign_outgoing

    def pack(self, msgs) -> bytes:
        """Serialize ``msgs`` into one datagram (concatenated MAVLink 2 frames)."""
        sink = self._sink
        s = self.mavlink.signing
        if s.sign_outgoing:
            s.timestamp = max(s.timestamp, now_timestamp())
        try:
            for m in msgs:
                self.mavlink.send(m)
        except (struct.error, OverflowError) as exc:
            sink.parts.clear()
            raise EncodeError(f"cannot pack {m.msgname}: {exc}") from exc
        data = b"".join(sink.parts)
        sink.parts.clear()
        return data

    def pack_payloads(self, payloads: Iterable[tuple[int, bytes]]) -> bytes:
        """Frame ``(msgid, payload)`` pairs into one datagram, exactly as :meth:`pack` frames messages.

        ``payload`` is the full packed payload of ``msgid`` (trailing zeros are
        dropped here, keeping at least one byte, as MAVLink 2 and pymavlink do).
        Shares the sequence number and signing state with :meth:`pack`.
        """
        m = self.mavlink
        s = m.signing
        signed = s.sign_outgoing
        if signed:
            s.timestamp = max(s.timestamp, now_timestamp())
            key, link_id = s.secret_key, s.link_id
        iflags = IFLAG_SIGNED if signed else 0
        seq, sysid, compid = m.seq, m.srcSystem, m.srcComponent
        frames = []
        for msgid, payload in payloads:
            body = payload.rstrip(b"\x00") or payload[:1]
            frame = _HEADER.pack(MAGIC_V2, len(body), iflags, 0, seq, sysid, compid, msgid & 0xFFFF, msgid >> 16) + body
            frame += _mcrf4xx(frame[1:] + _CRC_EXTRA[msgid]).to_bytes(2, "little")
            if signed:
                frame += _SIGN_PREFIX.pack(link_id, s.timestamp)[:7]
                frame += hashlib.sha256(key + frame).digest()[:6]
                s.timestamp += 1
            frames.append(frame)
            seq = (seq + 1) % 256
        data = b"".join(frames)
        m.seq = seq
        m.total_packets_sent += len(frames)
        m.total_bytes_sent += len(data)
        return data


class Decoder:
    """Parses datagrams into messages; corrupt, unauthenticated and replayed frames are counted.

    Args:
        keys: ``None`` -- signing off, unsigned and signed frames accepted
            (signatures unchecked).  A mapping ``sysid -> 32-byte key`` -- signing
            on: a frame is accepted only if signed with the key of the sysid it
            claims and newer than the last frame of its stream
            ``(link_id, sysid, compid)``.
        accept: message ids to decode; others (valid CRC) are counted as
            ``ignored`` without the cost of unpacking.  ``None``: all.
        counters: object whose counter attributes (``bad_frames``,
            ``unknown_sysid``, ``unsigned``, ``bad_signature``, ``replayed``,
            ``ignored``) are incremented, e.g. a :class:`amlink.protocol.LinkStats`;
            default: this decoder's own attributes.
        readers: ``msgid -> read(datagram, payload_start, payload_len) -> tuple``
            used by :meth:`feed_records` (e.g. :data:`amlink.codec.READERS`).
    """

    bad_frames = unknown_sysid = unsigned = bad_signature = replayed = ignored = 0

    def __init__(self, keys: Mapping[int, bytes] | None = None, *, accept=None, counters=None,
                 readers: Mapping[int, Reader] | None = None) -> None:  # fmt: skip
        self._c = self if counters is None else counters
        self._readers = dict(readers or {})
        self._keys = None if keys is None else {int(s): check_key(k) for s, k in keys.items()}
        self._accept = None if accept is None else frozenset(accept)
        self._plain = mav.MAVLink(None)
        self._parsers: dict[int, object] = {}

    @property
    def signing(self) -> bool:
        return self._keys is not None

    def feed(self, datagram: bytes) -> list:
        """All valid (and, signing on, authentic and fresh) messages in ``datagram``, in order."""
        return self._feed(datagram, None)

    def feed_records(self, datagram: bytes) -> list[tuple[int, int, int, object]]:
        """As :meth:`feed`, as ``(msgid, sysid, compid, body)``; see the module docstring.

        Same checks and counters as :meth:`feed`; ``body`` is the reader's tuple
        for ids with a reader, else the pymavlink message.
        """
        return self._feed(datagram, self._readers)

    def _feed(self, datagram: bytes, readers: dict[int, Reader] | None) -> list:
        c, keys, accept = self._c, self._keys, self._accept
        out = []
        n, i = len(datagram), 0
        while i < n:
            if n - i < _MIN_FRAME or datagram[i] != MAGIC_V2 or datagram[i + 2] & ~IFLAG_SIGNED:
                c.bad_frames += 1  # junk, MAVLink 1, or unknown incompat flags: drop the rest
                break
            plen = datagram[i + 1]
            signed = datagram[i + 2] & IFLAG_SIGNED
            crc_at = i + HEADER_LEN + plen
            end = crc_at + CRC_LEN + (SIGNATURE_LEN if signed else 0)
            if end > n:
                c.bad_frames += 1  # truncated
                break
            start, i = i, end
            msgid = datagram[start + 7] | datagram[start + 8] << 8 | datagram[start + 9] << 16
            crc_extra = _CRC_EXTRA.get(msgid)
            if crc_extra is None:
                c.bad_frames += 1
                continue
            if _mcrf4xx(datagram[start + 1 : crc_at] + crc_extra) != datagram[crc_at] | datagram[crc_at + 1] << 8:
                c.bad_frames += 1
                continue
            if accept is not None and msgid not in accept:
                c.ignored += 1
                continue
            if keys is None:
                parser = self._plain
            elif not signed:
                c.unsigned += 1
                continue
            else:
                parser = self._parser(datagram[start + 5])
                if parser is None:
                    c.unknown_sysid += 1
                    continue
                if not self._authentic(parser, datagram, start, end):
                    continue
            if readers is not None:
                read = readers.get(msgid)
                if read is not None:  # cannot fail: framing and CRC are checked, short payloads padded
                    body = read(datagram, start + HEADER_LEN, plen)
                    out.append((msgid, datagram[start + 5], datagram[start + 6], body))
                    continue
            try:
                msg = parser.decode(bytearray(datagram[start:end]))
            except Exception:  # MAVError, or anything odd in pymavlink's unpacking
                c.bad_frames += 1
                continue
            out.append(msg if readers is None else (msgid, datagram[start + 5], datagram[start + 6], msg))
        return out

    def _parser(self, sysid: int):
        p = self._parsers.get(sysid)
        if p is None:
            key = self._keys.get(sysid)
            if key is None:
                return None
            p = mav.MAVLink(None)
            p.signing.secret_key = key
            p.signing.timestamp = now_timestamp()
            p.check_signature = _verified  # decode() only sees frames _authentic() passed
            self._parsers[sysid] = p
        return p

    def _authentic(self, parser, data: bytes, start: int, end: int) -> bool:
        """Freshness, then signature; records the stream's timestamp only for an authentic frame.

        Replaces ``MAVLink.check_signature`` (see the module docstring).  The
        freshness test comes first because it is cheap and rejecting changes
        no state; a forged frame with an old timestamp is counted as replayed.
        """
        s = parser.signing
        timestamp = int.from_bytes(data[end - 12 : end - 6], "little")
        stream = (data[end - 13], data[start + 5], data[start + 6])  # (link id, sysid, compid)
        last = s.stream_timestamps.get(stream)
        if (timestamp <= last) if last is not None else (timestamp + NEW_STREAM_WINDOW < s.timestamp):
            self._c.replayed += 1
            return False
        expect = hashlib.sha256(s.secret_key + data[start : end - 6]).digest()[:6]
        if not hmac.compare_digest(expect, data[end - 6 : end]):
            self._c.bad_signature += 1
            return False
        s.stream_timestamps[stream] = timestamp
        s.timestamp = max(s.timestamp, timestamp)
        return True


def _verified(msgbuf, src_system, src_component) -> bool:
    return True
