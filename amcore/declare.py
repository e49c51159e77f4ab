"""Declarations beside a config table's fields (pure: typing and msgspec's Meta).

A field annotated `one_of(VALUES)` takes one of VALUES: amcore.config's loader refuses any
other, naming the file, the key and the value, and the JSON Schema that amcore.config_schema
generates from the same annotation lists them (`enum`), so an editor offers them.
"""
from __future__ import annotations

import typing
from typing import Annotated

import msgspec


def one_of(values: tuple, description: str = ""):
    """The type of a field that takes one of `values` (all of one type: str or int)."""
    kind = type(values[0])
    meta = msgspec.Meta(extra_json_schema={"enum": list(values)}, **({"description": description} if description else {}))
    return Annotated[kind, meta]


def enum_of(hint) -> tuple | None:
    """The values a field annotated `one_of(values)` takes, else None."""
    if typing.get_origin(hint) is not Annotated:
        return None
    for m in typing.get_args(hint)[1:]:
        if isinstance(m, msgspec.Meta) and m.extra_json_schema and "enum" in m.extra_json_schema:
            return tuple(m.extra_json_schema["enum"])
    return None


def at_least(lo: float, description: str = ""):
    """The type of a number field (float, or int if lo is one) that must be >= lo."""
    return Annotated[type(lo), msgspec.Meta(ge=lo, **({"description": description} if description else {}))]


def within(lo: float, hi: float, description: str = ""):
    """The type of a float field that must lie in [lo, hi]."""
    return Annotated[float, msgspec.Meta(ge=lo, le=hi, **({"description": description} if description else {}))]


def bounds_problem(hint, value) -> str | None:
    """Why `value` breaks the bounds a field annotated `at_least` or `within` declares
    ("must be >= 0" ...; a list's entry named), else None."""
    if typing.get_origin(hint) is not Annotated:
        return None
    for m in typing.get_args(hint)[1:]:
        if not isinstance(m, msgspec.Meta) or (m.ge is None and m.le is None):
            continue
        for i, v in enumerate(value if isinstance(value, tuple) else (value,)):
            if (m.ge is not None and not v >= m.ge) or (m.le is not None and not v <= m.le):
                need = f"must be in [{m.ge:g}, {m.le:g}]" if m.ge is not None and m.le is not None else \
                    f"must be >= {m.ge:g}" if m.ge is not None else f"must be <= {m.le:g}"
                return f"{need}, got {v!r}" + (f" (entry {i})" if isinstance(value, tuple) else "")
    return None
