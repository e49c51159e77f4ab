"""The JSON Schemas in configs/schema/: current with the tables' declarations, every shipped
scenario and vehicle file valid against its own, and a bad file refused by them."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from amcore import config_schema

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "configs" / "schema"
FILES = [(p, "scenario") for p in sorted((ROOT / "configs" / "scenarios").glob("*.toml"))] + \
        [(p, "vehicle") for p in sorted((ROOT / "configs" / "vehicles").glob("*.toml"))]


def _validator(kind: str):
    return jsonschema.Draft202012Validator(json.loads((SCHEMAS / f"{kind}.schema.json").read_text()))


def test_the_shipped_schemas_are_what_the_declarations_write():
    for name, text in config_schema.rendered().items():
        assert (SCHEMAS / name).read_text() == text, f"configs/schema/{name} is stale: python -m amcore.config_schema"
    assert config_schema.main(["--check"]) == 0


@pytest.mark.parametrize("path,kind", FILES, ids=lambda x: getattr(x, "stem", x))
def test_every_shipped_file_validates_and_names_its_schema(path, kind):
    text = path.read_text()
    assert text.splitlines()[0] == f"#:schema ../schema/{kind}.schema.json"
    errors = [e.message for e in _validator(kind).iter_errors(tomllib.loads(text))]
    assert errors == []


@pytest.mark.parametrize("kind,table,key,value,words", [
    ("vehicle", "rotors", "thrust_max_n", "12", "is not of type 'number'"),
    ("vehicle", "gains", "k_R", -1.0, "less than or equal to the minimum"),
    ("vehicle", "pad", "shape", "round", "is not one of"),
    ("vehicle", "gains", "colour", 1, "Additional properties"),
    ("scenario", "link", "loss", 1.5, "greater than the maximum"),
    ("scenario", "devices", "mocap", {"rate_hz": 0.5}, "less than the minimum"),
    ("scenario", "objekt", "mass_kg", 1.0, "Additional properties"),
])
def test_a_bad_file_is_refused_by_its_schema(kind, table, key, value, words):
    path = ROOT / "configs" / ("vehicles/am3dof.toml" if kind == "vehicle" else "scenarios/two_am_comp.toml")
    data = tomllib.loads(path.read_text())
    data.setdefault(table, {})[key] = value
    errors = [e.message for e in _validator(kind).iter_errors(data)]
    assert errors and any(words in m for m in errors), errors


def test_a_vehicle_without_its_required_tables_is_refused():
    data = tomllib.loads((ROOT / "configs" / "vehicles" / "am3dof.toml").read_text())
    del data["gains"]
    assert any("'gains' is a required property" in e.message for e in _validator("vehicle").iter_errors(data))
