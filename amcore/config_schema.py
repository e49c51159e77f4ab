"""JSON Schemas of the scenario and vehicle TOML files, written by msgspec from the tables'
declarations in amcore.config (types, defaults, Annotated Meta ranges and descriptions, Literal
enums), for editors that check TOML against a schema (Taplo, Even Better TOML) through the
`#:schema ../schema/<kind>.schema.json` line each shipped file starts with.

    python -m amcore.config_schema           # writes configs/schema/{scenario,vehicle}.schema.json
    python -m amcore.config_schema --check   # exit 1 if the shipped files are not current

The vehicle schema requires what the loader requires. A scenario may be an overlay
(`base = "..."`, `unset = [...]`) giving only the keys that differ, so the scenario schema
requires no key: it checks the names, types, ranges and enums of what a file gives; the loader
checks the merged whole. What a schema cannot state (lengths that follow the arm's joints, the
URDF, rates dividing each other, the grasp's geometry, the lift) the loader checks in code.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
from pathlib import Path

import msgspec

from . import config as c
from .rotors import Rotor, RotorParams

SCHEMA_DIR = c.CONFIGS_DIR / "schema"
DRAFT = "https://json-schema.org/draft/2020-12/schema"
VEHICLE_TABLES = {"vehicle": c.VehicleParams, "rotors": RotorParams, "task": c.TaskSpec, "gains": c.Gains,
                  "safety": c.Safety, "options": c.ControllerOptions, "pad": c.PadSpec,
                  "baseline": c.BaselineGains, "flight_controller": c.FlightControllerParams}
VEHICLE_REQUIRED = ("vehicle", "rotors", "task", "gains")
SCENARIO_TABLES = {"scenario": c.ScenarioSpec, "object": c.ObjectSpec, "mission": c.MissionSpec,
                   "link": c.LinkSpec, "sensors": c.SensorSpec, "devices": c.DevicesSpec,
                   "success": c.SuccessCriteria}
# fields of a dataclass that its own TOML table does not hold (other tables, or set by the loader)
NOT_IN_TABLE = {c.VehicleParams: set(VEHICLE_TABLES) - {"vehicle"},
                c.ScenarioSpec: {"object", "mission", "ams", "path", "link", "sensors", "devices", "success"},
                c.AmSpec: {"link"}}


def _hook(tp):
    if tp is Path:
        return {"type": "string", "description": "a path, relative to this file's folder"}
    raise NotImplementedError


def _clean(value):
    """Defaults JSON cannot hold (inf) or that repeat a table's own schema (a table) are dropped."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if k == "default" and (isinstance(v, dict) or (isinstance(v, float) and not math.isfinite(v))):
                continue
            out[k] = _clean(v)
        return out
    if isinstance(value, list):
        return [_clean(v) for v in value]
    return value


def _defs() -> dict:
    classes = sorted({*VEHICLE_TABLES.values(), *SCENARIO_TABLES.values(), c.AmSpec, Rotor}, key=lambda k: k.__name__)
    classes += [c.ImuSpec, c.MocapSpec, c.ForceTorqueSpec, c.EncoderSpec, c.JointEffortSpec, c.EstimatorSpec]
    _, defs = msgspec.json.schema_components(classes, schema_hook=_hook, ref_template="#/$defs/{name}")
    for cls in classes:
        d = defs[cls.__name__]
        keep = {f.name for f in dataclasses.fields(cls) if f.init} - NOT_IN_TABLE.get(cls, set())
        d["properties"] = {k: v for k, v in d.get("properties", {}).items() if k in keep}
        d["required"] = [k for k in d.get("required", []) if k in keep]
        if not d["required"]:
            del d["required"]
    for d in defs.values():
        if d.get("type") == "object":
            d["additionalProperties"] = False  # the loader refuses unknown keys
            d.pop("title", None)
            if d.get("description"):
                d["description"] = " ".join(d["description"].split())
    # the rotors table's old keys are refused with a hint by the loader; [scenario].vehicle is a path
    defs["ScenarioSpec"]["properties"]["vehicle"] = {
        "type": "string", "description": "the vehicle TOML, relative to this file's folder"}
    defs["ScenarioSpec"]["required"] = ["name", "vehicle"]
    return _clean(defs)


def _relaxed(defs: dict) -> dict:
    """The definitions with nothing required (a scenario overlay gives only what differs)."""
    out = json.loads(json.dumps(defs))
    for d in out.values():
        d.pop("required", None)
    return out


def vehicle_schema() -> dict:
    defs = _defs()
    props = {name: {"$ref": f"#/$defs/{cls.__name__}"} for name, cls in VEHICLE_TABLES.items()}
    return {"$schema": DRAFT, "title": "amstack vehicle TOML", "type": "object", "properties": props,
            "required": list(VEHICLE_REQUIRED), "additionalProperties": False, "$defs": defs}


def scenario_schema() -> dict:
    defs = _relaxed(_defs())
    props = {name: {"$ref": f"#/$defs/{cls.__name__}"} for name, cls in SCENARIO_TABLES.items()}
    props["am"] = {"type": "array", "items": {"$ref": "#/$defs/AmEntry"}, "minItems": 1,
                   "description": "one entry per aerial manipulator ([[am]])"}
    link = defs["LinkSpec"]
    defs["AmEntry"] = {**defs["AmSpec"], "properties": {
        **defs["AmSpec"]["properties"],
        "link": {"type": "object", "additionalProperties": False, "description": "this AM's [link] keys",
                 "properties": {k: v for k, v in link["properties"].items() if k not in ("signing", "key_file")}}}}
    for name in c._VEHICLE_OVERRIDES:  # merged key by key onto the vehicle's table
        props[name] = {"$ref": f"#/$defs/{VEHICLE_TABLES[name].__name__}"}
    props["randomize"] = {"type": "object", "description": "what am-trials varies (trials.randomize)"}
    props["base"] = {"type": "string", "description": "the scenario this file is an overlay of, relative to it"}
    props["unset"] = {"type": "array", "items": {"type": "string"},
                      "description": "dotted keys or tables of the base to remove, e.g. \"rotors\""}
    return {"$schema": DRAFT, "title": "amstack scenario TOML (a whole file or an overlay of its base)",
            "description": "Nothing is required here, since an overlay gives only what differs from its base; "
                           "the loader checks the merged scenario.",
            "type": "object", "properties": props, "additionalProperties": False, "$defs": defs}


def rendered() -> dict[str, str]:
    return {name: json.dumps(schema, indent=1, sort_keys=False) + "\n"
            for name, schema in (("scenario.schema.json", scenario_schema()), ("vehicle.schema.json", vehicle_schema()))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m amcore.config_schema", description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if the shipped schemas are not current")
    args = ap.parse_args(argv)
    stale = []
    for name, text in rendered().items():
        path = SCHEMA_DIR / name
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(str(path))
        else:
            SCHEMA_DIR.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
    if stale:
        print(f"not current: {', '.join(stale)} (python -m amcore.config_schema)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
