"""Payload layouts derived from the generated dialect: they match pymavlink's structs for every message."""

from __future__ import annotations

import random
import struct

import pytest

from amlink import dialect, wire
from amlink.codec import LayoutError, MessageLayout

mav = dialect.load()
ALL = sorted(mav.mavlink_map.items())


def _random_values(layout: MessageLayout, rng: random.Random) -> list:
    """One value per struct item of the full payload, in wire order (floats exactly representable)."""
    out = []
    for f in layout.fields:
        count, code = (f.token[:-1], f.token[-1])
        n = int(count) if count else 1
        if code == "s":
            out.append(bytes(rng.randrange(1, 128) for _ in range(n)))
            continue
        for _ in range(n):
            if code in "fd":
                out.append(rng.randrange(-(2**20), 2**20) / 64)
            else:
                size = struct.calcsize(code)
                signed = code.islower()
                lo, hi = (-(2 ** (8 * size - 1)), 2 ** (8 * size - 1)) if signed else (0, 2 ** (8 * size))
                out.append(rng.randrange(lo, hi))
    return out


def test_every_message_layout_matches_pymavlink_struct():
    assert len(ALL) > 200  # common.xml and ours
    for msgid, cls in ALL:
        layout = MessageLayout.of(cls)
        assert (layout.msgid, layout.name, layout.crc_extra) == (msgid, cls.msgname, cls.crc_extra)
        assert layout.size == cls.unpacker.size
        assert [f.name for f in layout.fields] == list(cls.ordered_fieldnames)
        full = layout.reader(*cls.ordered_fieldnames)
        assert full.struct.format == cls.unpacker.format and full.struct.size == cls.unpacker.size


def test_packer_and_reader_agree_with_pymavlink_payloads():
    rng = random.Random(1)
    for _msgid, cls in ALL:
        layout = MessageLayout.of(cls)
        values = _random_values(layout, rng)
        payload = cls.unpacker.pack(*values)
        assert layout.packer(*cls.ordered_fieldnames).pack(*values) == payload
        assert layout.reader(*cls.ordered_fieldnames).read(payload, 0, len(payload)) == cls.unpacker.unpack(payload)
        # a subset: the last field alone, read at an offset inside a bigger buffer
        last = layout.fields[-1]
        got = layout.reader(last.name).read(b"\xaa" * 7 + payload + b"\xbb" * 3, 7, len(payload))
        assert got == struct.unpack_from("<" + last.token, payload, last.offset)


def test_reader_zero_pads_a_truncated_payload_and_ignores_extra_bytes():
    layout = MessageLayout.of(mav.MAVLink_am_torque_setpoint_message)
    read = layout.reader("step", "thrust_n", "n_joints", "flags").read
    payload = struct.pack("<Qd3d8dBB", 5, 2.5, 0, 0, 0, *[0.0] * 8, 0, 0)
    short = payload.rstrip(b"\x00")
    assert read(short + b"\xff\xff", 0, len(short)) == (5, 2.5, 0, 0)  # bytes past the payload are not read
    assert read(payload + b"\x07" * 9, 0, len(payload) + 9) == (5, 2.5, 0, 0)


def test_packer_zero_fills_trailing_fields_not_fixed():
    layout = MessageLayout.of(mav.MAVLink_odometry_message)
    payload = layout.packer("time_usec", frame_id=4).pack(9)
    assert payload == mav.MAVLink_odometry_message.unpacker.pack(9, *[0.0] * 55, 4, 0, 0, 0, 0)


def test_packer_fixes_trailing_fields_once():
    layout = MessageLayout.of(mav.MAVLink_set_attitude_target_message)
    packer = layout.packer("time_boot_ms", "q", "body_roll_rate", "body_pitch_rate", "body_yaw_rate", "thrust",
                           "target_system", "target_component", type_mask=7)  # fmt: skip
    msg = mav.MAVLink_set_attitude_target_message(12, 1, 2, 7, [1.0, 0.0, 0.0, 0.0], 0.5, 0.25, 0.0, 0.75)
    assert packer.pack(12, 1.0, 0.0, 0.0, 0.0, 0.5, 0.25, 0.0, 0.75, 1, 2) == msg.pack(mav.MAVLink(None))[10:-2]


@pytest.mark.parametrize(
    "make",
    [
        lambda L: L.reader("x", "time_usec"),  # not in wire order
        lambda L: L.reader("nope"),
        lambda L: L.packer("x"),  # does not lead
        lambda L: L.packer("time_usec", "x", x=2.0),  # x is packed, not fixed
        lambda L: L.packer("time_usec", "time_usec"),
    ],
)
def test_layout_errors_are_raised_when_building(make):
    with pytest.raises(LayoutError):
        make(MessageLayout.of(mav.MAVLink_odometry_message))


def test_wire_crc_is_the_reference_crc():
    rng = random.Random(3)
    for _ in range(300):
        data, init = rng.randbytes(rng.randrange(0, 300)), rng.randrange(1 << 16)
        ref = mav._x25crc_slow()
        ref.crc = init
        ref.accumulate(data)
        assert wire._mcrf4xx(data, init) == dialect.mcrf4xx(data, init) == ref.crc
