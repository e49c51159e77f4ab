"""The motion capture's UDP stream of rigid-body poses, defined once for both ends: the
simulator's sender (`simulator.mocap_stream`) and the companion's client
(`companion.devices.mocap`). Pure: no I/O.

A fixed binary layout of our own (documented here and in docs/devices.md), in the spirit of
the rigid-body part of a VRPN tracker report or a NatNet frame without their session
machinery. Little-endian, no padding:

  frame datagram, 76 bytes:
    offset size  type         field
    0      4     char[4]      magic  b"AMMC"
    4      1     uint8        version (1)
    5      1     uint8        flags  (bit 0: tracked; 0 = the body was not seen in this frame)
    6      2     uint16       body_id (0 = the object)
    8      4     uint32       frame  (the stream's frame counter, +1 per frame, wraps)
    12     8     uint64       time_us (capture time [us] on the sender's clock)
    20     24    float64[3]   p_W  [m], position of the body in the world frame W (ENU)
    44     32    float64[4]   q_W  (w, x, y, z), attitude W <- body, unit norm

  subscribe datagram, 8 bytes (client -> sender):
    0 char[4] magic b"AMMS", 4 uint8 version (1), 5..7 zero

A client subscribes by sending a subscribe datagram to the stream's port; the sender then
sends every frame to the address the subscription came from, for as long as subscriptions
keep coming (a client repeats it every SUBSCRIBE_PERIOD_S; the sender forgets one after
SUBSCRIPTION_TIMEOUT_S). The sender may also send to configured destinations (a client
listening on its own port). Default stream: UDP 127.0.0.1:7400 (one stream for the scene).
"""
from __future__ import annotations

import math
import struct
from typing import NamedTuple

MOCAP_PORT = 7400
MAGIC_FRAME, MAGIC_SUBSCRIBE = b"AMMC", b"AMMS"
VERSION = 1
FLAG_TRACKED = 0x01
OBJECT_BODY_ID = 0
SUBSCRIBE_PERIOD_S = 1.0
SUBSCRIPTION_TIMEOUT_S = 5.0

_FRAME = struct.Struct("<4sBBHIQ3d4d")
_SUBSCRIBE = struct.Struct("<4sB3x")
FRAME_SIZE, SUBSCRIBE_SIZE = _FRAME.size, _SUBSCRIBE.size  # 76, 8


class PoseFrame(NamedTuple):
    frame: int
    time_us: int
    body_id: int
    tracked: bool
    p_W: tuple[float, float, float]  # [m], ENU
    q_W_wxyz: tuple[float, float, float, float]


def pack_frame(f: PoseFrame) -> bytes:
    return _FRAME.pack(MAGIC_FRAME, VERSION, FLAG_TRACKED if f.tracked else 0, f.body_id, f.frame & 0xFFFFFFFF,
                       f.time_us, *f.p_W, *f.q_W_wxyz)


def unpack_frame(data: bytes) -> PoseFrame:
    """A frame datagram; ValueError naming what is wrong (size, magic, version, values)."""
    if len(data) != FRAME_SIZE:
        raise ValueError(f"mocap frame of {len(data)} bytes, expected {FRAME_SIZE}")
    magic, version, flags, body, frame, t_us, *v = _FRAME.unpack(data)
    if magic != MAGIC_FRAME:
        raise ValueError(f"mocap frame magic {magic!r}, expected {MAGIC_FRAME!r}")
    if version != VERSION:
        raise ValueError(f"mocap frame version {version}, expected {VERSION}")
    if not all(math.isfinite(x) for x in v):
        raise ValueError("mocap frame with a non-finite position or attitude")
    q = tuple(v[3:7])
    if abs(math.sqrt(sum(x * x for x in q)) - 1.0) > 1e-6 and flags & FLAG_TRACKED:
        raise ValueError(f"mocap frame attitude {q} is not a unit quaternion")
    return PoseFrame(frame, t_us, body, bool(flags & FLAG_TRACKED), tuple(v[0:3]), q)


def pack_subscribe() -> bytes:
    return _SUBSCRIBE.pack(MAGIC_SUBSCRIBE, VERSION)


def is_subscribe(data: bytes) -> bool:
    return len(data) == SUBSCRIBE_SIZE and data[:4] == MAGIC_SUBSCRIBE and data[4] == VERSION


