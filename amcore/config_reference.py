"""The scenario TOML reference (docs/reference/scenario_toml.md), written from the typed
tables of `amcore.config` themselves: every key of every scenario table with its type, its
default and the comments beside its declaration, so the page lists exactly the keys the loader
takes. tests/test_docs.py checks that the committed page is what this writes.

    python -m amcore.config_reference > docs/reference/scenario_toml.md

Not math: a documentation tool (it reads amcore/config.py's source).
"""
from __future__ import annotations

import dataclasses
import inspect
import json
import re
import sys
import typing

from . import config

# (table as written in a scenario, its dataclass, keys the table does not take as plain keys)
SCENARIO_TABLES = (
    ("[scenario]", config.ScenarioSpec, ("name", "vehicle", "object", "mission", "ams", "link", "sensors", "devices",
                                         "success", "path")),
    ("[object]", config.ObjectSpec, ()),
    ("[mission]", config.MissionSpec, ()),
    ("[[am]]", config.AmSpec, ()),
    ("[link]", config.LinkSpec, ()),
    ("[sensors]", config.SensorSpec, ()),
    ("[devices]", config.DevicesSpec, ("imu", "mocap", "ft", "encoders", "estimator", "effort")),
    ("[devices.imu]", config.ImuSpec, ()),
    ("[devices.mocap]", config.MocapSpec, ()),
    ("[devices.ft]", config.ForceTorqueSpec, ()),
    ("[devices.encoders]", config.EncoderSpec, ()),
    ("[devices.effort]", config.JointEffortSpec, ()),
    ("[devices.estimator]", config.EstimatorSpec, ()),
    ("[success]", config.SuccessCriteria, ()),
)

HEADER = """# Scenario TOML reference

A scenario is a TOML file in `configs/scenarios/` (list them with `am-run --list`). It names a
vehicle file and sets the object, the mission, the team and the world. Every key below is
optional unless its default says "required"; an unknown key or table is refused with exit 2,
naming the file and the key, and so is a value outside its range (the loader,
`amcore/config.py`, gives each range's reason). The same declarations make the JSON Schema
`configs/schema/scenario.schema.json`, which an editor uses to check a file as it is typed
(see [the vehicle TOML reference](../vehicle_toml.md#checking-a-file-in-the-editor)).

Besides these tables a scenario may set `[options]`, `[safety]`, `[pad]`,
`[flight_controller]` and `[rotors]`: each is merged key by key onto the vehicle file's table
of that name, so a scenario can turn a controller option on without copying the vehicle. Their
keys are the vehicle's: see [the vehicle TOML reference](../vehicle_toml.md). A `[randomize]`
table says what `am-trials` varies ([campaigns](../guides/campaigns.md)).

[scenario] also takes `name` (required, the run's name) and `vehicle` (required, the vehicle
TOML's path relative to the scenario's folder). [[am]] is an array: one entry per aerial
manipulator; [[am]].link takes [link]'s keys for that AM alone.

## Overlays: `base` and `unset`

A variant of a scenario is written as an overlay of it, not a copy: a top-level
`base = "two_am_comp.toml"` (a path relative to the overlay's own folder) makes the file
the base scenario with the overlay's keys laid on top. The base is read first (and its own
base, if it has one, and so on), then merged with the overlay by one rule:

- a table merges key by key, recursively: `[mission] squeeze_max_n = 12.0` changes that key
  and keeps the base's other [mission] keys;
- any other value replaces the base's whole: a number, a string, a boolean, an array
  (`size_m = [...]`), and an array of tables: an overlay's `[[am]]` entries are the whole team,
  none of the base's is kept.

An overlay cannot delete by setting a key, so a top-level `unset = ["rotors",
"mission.envelope_check"]` removes those keys or whole tables (dotted: table.key) from the base
before the overlay is laid on: `unset = ["rotors"]` flies the vehicle's own rotors where the
base set ideal ones. Each name must be in the base. A path in a base (`[scenario].vehicle`,
`[link].key_file`) stays relative to the file that wrote it, wherever the overlay is. The
resolved scenario is what every tool reads (`amcore.config.read_scenario`); its fingerprint
(AM_SCENARIO.scenario_id) is that of the data, so an overlay that resolves to a file's data
flies that file's run. `base` that is not a string, a base that is missing, unreadable or not
TOML (both files named), a cycle of bases (the chain named) and a bad `unset` are refused with
exit 2; an error in the resolved scenario names the overlay and the bases under it. Each `*_attitude.toml` in `configs/scenarios/` is an overlay of its torque-mode twin.
What `am-run` writes as RUN/scenario.toml and `am-trials` as each trial's file is the resolved
scenario, self-contained (no `base`).

This page is written by `python -m amcore.config_reference` from the loader's own tables.
"""


# what a key means where its declaration carries no comment
NOTES = {
    (config.ScenarioSpec, "duration_s"): "simulated time of the run [s]",
    (config.ScenarioSpec, "seed"): "seed of every random draw of the run (sensor noise, device biases)",
    (config.ObjectSpec, "mass_kg"): "the object's true mass [kg]",
    (config.MissionSpec, "approach_end_s"): "end of the approach phase [s]",
    (config.MissionSpec, "grasp_end_s"): "end of the grasp phase; the lift starts here [s]",
    (config.MissionSpec, "hover_end_s"): "end of the hover [s]",
    (config.MissionSpec, "grasp_move_s"): "the grasp's motion takes this long, then holds [s]",
    (config.MissionSpec, "lift_move_s"): "the lift's motion takes this long, then holds [s]",
    (config.MissionSpec, "friction_margin"): "squeeze sizing: the margin on the friction needed",
    (config.MissionSpec, "lift_m"): "how high the team lifts the object [m]",
    (config.AmSpec, "sysid"): "the AM's MAVLink system id (unique in the team)",
    (config.AmSpec, "azimuth_deg"): "direction from the object's centre to the AM, about world z [deg]",
    (config.DevicesSpec, "enabled"): "sensors as devices produce them, and the estimator, on",
    (config.DevicesSpec, "scale"): "multiplies every noise, random walk, bias, offset and drift",
}


def _comments(cls) -> dict[str, str]:
    """Each field's comments in the class source: the lines just above it and the one after it."""
    out, above = {}, []
    for line in inspect.getsource(cls).splitlines():
        s = line.strip()
        if s.startswith("#"):
            above.append(s.lstrip("# ").rstrip())
            continue
        m = re.match(r"(\w+)\s*:\s*[^=#]+?(?:=\s*[^#]*)?(?:#\s*(.*))?$", s)
        if m and not s.startswith(("def ", "class ", "@", "return")):
            out[m.group(1)] = " ".join([*above, m.group(2) or ""]).strip()
        above = []
    return out


def _type(tp) -> str:
    """A declared type in words: its base type, its enum's values, its range ("float >= 0")."""
    base, meta = config._meta_at(tp, None)
    if typing.get_origin(base) is typing.Literal:
        return " or ".join(json.dumps(v) for v in typing.get_args(base))
    if typing.get_origin(base) is tuple:
        args = typing.get_args(base)
        inner = _type(args[0])
        return f"list of {inner}" if len(args) == 2 and args[1] is Ellipsis else f"{len(args)} x {inner}"
    text = getattr(base, "__name__", str(base)).replace("typing.", "").replace("|", "or")
    if meta is not None and (meta.ge, meta.gt, meta.le, meta.lt) != (None,) * 4:
        text += ", " + config._bounds(meta, base is int).removeprefix("must be ")
    return text


def _default(f: dataclasses.Field) -> str:
    if f.default is not dataclasses.MISSING:
        v = f.default
    elif f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        v = f.default_factory()  # type: ignore[misc]
    else:
        return "required"
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, tuple):
        return "[" + ", ".join(f"{x:g}" if isinstance(x, float) else str(x) for x in v) + "]"
    if isinstance(v, float):
        return "inf" if v == float("inf") else f"{v:g}"
    return str(v)


def table_rows(cls, skip=()) -> list[tuple[str, str, str, str]]:
    """(key, type, default, description) of every plain key of `cls`'s table."""
    hints = config._hints(cls)
    notes = _comments(cls)
    return [(f.name, _type(hints[f.name]), _default(f), notes.get(f.name) or NOTES.get((cls, f.name), ""))
            for f in dataclasses.fields(cls) if f.name not in skip]


def render() -> str:
    parts = [HEADER]
    for title, cls, skip in SCENARIO_TABLES:
        doc = cls.__doc__ or ""
        doc = "" if doc.startswith(cls.__name__ + "(") else inspect.cleandoc(doc)  # dataclass's own
        parts.append(f"## {title}\n")
        if doc:  # the table's docstring, its paragraphs and lists as they are
            parts.append(doc + "\n")
        parts.append("| key | type | default | meaning |\n|---|---|---|---|")
        for key, tp, default, note in table_rows(cls, skip):
            parts.append(f"| `{key}` | {tp} | {default} | {note.replace('|', '/')} |")
        parts.append("")
    return "\n".join(parts).rstrip() + "\n"


def main() -> int:
    sys.stdout.write(render())
    return 0


if __name__ == "__main__":
    sys.exit(main())
