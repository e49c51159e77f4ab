"""A seeded datagram fuzzer for the link tests: junk, mutated captures, forged frames."""

from __future__ import annotations

import random
import struct
from collections import Counter
from collections.abc import Callable

from amlink import codec
from amlink.codec import mav
from amlink.wire import HEADER_LEN, frame_crc, split_frames

BAD_F64 = [struct.pack("<d", v) for v in (float("nan"), float("inf"), float("-inf"), 1e300, -1e300)]
BAD_F32 = [struct.pack("<f", v) for v in (float("nan"), float("inf"), float("-inf"), 3e38, -3e38)]
_STEP_FIRST = {mav.MAVLINK_MSG_ID_AM_TORQUE_SETPOINT, mav.MAVLINK_MSG_ID_AM_SIM_STEP,
               mav.MAVLINK_MSG_ID_AM_JOINT_STATE, mav.MAVLINK_MSG_ID_AM_WRENCH}  # fmt: skip


def _with_crc(frame: bytearray) -> bytearray:
    plen = frame[1]
    frame[HEADER_LEN + plen : HEADER_LEN + plen + 2] = frame_crc(bytes(frame)).to_bytes(2, "little")
    return frame


class Fuzzer:
    """Makes fuzz datagrams from ``captured`` genuine traffic and a ``forge`` callback.

    Args:
        rng: the only source of randomness (same seed, same datagrams).
        captured: genuine datagrams of the peer being impersonated (grows as the run goes).
        forge: ``forge(rng, step) -> bytes``: a freshly encoded frame the fuzzer could
            build itself (no key, or a wrong one).
        tamper_steps: also rewrite step fields with a valid CRC (only where the
            receiver can tell: signing on).
    """

    def __init__(self, rng: random.Random, captured: list[bytes], forge: Callable[[random.Random, int], bytes],
                 tamper_steps: bool = True) -> None:  # fmt: skip
        self.rng = rng
        self.captured = captured
        self.forge = forge
        self.kinds = [
            ("random", 30, self._random), ("random_header", 6, self._random_header),
            ("bitflip", 14, self._bitflip), ("truncate", 8, self._truncate), ("oversize", 3, self._oversize),
            ("bad_value", 14, self._bad_value), ("sysid", 5, self._sysid), ("unknown_msgid", 3, self._unknown_id),
            ("mavlink1", 2, self._mavlink1), ("replay", 5, self._replay), ("forged", 10, self._forged),
        ]  # fmt: skip
        if tamper_steps:
            self.kinds.append(("step", 6, self._step))
        self._names = [k[0] for k in self.kinds]
        self._weights = [k[1] for k in self.kinds]
        self._makers = {k[0]: k[2] for k in self.kinds}
        self.made: Counter[str] = Counter()

    def batch(self, n: int, step: int) -> list[bytes]:
        names = self.rng.choices(self._names, self._weights, k=n)
        self.made.update(names)
        return [self._makers[name](step) for name in names]

    # -- kinds ---------------------------------------------------------------------
    def _random(self, step):
        return self.rng.randbytes(self.rng.randrange(0, 300))

    def _random_header(self, step):  # gets past the magic byte check
        return bytes((0xFD, self.rng.randrange(256), self.rng.choice((0, 1)))) + self.rng.randbytes(
            self.rng.randrange(9, 300))

    def _frame(self) -> tuple[bytes, int, list[bytes]]:
        frames = split_frames(self.rng.choice(self.captured))
        return frames, self.rng.randrange(len(frames)), frames

    def _join(self, frames, i, new) -> bytes:
        return b"".join(frames[:i]) + bytes(new) + b"".join(frames[i + 1 :])

    def _bitflip(self, step):
        data = bytearray(self.rng.choice(self.captured))
        for _ in range(self.rng.randrange(1, 4)):
            data[self.rng.randrange(len(data))] ^= 1 << self.rng.randrange(8)
        return bytes(data)

    def _truncate(self, step):
        data = self.rng.choice(self.captured)
        return data[: self.rng.randrange(len(data))]

    def _oversize(self, step):
        data = self.rng.choice(self.captured)
        if self.rng.random() < 0.05:  # up to the largest UDP payload (65507 bytes)
            return data + self.rng.randbytes(self.rng.randrange(1500, 65507 - len(data)))
        return data + self.rng.randbytes(self.rng.randrange(1, 400))

    def _bad_value(self, step):
        frames, i, _ = self._frame()
        f = bytearray(frames[i])
        plen = f[1]
        if plen >= 8 and self.rng.random() < 0.6:
            at = HEADER_LEN + 8 * self.rng.randrange(plen // 8)
            f[at : at + 8] = self.rng.choice(BAD_F64)
        elif plen >= 4:
            at = HEADER_LEN + 4 * self.rng.randrange(plen // 4)
            f[at : at + 4] = self.rng.choice(BAD_F32)
        return self._join(frames, i, _with_crc(f))

    def _sysid(self, step):
        frames, i, _ = self._frame()
        f = bytearray(frames[i])
        f[5] = self.rng.randrange(256)
        return self._join(frames, i, _with_crc(f))

    def _step(self, step):
        frames, i, _ = self._frame()
        f = bytearray(frames[i])
        msgid = f[7] | f[8] << 8 | f[9] << 16
        if msgid in _STEP_FIRST and f[1] >= 8:
            f[HEADER_LEN : HEADER_LEN + 8] = max(0, step + self.rng.randrange(-2, 4)).to_bytes(8, "little", signed=False)
        return self._join(frames, i, _with_crc(f))

    def _unknown_id(self, step):
        frames, i, _ = self._frame()
        f = bytearray(frames[i])
        while True:
            mid = self.rng.randrange(1 << 24)
            if mid not in mav.mavlink_map:
                break
        f[7:10] = mid.to_bytes(3, "little")
        plen = f[1]
        f[HEADER_LEN + plen : HEADER_LEN + plen + 2] = self.rng.randbytes(2)  # no CRC_EXTRA to compute with
        return self._join(frames, i, f)

    def _mavlink1(self, step):
        m = mav.MAVLink(None, srcSystem=self.rng.randrange(1, 256), srcComponent=191)
        return mav.MAVLink_heartbeat_message(18, 8, 0, 0, 4, 3).pack(m, force_mavlink1=True)

    def _replay(self, step):
        return self.rng.choice(self.captured)

    def _forged(self, step):
        return self.forge(self.rng, step)


def encoder_pool(sysids, keys: dict[int, bytes | None], compid: int) -> dict[tuple[int, object], codec.Encoder]:
    """Encoders a fuzzer may use: per sysid, unsigned and signed with each given (wrong) key."""
    pool = {}
    for s in sysids:
        for name, key in keys.items():
            pool[(s, name)] = codec.Encoder(s, compid, signing_key=key, link_id=s)
    return pool
