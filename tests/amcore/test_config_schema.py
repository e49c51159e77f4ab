"""The scenario and vehicle JSON Schemas (amcore.config_schema): shipped current, valid JSON
Schemas, every shipped file valid against its own and pointing at it with its `#:schema` line,
and what the loader refuses by a declaration refused by the schema too."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from amcore import config_schema
from amcore.config import ConfigError, load_scenario, load_vehicle

jsonschema = pytest.importorskip("jsonschema", reason="jsonschema is in the test extra: pip install -e '.[test]'")

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
KINDS = {"scenario": sorted((CONFIGS / "scenarios").glob("*.toml")), "vehicle": sorted((CONFIGS / "vehicles").glob("*.toml"))}


def validator(kind: str):
    schema = json.loads((CONFIGS / "schema" / f"{kind}.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def test_the_shipped_schemas_are_current(tmp_path):
    assert config_schema.main(["--check"]) == 0, "run: python -m amcore.config_schema"
    (tmp_path / "vehicle.schema.json").write_text("{}\n")  # the check can fail
    assert config_schema.main(["--check", "--out", str(tmp_path)]) == 1


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_every_shipped_file_is_valid_and_names_its_schema(kind):
    v = validator(kind)
    assert KINDS[kind]
    for path in KINDS[kind]:
        assert path.read_text().splitlines()[0] == f"#:schema ../schema/{kind}.schema.json", path
        errors = [f"{list(e.path)}: {e.message}" for e in v.iter_errors(tomllib.loads(path.read_text()))]
        assert not errors, f"{path}: {errors}"


BAD_VEHICLE = [
    ('spin = "cw"', 'spin = "left"', "rotor[0].spin: expected one of ccw, cw, got 'left'"),
    ('mode = "torque"', 'mode = "rates"', "[flight_controller].mode: expected one of torque, attitude, got 'rates'"),
    ('[vehicle]', '[vehicle]\narm_length = 0.2', "unknown key 'arm_length'"),
    ('thrust_max_n = ', 'thrust_max_n = "12" #', "thrust_max_n: expected a number"),
]


@pytest.mark.parametrize("old,new,message", BAD_VEHICLE)
def test_what_the_loader_refuses_the_schema_refuses(tmp_path, old, new, message):
    src = CONFIGS / "vehicles" / "am3dof.toml"
    text = src.read_text()
    assert old in text, old
    bad = tmp_path / "am3dof.toml"
    bad.write_text(text.replace(old, new, 1))
    (tmp_path / "am3dof.urdf").write_bytes((CONFIGS / "vehicles" / "am3dof.urdf").read_bytes())
    with pytest.raises(ConfigError) as e:
        load_vehicle(bad)
    assert message in str(e.value) and str(bad) in str(e.value)
    assert list(validator("vehicle").iter_errors(tomllib.loads(bad.read_text())))


def test_an_overlay_needs_nothing_but_what_it_changes(tmp_path):
    """A scenario that overlays another validates with one key; a misspelt table does not."""
    v = validator("scenario")
    base = CONFIGS / "scenarios" / "two_am_comp_attitude.toml"
    good = {"base": str(base), "object": {"mass_kg": 1.5}}
    assert not list(v.iter_errors(good))
    assert list(v.iter_errors({**good, "objet": {"mass_kg": 1.5}}))
    assert list(v.iter_errors({**good, "object": {"shape": "sphere"}}))
    path = tmp_path / "heavier.toml"
    path.write_text(f'base = "{base}"\n[object]\nmass_kg = 1.5\n')
    assert load_scenario(path).object.mass_kg == 1.5
