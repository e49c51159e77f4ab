"""ROS 1 message serialization of flat messages, from their .msg text (pure: struct only).

The binary telemetry channels (telemetry.binary) are ROS 1 messages: MCAP message encoding
`ros1`, schema encoding `ros1msg` (the .msg text), which Foxglove decodes natively. ROS 1
serialization is a packed little-endian struct in field order, no padding:

    float64, float32, (u)int8/16/32/64   the value
    bool                                 one byte, 0 or 1
    T[k] (fixed array)                   k values, no count
    T[] (variable array)                 uint32 count, then the values
    string                               uint32 byte length, then UTF-8 bytes (no NUL)
    string[] (string[k])                 uint32 count (none if fixed), then each string

Only flat messages of these built-in types are supported (no nested message types, no
time/duration, no constants): enough for the telemetry samples and checked when a .msg
text is parsed.

    msg = Ros1Message.parse("amstack/ObjectTruth", TEXT)
    data = msg.encode({"t": 0.5, ...})       # the literal path: any values, one field at a time
    msg.decode(data) == {...}                # ValueError if data is not one whole message
    msg.struct({"y": 3})                     # a struct.Struct for the fast builders (see `struct`)
"""
from __future__ import annotations

import re
import struct
from dataclasses import dataclass
from typing import Any, Mapping

PRIMITIVES = {"float64": "d", "float32": "f", "int8": "b", "uint8": "B", "int16": "h", "uint16": "H", "int32": "i",
              "uint32": "I", "int64": "q", "uint64": "Q", "bool": "?", "byte": "b", "char": "B"}
_COUNT = struct.Struct("<I")
_LINE = re.compile(r"([A-Za-z][A-Za-z0-9_]*)(\[(\d*)\])?\s+([A-Za-z][A-Za-z0-9_]*)")

VARIABLE = -1  # Field.count of a variable-length array


@dataclass(frozen=True)
class Field:
    type: str  # a key of PRIMITIVES, or "string"
    name: str
    count: int | None = None  # None: a scalar; k: fixed array of k; VARIABLE: variable-length array

    @property
    def code(self) -> str:
        return PRIMITIVES.get(self.type, "")


@dataclass(frozen=True)
class _Fixed:
    """Consecutive fixed-size fields, unpacked by one struct call."""

    st: struct.Struct
    slots: tuple[tuple[str, int, int | None], ...]  # (name, index into the unpacked tuple, count or None)


class Ros1Message:
    """One flat ROS 1 message type: its name, .msg text and fields, and a codec."""

    def __init__(self, name: str, text: str, fields: tuple[Field, ...]):
        self.name, self.text, self.fields = name, text, fields
        self._steps = self._compile()

    @classmethod
    def parse(cls, name: str, text: str) -> "Ros1Message":
        """The message `name` ('package/Type') of a .msg text. ValueError for what is not
        supported (nested types, time, constants) or not a .msg line."""
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*/[A-Za-z][A-Za-z0-9_]*", name):
            raise ValueError(f"{name!r}: a ros1msg schema name is 'package/Type'")
        fields = []
        for raw in text.splitlines():
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            m = _LINE.fullmatch(line)
            if m is None or "=" in line:
                raise ValueError(f"{name}: not a supported field line: {raw.strip()!r}")
            typ, arr, size, fname = m.groups()
            if typ not in PRIMITIVES and typ != "string":
                raise ValueError(f"{name}.{fname}: type {typ!r} is not a built-in type this codec supports")
            count = None if arr is None else (VARIABLE if size == "" else int(size))
            fields.append(Field(typ, fname, count))
        if len({f.name for f in fields}) != len(fields):
            raise ValueError(f"{name}: a field name appears twice")
        return cls(name, text, tuple(fields))

    # ------------------------------------------------------------------ decoding
    def _compile(self) -> tuple:
        steps: list = []
        fmt, slots, n = "", [], 0
        for f in self.fields:
            if f.type != "string" and f.count != VARIABLE:
                k = 1 if f.count is None else f.count
                fmt += f.code * k
                slots.append((f.name, n, f.count))
                n += k
                continue
            if slots:
                steps.append(_Fixed(struct.Struct("<" + fmt), tuple(slots)))
                fmt, slots, n = "", [], 0
            steps.append(f)
        if slots:
            steps.append(_Fixed(struct.Struct("<" + fmt), tuple(slots)))
        return tuple(steps)

    def decode(self, data: bytes) -> dict[str, Any]:
        """The fields of one serialized message: numbers as int, float or bool, arrays as
        lists, strings as str. ValueError if `data` is not exactly one message."""
        out: dict[str, Any] = {}
        off = 0
        try:
            for step in self._steps:
                if type(step) is _Fixed:
                    vals = step.st.unpack_from(data, off)
                    off += step.st.size
                    for name, i, count in step.slots:
                        out[name] = vals[i] if count is None else list(vals[i:i + count])
                elif step.type == "string":
                    if step.count is None:
                        out[step.name], off = _string(data, off)
                    else:
                        k = step.count
                        if k == VARIABLE:
                            (k,), off = _COUNT.unpack_from(data, off), off + 4
                        items = []
                        for _ in range(k):
                            s, off = _string(data, off)
                            items.append(s)
                        out[step.name] = items
                else:  # a variable-length array of numbers
                    (k,) = _COUNT.unpack_from(data, off)
                    off += 4
                    if k * struct.calcsize(step.code) > len(data) - off:
                        raise ValueError(f"{step.name}: {k} elements do not fit in the {len(data) - off} bytes left")
                    out[step.name] = list(struct.unpack_from(f"<{k}{step.code}", data, off))
                    off += k * struct.calcsize(step.code)
        except struct.error as exc:
            raise ValueError(f"{self.name}: {len(data)} bytes end inside the message ({exc})") from None
        if off != len(data):
            raise ValueError(f"{self.name}: {len(data) - off} bytes after the end of the message")
        return out

    def size_of(self, data: bytes) -> int:
        """The length of the message that `data` starts with, read from its counts without
        decoding the numbers (a recorder's check that a sample is one whole message that will
        decode: size_of(data) == len(data)). ValueError if `data` ends inside it, or a string
        is not UTF-8."""
        off = 0
        try:
            for step in self._steps:
                if type(step) is _Fixed:
                    off += step.st.size
                elif step.type == "string":
                    k = 1
                    if step.count is not None:
                        k = step.count
                        if k == VARIABLE:
                            (k,), off = _COUNT.unpack_from(data, off), off + 4
                    for _ in range(k):
                        off = _string(data, off)[1]
                else:
                    (k,) = _COUNT.unpack_from(data, off)
                    off += 4 + k * struct.calcsize(step.code)
        except struct.error:
            off = len(data) + 1
        if off > len(data):
            raise ValueError(f"{self.name}: {len(data)} bytes end inside the message")
        return off

    # ------------------------------------------------------------------ encoding
    def encode(self, values: Mapping[str, Any]) -> bytes:
        """Serialize `values` (every field by name), one field at a time: the literal path,
        against which the fast builders are checked. KeyError for a missing field,
        ValueError for a fixed array of the wrong length, struct.error for a value out of range."""
        parts = []
        for f in self.fields:
            v = values[f.name]
            if f.count is None:
                parts.append(_encode_string(v) if f.type == "string" else struct.pack("<" + f.code, v))
                continue
            v = list(v)
            if f.count != VARIABLE and len(v) != f.count:
                raise ValueError(f"{self.name}.{f.name}: {len(v)} elements, the type has {f.count}")
            if f.count == VARIABLE:
                parts.append(_COUNT.pack(len(v)))
            if f.type == "string":
                parts.extend(_encode_string(s) for s in v)
            else:
                parts.append(struct.pack(f"<{len(v)}{f.code}", *v))
        return b"".join(parts)

    def struct(self, lengths: Mapping[str, int] | None = None, stop: str | None = None) -> struct.Struct:
        """A struct.Struct serializing the fields in order, up to (without) field `stop`, for
        the given `lengths` (element count of each variable-length array, byte length of each
        string). Its pack() takes, in field order: a scalar; each element of a fixed array;
        a variable array's count (uint32) then its elements; a string's byte length then the
        bytes. For builders that serialize one layout many times (telemetry.binary)."""
        lengths = lengths or {}
        fmt = "<"
        for f in self.fields:
            if f.name == stop:
                break
            if f.type == "string":
                if f.count is not None:
                    raise ValueError(f"{self.name}.{f.name}: string arrays have no fixed layout; stop before it")
                fmt += f"I{lengths[f.name]}s"
            elif f.count == VARIABLE:
                fmt += "I" + f.code * lengths[f.name]
            else:
                fmt += f.code * (1 if f.count is None else f.count)
        else:
            if stop is not None:
                raise KeyError(f"{self.name} has no field {stop!r}")
        return struct.Struct(fmt)

    def __repr__(self) -> str:
        return f"Ros1Message({self.name!r}, {len(self.fields)} fields)"


def _string(data: bytes, off: int) -> tuple[str, int]:
    (n,) = _COUNT.unpack_from(data, off)
    off += 4
    if n > len(data) - off:
        raise ValueError(f"a string of {n} bytes does not fit in the {len(data) - off} bytes left")
    try:
        return bytes(data[off:off + n]).decode("utf-8"), off + n
    except UnicodeDecodeError as exc:
        raise ValueError(f"a string is not UTF-8: {exc}") from None


def _encode_string(s: str) -> bytes:
    b = s.encode("utf-8")
    return _COUNT.pack(len(b)) + b


def string_array(items) -> bytes:
    """A variable-length string[] as ROS 1 serializes it (count, then each string)."""
    return _COUNT.pack(len(items)) + b"".join(_encode_string(s) for s in items)
