"""Schema checks of telemetry payloads and Foxglove messages, for the tests (jsonschema).

`errors(value, schema)` lists every violation as 'path: reason' (empty: valid), with the
JSON Schema 2020-12 validator of the `jsonschema` package (the test extra), plus one rule
JSON itself implies and Python floats do not: every number is finite.
`binary_errors(channel, data)` checks a binary sample the same way: it must be one whole
message of the channel's layout, and its JSON view (telemetry.binary.to_dict) must satisfy
the channel's JSON Schema.
"""
from __future__ import annotations

import math
from typing import Any

from jsonschema import Draft202012Validator

from .binary import to_dict
from .schema import SCHEMAS, Channel

_validators: dict[int, tuple[dict, Draft202012Validator]] = {}


def _validator(schema: dict) -> Draft202012Validator:
    hit = _validators.get(id(schema))
    if hit is None or hit[0] is not schema:
        Draft202012Validator.check_schema(schema)
        hit = _validators[id(schema)] = (schema, Draft202012Validator(schema))
    return hit[1]


def _where(path: str, parts) -> str:
    return path + "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in parts)


def _non_finite(value: Any, path: str) -> list[str]:
    if isinstance(value, float) and not math.isfinite(value):
        return [f"{path}: non-finite number {value!r}"]
    if isinstance(value, dict):
        return [e for k, v in value.items() for e in _non_finite(v, f"{path}.{k}")]
    if isinstance(value, list):
        return [e for i, v in enumerate(value) for e in _non_finite(v, f"{path}[{i}]")]
    return []


def errors(value: Any, schema: dict, path: str = "$") -> list[str]:
    """Every violation of `schema` by `value`, as 'path: reason' strings (empty: valid)."""
    out = [f"{_where(path, e.absolute_path)}: {e.message}" for e in _validator(schema).iter_errors(value)]
    return out + _non_finite(value, path)


def binary_errors(channel: Channel, data: bytes) -> list[str]:
    """Every violation of a binary sample of `channel` (empty: valid)."""
    try:
        fields = to_dict(channel, data)
    except (ValueError, KeyError) as exc:
        return [f"$: not a {channel.value} sample: {exc}"]
    return errors(fields, SCHEMAS[channel])
