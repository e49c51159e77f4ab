"""A TOML writer for scenario data (tables, arrays of tables, strings, numbers, booleans and
lists of them), so that a drawn trial can be written as a scenario file and replayed.

Floats are written with `repr`, which reads back to the same float: a replayed trial is
the same trial, bit for bit.
"""
from __future__ import annotations

import math


def dumps(data: dict) -> str:
    """`data` as TOML text: top-level scalars first, then tables, then arrays of tables."""
    lines: list[str] = []
    _table(lines, (), data)
    return "\n".join(lines).lstrip("\n") + "\n"


def _table(lines: list[str], path: tuple[str, ...], table: dict) -> None:
    scalars = {k: v for k, v in table.items() if not _is_table(v) and not _is_table_array(v)}
    tables = {k: v for k, v in table.items() if _is_table(v)}
    arrays = {k: v for k, v in table.items() if _is_table_array(v)}
    if path and (scalars or not (tables or arrays)):
        lines.append(f"\n[{'.'.join(map(_key, path))}]")
    for k, v in scalars.items():
        lines.append(f"{_key(k)} = {_value(v)}")
    for k, v in tables.items():
        _table(lines, (*path, k), v)
    for k, items in arrays.items():
        for item in items:
            lines.append(f"\n[[{'.'.join(map(_key, (*path, k)))}]]")
            sub_tables = {kk: vv for kk, vv in item.items() if _is_table(vv)}
            for kk, vv in item.items():
                if kk not in sub_tables:
                    lines.append(f"{_key(kk)} = {_value(vv)}")
            for kk, vv in sub_tables.items():  # an inline table keeps it inside this array entry
                lines.append(f"{_key(kk)} = {_inline(vv)}")


def _is_table(v) -> bool:
    return isinstance(v, dict)


def _is_table_array(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() and k.isascii() else _string(k)


def _string(s: str) -> str:
    out = s.replace("\\", "\\\\").replace('"', '\\"')
    out = "".join(c if c >= " " and c != "\x7f" else f"\\u{ord(c):04x}" for c in out)
    return f'"{out}"'


def _inline(d: dict) -> str:
    return "{" + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in d.items()) + "}"


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return _inline(v)
    raise TypeError(f"cannot write {type(v).__name__} {v!r} as TOML")
