"""Payload layouts of dialect messages, derived from the mavgen-generated module (struct only, no I/O).

pymavlink's generated class of every message carries what the wire needs: the
payload ``struct`` format (``unpacker.format``, the ``fmtstr``, fields sorted
by MAVLink 2 rules), the field order it follows (``ordered_fieldnames``),
``crc_extra`` and the id.  :class:`MessageLayout` turns that into per-field
offsets, and builds precompiled :class:`struct.Struct` objects that pack or
read just the fields a caller names -- so the fast codec
(:mod:`amlink.codec`) copies no layout by hand.  A caller names fields in
wire order; if a dialect change reorders them, building the packer or reader
raises :class:`LayoutError` at import instead of corrupting frames.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable
from dataclasses import dataclass

_TOKEN = re.compile(r"(\d*)([a-zA-Z?])")


class LayoutError(ValueError):
    """A requested field does not exist or is not in wire order, or the dialect's format is odd."""


@dataclass(frozen=True)
class Field:
    """One payload field: ``token`` is its struct code (``"d"``, ``"8d"``, ``"32s"``), ``offset`` in bytes."""

    name: str
    token: str
    offset: int
    size: int

    @property
    def values(self) -> int:
        """How many values ``struct`` yields for it (a char array is one ``bytes``)."""
        count, code = _TOKEN.fullmatch(self.token).groups()
        return 1 if code == "s" or not count else int(count)


@dataclass(frozen=True)
class MessageLayout:
    """Wire layout of one message: id, CRC_EXTRA, payload size and fields in wire order."""

    msgid: int
    name: str
    crc_extra: int
    size: int
    fields: tuple[Field, ...]

    @classmethod
    def of(cls, msg_class) -> MessageLayout:
        """Layout of a generated ``MAVLink_*_message`` class (its ``unpacker.format`` and field order)."""
        fmt = msg_class.unpacker.format
        if not fmt.startswith("<"):
            raise LayoutError(f"{msg_class.msgname}: format {fmt!r} is not little-endian standard")
        tokens = [count + code for count, code in _TOKEN.findall(fmt[1:])]
        names = list(msg_class.ordered_fieldnames)
        if len(tokens) != len(names) or "".join(tokens) != fmt[1:]:
            raise LayoutError(f"{msg_class.msgname}: cannot match format {fmt!r} to fields {names}")
        fields, offset = [], 0
        for name, token in zip(names, tokens):
            size = struct.calcsize("<" + token)
            fields.append(Field(name, token, offset, size))
            offset += size
        if offset != msg_class.unpacker.size:  # pragma: no cover - struct and calcsize disagree
            raise LayoutError(f"{msg_class.msgname}: derived size {offset} != {msg_class.unpacker.size}")
        return cls(msg_class.id, msg_class.msgname, msg_class.crc_extra, offset, tuple(fields))

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise LayoutError(f"{self.name} has no field {name!r}")

    def _indices(self, names: tuple[str, ...]) -> list[int]:
        order = [f.name for f in self.fields]
        idx = []
        for name in names:
            if name not in order:
                raise LayoutError(f"{self.name} has no field {name!r}")
            idx.append(order.index(name))
        if idx != sorted(set(idx)):
            raise LayoutError(f"{self.name}: fields {names} are not in wire order {tuple(order)}")
        return idx

    def packer(self, *names: str, **fixed) -> Packer:
        """Pack ``names`` (leading fields, wire order); every later field is ``fixed[name]`` or zero.

        The trailing fixed fields are packed once here.  Their values must be what
        ``struct`` takes for them (a sequence for an array).
        """
        idx = self._indices(names)
        if idx != list(range(len(names))):
            raise LayoutError(f"{self.name}: packed fields {names} must lead the wire order "
                              f"{tuple(f.name for f in self.fields)}")  # fmt: skip
        rest = self.fields[len(names) :]
        unknown = set(fixed) - {f.name for f in rest}
        if unknown:
            raise LayoutError(f"{self.name}: fixed fields {sorted(unknown)} are not trailing fields")
        tail_values = []
        for f in rest:
            zero = b"" if f.token.endswith("s") else (0,) * f.values if f.values > 1 else 0
            v = fixed.get(f.name, zero)
            tail_values.extend(v if f.values > 1 else (v,))
        tail = struct.pack("<" + "".join(f.token for f in rest), *tail_values)
        head = struct.Struct("<" + "".join(self.fields[i].token for i in idx))
        return Packer(self.msgid, self.name, head, tail)

    def reader(self, *names: str) -> Reader:
        """Read ``names`` (wire order) from a payload, other bytes skipped; values flattened."""
        idx = self._indices(names)
        fmt, at = "<", 0
        for i in idx:
            f = self.fields[i]
            if f.offset > at:
                fmt += f"{f.offset - at}x"
            fmt += f.token
            at = f.offset + f.size
        return Reader(self.msgid, self.name, struct.Struct(fmt))


class Packer:
    """``pack(*values) -> payload`` (full length, trailing zeros kept: the framer drops them)."""

    __slots__ = ("msgid", "name", "head", "tail", "pack")

    def __init__(self, msgid: int, name: str, head: struct.Struct, tail: bytes) -> None:
        self.msgid, self.name, self.head, self.tail = msgid, name, head, tail
        if not tail:
            self.pack: Callable[..., bytes] = head.pack
        else:
            head_pack = head.pack

            def pack(*values) -> bytes:
                return head_pack(*values) + tail

            self.pack = pack


class Reader:
    """``read(buf, at, plen) -> tuple``: the named fields of the payload ``buf[at : at + plen]``.

    MAVLink 2 drops trailing zero bytes, so a short payload is read as if zero-padded;
    a longer one's extra bytes are ignored (both as pymavlink's ``decode``).
    """

    __slots__ = ("msgid", "name", "struct", "read")

    def __init__(self, msgid: int, name: str, s: struct.Struct) -> None:
        self.msgid, self.name, self.struct = msgid, name, s
        size, unpack_from, unpack = s.size, s.unpack_from, s.unpack

        def read(buf, at: int, plen: int) -> tuple:
            if plen >= size:
                return unpack_from(buf, at)
            return unpack(bytes(buf[at : at + plen]) + bytes(size - plen))

        self.read: Callable[[bytes, int, int], tuple] = read
