"""A small JSON-schema checker for the subset our schemas use (pure, no dependency).

Supported keywords: type (one name or a list), properties, required, items, minItems,
maxItems, enum, const, minimum, maximum, oneOf. Unknown keywords (title, description,
$comment) are ignored. Enough to hold every payload and every Foxglove message we
write to its schema; not a general validator.
"""
from __future__ import annotations

import math
from typing import Any

_TYPES = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "null": lambda v: v is None,
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v),
}


def errors(value: Any, schema: dict, path: str = "$") -> list[str]:
    """Every violation of `schema` by `value`, as 'path: reason' strings (empty: valid)."""
    out: list[str] = []
    t = schema.get("type")
    if t is not None:
        names = t if isinstance(t, list) else [t]
        for n in names:
            if n not in _TYPES:
                raise ValueError(f"{path}: schema type {n!r} not supported")
        if not any(_TYPES[n](value) for n in names):
            return [f"{path}: expected {'/'.join(names)}, got {type(value).__name__} {value!r:.60}"]
    if "const" in schema and value != schema["const"]:
        out.append(f"{path}: expected {schema['const']!r}, got {value!r}")
    if "enum" in schema and value not in schema["enum"]:
        out.append(f"{path}: {value!r} not one of {schema['enum']}")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        if "minimum" in schema and value < schema["minimum"]:
            out.append(f"{path}: {value} < minimum {schema['minimum']}")
        if "maximum" in schema and value > schema["maximum"]:
            out.append(f"{path}: {value} > maximum {schema['maximum']}")
    if "oneOf" in schema:
        n_ok = sum(not errors(value, s, path) for s in schema["oneOf"])
        if n_ok != 1:
            out.append(f"{path}: matches {n_ok} of the oneOf alternatives, expected exactly 1")
    if isinstance(value, dict):
        for k in schema.get("required", ()):
            if k not in value:
                out.append(f"{path}: missing required {k!r}")
        for k, sub in schema.get("properties", {}).items():
            if k in value:
                out.extend(errors(value[k], sub, f"{path}.{k}"))
    if isinstance(value, list):
        if "minItems" in schema and len(value) < schema["minItems"]:
            out.append(f"{path}: {len(value)} items < minItems {schema['minItems']}")
        if "maxItems" in schema and len(value) > schema["maxItems"]:
            out.append(f"{path}: {len(value)} items > maxItems {schema['maxItems']}")
        if "items" in schema:
            for i, v in enumerate(value):
                out.extend(errors(v, schema["items"], f"{path}[{i}]"))
    return out
