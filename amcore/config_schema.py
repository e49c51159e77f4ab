"""JSON Schemas of the scenario and vehicle TOML files, generated from the tables' declarations
in amcore.config (the frozen dataclasses: their fields' types, defaults and, where a field is
`Annotated` with msgspec's `Meta`, its description, enum and range), by msgspec.

    python -m amcore.config_schema            # writes configs/schema/{scenario,vehicle}.schema.json
    python -m amcore.config_schema --check    # exit 1 if the shipped files are not current

Editors that read TOML against a JSON Schema (Taplo, VS Code's Even Better TOML) take the
`#:schema ../schema/scenario.schema.json` line each shipped file starts with: a key misspelt,
a value of the wrong type or outside its declared range is marked as it is typed.

A vehicle file's schema requires what the loader requires (the [vehicle], [rotors], [task]
and [gains] tables and each table's keys without a default). A scenario file may be an overlay
of another (`base = "..."`, `unset = [...]`): its schema checks the names, types and declared
ranges of what it gives and requires nothing; the loader checks the merged whole. What the
schema cannot say (lengths that depend on the arm's joints, the URDF, the rates dividing each
other, the grasp's geometry and the lift) the loader checks in code, naming file and key.
The [randomize] table belongs to am-trials (trials.randomize) and is left open here.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import sys
from pathlib import Path

import msgspec

from . import config as c
from .rotors import Rotor, RotorParams

SCHEMA_DIR = c.CONFIGS_DIR / "schema"
DRAFT = "https://json-schema.org/draft/2020-12/schema"

# the vehicle file's tables and the dataclass each is read into (amcore.config.vehicle_from_dict)
VEHICLE_TABLES = {"vehicle": c.VehicleParams, "rotors": RotorParams, "task": c.TaskSpec, "gains": c.Gains,
                  "safety": c.Safety, "options": c.ControllerOptions, "pad": c.PadSpec,
                  "baseline": c.BaselineGains, "flight_controller": c.FlightControllerParams}
VEHICLE_REQUIRED = ("vehicle", "rotors", "task", "gains")
# the scenario file's own tables (amcore.config.scenario_from_dict); the vehicle's tables it may
# override are _VEHICLE_OVERRIDES
SCENARIO_TABLES = {"scenario": c.ScenarioSpec, "object": c.ObjectSpec, "mission": c.MissionSpec,
                   "link": c.LinkSpec, "sensors": c.SensorSpec, "devices": c.DevicesSpec,
                   "success": c.SuccessCriteria}
# fields of a dataclass that its own table does not hold (another table, or derived)
NOT_IN_TABLE = {
    c.VehicleParams: ("rotors", "task", "gains", "safety", "options", "pad", "baseline", "flight_controller"),
    c.ScenarioSpec: ("vehicle", "object", "mission", "ams", "path", "link", "sensors", "devices", "success"),
    c.AmSpec: ("link",),
}


def _hook(tp):
    if tp is Path:
        return {"type": "string", "description": "a path, relative to this file's folder"}
    raise NotImplementedError  # msgspec's own error then names the type


def _components() -> dict:
    classes = sorted({*VEHICLE_TABLES.values(), *SCENARIO_TABLES.values(), c.AmSpec, Rotor},
                     key=lambda k: k.__name__)
    _, defs = msgspec.json.schema_components(classes, schema_hook=_hook, ref_template="#/$defs/{name}")
    for cls in classes:  # what each table holds: its init fields less those read from other tables
        d = defs[cls.__name__]
        keep = {f.name for f in dataclasses.fields(cls) if f.init} - set(NOT_IN_TABLE.get(cls, ()))
        d["properties"] = {k: v for k, v in d.get("properties", {}).items() if k in keep}
        if "required" in d:
            d["required"] = [k for k in d["required"] if k in keep]
            if not d["required"]:
                del d["required"]
    for d in defs.values():
        if d.get("type") == "object":
            d["additionalProperties"] = False
            d.pop("title", None)
            if d.get("description"):
                d["description"] = " ".join(d["description"].split())
    return defs


def _optional(defs: dict) -> dict:
    """The definitions with nothing required (an overlay gives what differs)."""
    out = copy.deepcopy(defs)
    for d in out.values():
        d.pop("required", None)
    return out


def _ref(name: str) -> dict:
    return {"$ref": f"#/$defs/{name}"}


def vehicle_schema() -> dict:
    defs = _components()
    defs["RotorParams"]["properties"]["rotor"] = {"type": "array", "items": _ref("Rotor"), "minItems": 1,
                                                  "description": "one [[rotors.rotor]] row per rotor"}
    if "rotor" not in defs["RotorParams"].setdefault("required", []):
        defs["RotorParams"]["required"].append("rotor")
    defs["VehicleParams"]["properties"]["urdf"] = {"type": "string",
                                                   "description": "the URDF, relative to this file's folder"}
    return {"$schema": DRAFT, "title": "amstack vehicle", "type": "object", "additionalProperties": False,
            "properties": {name: _ref(cls.__name__) for name, cls in VEHICLE_TABLES.items()},
            "required": list(VEHICLE_REQUIRED), "$defs": _used(defs, VEHICLE_TABLES.values(), [Rotor])}


def scenario_schema() -> dict:
    defs = _optional(_components())
    defs["ScenarioSpec"]["properties"]["vehicle"] = {
        "type": "string", "description": "the vehicle TOML, relative to this file's folder"}
    defs["RotorParams"]["properties"]["rotor"] = {"type": "array", "items": _ref("Rotor")}
    am = defs["AmSpec"]
    am["properties"]["link"] = {**_ref("LinkSpec"), "description": "this AM's link, over the [link] table"}
    props = {name: _ref(cls.__name__) for name, cls in SCENARIO_TABLES.items()}
    props.update({name: _ref(VEHICLE_TABLES[name].__name__) for name in c._VEHICLE_OVERRIDES})
    props["am"] = {"type": "array", "items": _ref("AmSpec"), "description": "one [[am]] entry per AM"}
    props["randomize"] = {"type": "object", "description": "am-trials' variation (trials.randomize)"}
    props["base"] = {"type": "string", "description": "the scenario this file overlays, relative to its folder"}
    props["unset"] = {"type": "array", "items": {"type": "string"},
                      "description": "keys of the base to drop, as 'table.key'"}
    used = [*SCENARIO_TABLES.values(), *(VEHICLE_TABLES[n] for n in c._VEHICLE_OVERRIDES), c.AmSpec]
    return {"$schema": DRAFT, "title": "amstack scenario", "type": "object", "additionalProperties": False,
            "properties": props, "$defs": _used(defs, used, [Rotor])}


def _used(defs: dict, classes, extra) -> dict:
    """The definitions the given classes reach, by their $refs."""
    names, todo = set(), [k.__name__ for k in (*classes, *extra)]
    while todo:
        n = todo.pop()
        if n in names:
            continue
        names.add(n)
        text = json.dumps(defs[n])
        todo += [m for m in defs if f'"#/$defs/{m}"' in text]
    return {n: defs[n] for n in sorted(names)}


def rendered() -> dict[str, str]:
    """{file name: text} of the schemas."""
    dump = lambda s: json.dumps(s, indent=1, sort_keys=True) + "\n"  # noqa: E731
    return {"scenario.schema.json": dump(scenario_schema()), "vehicle.schema.json": dump(vehicle_schema())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m amcore.config_schema", description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if the shipped schemas are not current")
    ap.add_argument("--out", type=Path, default=SCHEMA_DIR, help="folder (default: configs/schema)")
    a = ap.parse_args(argv)
    stale = []
    for name, text in rendered().items():
        path = a.out / name
        if a.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(str(path))
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
    if stale:
        print(f"not current: {', '.join(stale)} (python -m amcore.config_schema)", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
