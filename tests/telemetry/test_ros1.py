"""telemetry.ros1: ROS 1 serialization of flat messages, against bytes spelled out by hand and
against itself (encode/decode, the precompiled struct), for messages of any shape."""
from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings, strategies as st

from telemetry.ros1 import PRIMITIVES, VARIABLE, Ros1Message, string_array

TEXT = """\
# a comment line
float64 t          # [s]
uint64 seq
string name
float64[2] p
int32[] counts
bool flag
string[] tags
uint8[3] rgb
"""


def test_bytes_as_ros1_lays_them_out():
    msg = Ros1Message.parse("pkg/Thing", TEXT)
    assert [(f.type, f.name, f.count) for f in msg.fields] == [
        ("float64", "t", None), ("uint64", "seq", None), ("string", "name", None), ("float64", "p", 2),
        ("int32", "counts", VARIABLE), ("bool", "flag", None), ("string", "tags", VARIABLE), ("uint8", "rgb", 3)]
    values = {"t": 1.5, "seq": 7, "name": "am4", "p": [0.25, -2.0], "counts": [-1, 2], "flag": True,
              "tags": ["a", "bc"], "rgb": [1, 2, 255]}
    expected = (b"\x00\x00\x00\x00\x00\x00\xf8\x3f"  # 1.5, little-endian float64
                + b"\x07" + b"\x00" * 7  # seq
                + b"\x03\x00\x00\x00am4"  # string: uint32 length, bytes, no NUL
                + struct.pack("<2d", 0.25, -2.0)  # fixed array: no count
                + b"\x02\x00\x00\x00" + b"\xff\xff\xff\xff" + b"\x02\x00\x00\x00"  # int32[]: count, values
                + b"\x01"  # bool: one byte
                + b"\x02\x00\x00\x00" + b"\x01\x00\x00\x00a" + b"\x02\x00\x00\x00bc"  # string[]
                + b"\x01\x02\xff")
    assert msg.encode(values) == expected
    assert msg.decode(expected) == values
    assert type(msg.decode(expected)["flag"]) is bool
    head = msg.struct({"name": 3, "counts": 2}, stop="tags")
    assert head.pack(1.5, 7, 3, b"am4", 0.25, -2.0, 2, -1, 2, True) + string_array(["a", "bc"]) + bytes([1, 2, 255]) \
        == expected


@pytest.mark.parametrize("text", [
    "geometry_msgs/Point p",  # nested types are not supported
    "time stamp",
    "int32 X=3",  # constants
    "float64[3 p",
    "float64 p\nfloat64 p",  # twice
    "float64",
])
def test_unsupported_or_broken_lines_are_refused(text):
    with pytest.raises(ValueError):
        Ros1Message.parse("pkg/T", text)


def test_the_name_is_a_package_resource_name():
    with pytest.raises(ValueError, match="package/Type"):
        Ros1Message.parse("pkg.T", "float64 t")
    with pytest.raises(KeyError):
        Ros1Message.parse("pkg/T", "float64 t").struct(stop="nope")
    with pytest.raises(ValueError, match="string arrays"):
        Ros1Message.parse("pkg/T", "string[] s").struct()


_NUMERIC = sorted(t for t in PRIMITIVES if t not in ("byte", "char"))
_VALUES = {"float64": st.floats(allow_nan=False, width=64), "float32": st.floats(allow_nan=False, width=32),
           "int8": st.integers(-2**7, 2**7 - 1), "uint8": st.integers(0, 2**8 - 1),
           "int16": st.integers(-2**15, 2**15 - 1), "uint16": st.integers(0, 2**16 - 1),
           "int32": st.integers(-2**31, 2**31 - 1), "uint32": st.integers(0, 2**32 - 1),
           "int64": st.integers(-2**63, 2**63 - 1), "uint64": st.integers(0, 2**64 - 1), "bool": st.booleans(),
           "string": st.text(max_size=6)}


@st.composite
def messages(draw):
    """A random flat message type and values for it."""
    n = draw(st.integers(1, 8))
    lines, values = [], {}
    for i in range(n):
        typ = draw(st.sampled_from(_NUMERIC + ["string"]))
        shape = draw(st.sampled_from(["", "[]", "[2]"]))
        lines.append(f"{typ}{shape} f{i}")
        k = {"": None, "[]": draw(st.integers(0, 4)), "[2]": 2}[shape]
        v = draw(_VALUES[typ]) if k is None else draw(st.lists(_VALUES[typ], min_size=k, max_size=k))
        values[f"f{i}"] = v
    return Ros1Message.parse("pkg/Random", "\n".join(lines)), values


@settings(max_examples=200, deadline=None)
@given(messages())
def test_decode_inverts_encode_and_every_cut_is_refused(case):
    msg, values = case
    data = msg.encode(values)
    assert msg.decode(data) == values
    for cut in range(len(data)):
        with pytest.raises(ValueError):
            msg.decode(data[:cut])
    with pytest.raises(ValueError, match="after the end"):
        msg.decode(data + b"\x00")


@settings(max_examples=100, deadline=None)
@given(messages())
def test_the_precompiled_struct_serializes_as_encode_does(case):
    msg, values = case
    stop = next((f.name for f in msg.fields if f.type == "string" and f.count is not None), None)
    lengths, args = {}, []
    for f in msg.fields:
        if f.name == stop:
            break
        v = values[f.name]
        if f.type == "string":
            b = v.encode()
            lengths[f.name] = len(b)
            args += [len(b), b]
        elif f.count is None:
            args.append(v)
        else:
            if f.count == VARIABLE:
                lengths[f.name] = len(v)
                args.append(len(v))
            args += v
    head = msg.struct(lengths, stop=stop).pack(*args)
    assert msg.encode(values).startswith(head)
    if stop is None:
        assert head == msg.encode(values)


def test_garbled_counts_and_strings_are_refused_not_allocated():
    msg = Ros1Message.parse("pkg/T", "float64[] x\nstring s")
    with pytest.raises(ValueError, match="do not fit"):
        msg.decode(b"\xff\xff\xff\x7f" + b"\x00" * 16)  # 2**31 doubles claimed
    with pytest.raises(ValueError, match="does not fit"):
        msg.decode(b"\x00\x00\x00\x00" + b"\xff\xff\x00\x00ab")
    with pytest.raises(ValueError, match="UTF-8"):
        msg.decode(b"\x00\x00\x00\x00" + b"\x02\x00\x00\x00\xff\xfe")


@settings(max_examples=200, deadline=None)
@given(messages(), st.binary(max_size=8))
def test_size_of_reads_the_length_from_the_counts(case, tail):
    msg, values = case
    data = msg.encode(values)
    assert msg.size_of(data) == len(data) and msg.size_of(data + tail) == len(data)
    for cut in range(len(data)):
        try:
            n = msg.size_of(data[:cut])
        except ValueError:
            continue
        assert n <= cut  # never a length past the bytes it was given
        with pytest.raises(ValueError):
            msg.decode(data[:cut])


def test_size_of_refuses_strings_that_would_not_decode():
    msg = Ros1Message.parse("pkg/T", "float64 t\nstring s")
    assert msg.size_of(msg.encode({"t": 0.0, "s": "grasp"})) == 17
    with pytest.raises(ValueError, match="UTF-8"):
        msg.size_of(b"\0" * 8 + b"\x02\x00\x00\x00\xff\xfe")
