"""What varies from trial to trial, and how each trial's variation is drawn (pure: numpy).

A `[randomize]` table (in a scenario, or alone in a TOML file such as
configs/randomize/default.toml) names ranges; `draw_trial` turns the base scenario's TOML
data and a trial index into that trial's scenario data, so that a trial *is* a scenario:
it loads through `amcore.config.scenario_from_dict`, and written out (`amcore.toml_write`)
it replays with `am-run`. Ranges are uniform:

    object_mass_kg = [lo, hi]     the object's mass [kg]
    object_size_scale = [lo, hi]  every edge of a box, or radius and height of a cylinder, times s
    pad_friction = [lo, hi]       the pad-object Coulomb coefficient ([object].pad_friction)
    setpoint_loss = [lo, hi]      [link].loss: companion -> flight controller setpoints lost
    sensor_latency_s = [lo, hi]   [sensors].latency_s
    misalignment_deg = a          per AM, uniform in [-a, a] ([[am]].misalignment_deg)
    start_offset_m = d            per AM, each world axis uniform in [-d, d] ([[am]].start_offset_m)
    start_heading_deg = h         per AM, uniform in [-h, h] ([[am]].start_heading_deg)
    planned_mass_tolerance = t    the team is told a planned mass within +/-t of the drawn one:
                                  [mission].planned_mass_kg = m (1 + u), u uniform in [-t, t], and
                                  [mission].mass_tolerance = t (what the plan allows for)
    object_position_m = d         the object (and its table) moved on each horizontal axis, uniform
                                  in [-d, d] ([object].position_m)
    object_yaw_deg = a            the object (and its table) turned about z, uniform in [-a, a]
                                  ([object].yaw_deg)
    object_pose = "mocap"         where every trial's team takes the object's pose from
                                  ([mission].object_pose): "mocap", the motion capture's
                                  measurement; "config", the scenario's [object] pose, blind
                                  to a moved object. Unset: the scenario's own. A table that
                                  moves or turns the object while its trials would plan from
                                  the configured pose is refused unless it says "config".
    [randomize.sensors]           the [sensors] levels every trial gets (noise and bias standard
                                  deviations; each trial's noise and biases follow its own seed)
    [randomize.devices]           the [devices] every trial gets (sensor devices and the flight
                                  controller's estimator, `simulator.devices`); each trial's noise
                                  and biases follow its own seed. A key the scenario itself sets
                                  under [devices] (or `--set devices.KEY=...`) wins over it.

Each trial draws from its own generator, seeded by (campaign seed, trial index), in a fixed
order, so a trial's variation does not depend on how many trials run or where.
"""
from __future__ import annotations

import copy
import dataclasses
import typing
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from amcore.config import (MASS_TOLERANCE_MAX, OBJECT_POSE_SOURCES, SCENARIO_PATH_KEYS, ConfigError, SensorSpec, _build,
                           devices_from_table, read_scenario)

Range = tuple[float, ...]


@dataclass(frozen=True)
class RandomizeSpec:
    object_mass_kg: Range = ()
    object_size_scale: Range = ()
    pad_friction: Range = ()
    setpoint_loss: Range = ()
    sensor_latency_s: Range = ()
    misalignment_deg: float = 0.0
    start_offset_m: float = 0.0
    start_heading_deg: float = 0.0
    planned_mass_tolerance: float = 0.0
    object_position_m: float = 0.0
    object_yaw_deg: float = 0.0
    object_pose: str = ""  # "" leaves the scenario's [mission].object_pose
    sensors: dict = dataclasses.field(default_factory=dict)  # a [sensors] table
    devices: dict = dataclasses.field(default_factory=dict)  # a [devices] table

    def ranges(self) -> dict[str, Range]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if typing.get_type_hints(RandomizeSpec)[f.name] == Range and getattr(self, f.name)}


OBJECT_SHIFT_MAX_M = 1.0  # [randomize].object_position_m: the most the object moves on its bench

# per range: (lowest allowed low, low must be > it rather than >=, highest allowed high)
_LIMITS = {"object_mass_kg": (0.0, True, None), "object_size_scale": (0.0, True, None),
           "pad_friction": (0.0, True, None), "setpoint_loss": (0.0, False, 1.0),
           "sensor_latency_s": (0.0, False, 1.0)}


def randomize_from_table(table: dict, where: str) -> RandomizeSpec:
    """A [randomize] table as a RandomizeSpec; errors name `where` and the key."""
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: [randomize] must be a table")
    sensors = table.get("sensors", {})
    devices = table.get("devices", {})
    kw = _build(RandomizeSpec, {k: v for k, v in table.items() if k not in ("sensors", "devices")},
                f"{where}: [randomize]", skip=("sensors", "devices"))
    if not isinstance(devices, dict):
        raise ConfigError(f"{where}: [randomize.devices] must be a table")
    devices_from_table(devices, f"{where}: [randomize]")
    if not isinstance(sensors, dict):
        raise ConfigError(f"{where}: [randomize.sensors] must be a table")
    levels = SensorSpec(**_build(SensorSpec, sensors, f"{where}: [randomize.sensors]"))
    for f in dataclasses.fields(SensorSpec):
        if getattr(levels, f.name) < 0.0:
            raise ConfigError(f"{where}: [randomize.sensors].{f.name}: must be >= 0")
    spec = RandomizeSpec(**kw, sensors=dict(sensors), devices=copy.deepcopy(devices))
    for name, rng in spec.ranges().items():
        lowest, strict, highest = _LIMITS[name]
        if len(rng) != 2 or not rng[0] <= rng[1]:
            raise ConfigError(f"{where}: [randomize].{name}: expected [low, high] with low <= high, got {list(rng)}")
        if rng[0] < lowest or (strict and rng[0] == lowest) or (highest is not None and rng[1] > highest):
            bound = f"{'>' if strict else '>='} {lowest:g}" + (f" and <= {highest:g}" if highest is not None else "")
            raise ConfigError(f"{where}: [randomize].{name}: {list(rng)} is out of range (values {bound})")
    for name in ("misalignment_deg", "start_offset_m", "start_heading_deg"):
        if getattr(spec, name) < 0.0:
            raise ConfigError(f"{where}: [randomize].{name}: must be >= 0 (a half-width)")
    if spec.misalignment_deg >= 45.0:
        raise ConfigError(f"{where}: [randomize].misalignment_deg: must be < 45")
    for name, most, why in (("planned_mass_tolerance", MASS_TOLERANCE_MAX, "a fraction of the mass"),
                            ("object_position_m", OBJECT_SHIFT_MAX_M, "m: the object stays over its bench"),
                            ("object_yaw_deg", 180.0, "deg: a half-turn either way covers every yaw")):
        if not 0.0 <= getattr(spec, name) <= most:
            raise ConfigError(f"{where}: [randomize].{name}: must be in [0, {most:g}] ({why}), "
                              f"got {getattr(spec, name)!r}")
    if spec.object_pose not in ("", *OBJECT_POSE_SOURCES):
        raise ConfigError(f"{where}: [randomize].object_pose: expected one of {', '.join(OBJECT_POSE_SOURCES)}, "
                          f"got {spec.object_pose!r}")
    return spec


def load_randomize(path: str | Path) -> RandomizeSpec:
    """The [randomize] table of a TOML file (a scenario, or a file holding only that table)."""
    path = Path(path).resolve()
    data = read_scenario(path)  # a scenario's own [randomize] may come from its base
    if "randomize" not in data:
        raise ConfigError(f"{path}: no [randomize] table")
    return randomize_from_table(data["randomize"], str(path))


def _uniform(rng: np.random.Generator, r: Range) -> float:
    return float(rng.uniform(r[0], r[1]))


def draw_trial(base: dict, rand: RandomizeSpec, campaign_seed: int, index: int) -> tuple[dict, dict]:
    """(scenario data, drawn parameters) of trial `index`: the base scenario's TOML data
    with this trial's variation, and the drawn values flat, for the trial's table row."""
    rng = np.random.default_rng([campaign_seed, index])
    data = copy.deepcopy(base)
    data.pop("randomize", None)
    p: dict[str, float | int] = {}
    obj = data.setdefault("object", {})
    if rand.object_mass_kg:
        obj["mass_kg"] = p["object_mass_kg"] = _uniform(rng, rand.object_mass_kg)
    if rand.object_size_scale:
        s = p["object_size_scale"] = _uniform(rng, rand.object_size_scale)
        if obj.get("shape", "box") == "box":
            obj["size_m"] = [s * x for x in obj.get("size_m", [0.2, 0.2, 0.2])]
        else:
            obj["radius_m"], obj["height_m"] = s * obj["radius_m"], s * obj["height_m"]
    if rand.pad_friction:
        obj["pad_friction"] = p["pad_friction"] = _uniform(rng, rand.pad_friction)
    if rand.setpoint_loss:
        data.setdefault("link", {})["loss"] = p["setpoint_loss"] = _uniform(rng, rand.setpoint_loss)
    if rand.sensors or rand.sensor_latency_s:
        sensors = data.setdefault("sensors", {})
        sensors.update(rand.sensors)
        if rand.sensor_latency_s:
            sensors["latency_s"] = p["sensor_latency_s"] = _uniform(rng, rand.sensor_latency_s)
    if rand.devices:
        data["devices"] = _merged(rand.devices, data.get("devices", {}))
    for am in data.get("am", []):
        s = am["sysid"]
        if rand.misalignment_deg:
            am["misalignment_deg"] = p[f"am{s}_misalignment_deg"] = _uniform(rng, (-rand.misalignment_deg,
                                                                                   rand.misalignment_deg))
        if rand.start_offset_m:
            d = rand.start_offset_m
            off = [float(x) for x in rng.uniform(-d, d, 3)]
            am["start_offset_m"] = off
            p[f"am{s}_start_offset_x_m"], p[f"am{s}_start_offset_y_m"], p[f"am{s}_start_offset_z_m"] = off
        if rand.start_heading_deg:
            h = rand.start_heading_deg
            am["start_heading_deg"] = p[f"am{s}_start_heading_deg"] = _uniform(rng, (-h, h))
    # drawn after everything above, so that a [randomize] table without these keys draws as before
    if rand.planned_mass_tolerance:
        t = rand.planned_mass_tolerance
        mission = data.setdefault("mission", {})
        mission["planned_mass_kg"] = p["planned_mass_kg"] = obj.get("mass_kg", 1.0) * (1.0 + _uniform(rng, (-t, t)))
        mission["mass_tolerance"] = t
    if rand.object_position_m:
        d = rand.object_position_m
        dx, dy = (float(x) for x in rng.uniform(-d, d, 2))
        x, y, z = obj.get("position_m", [0.0, 0.0, 0.6])
        obj["position_m"] = [x + dx, y + dy, z]
        p["object_dx_m"], p["object_dy_m"] = dx, dy
    if rand.object_yaw_deg:
        a = rand.object_yaw_deg
        obj["yaw_deg"] = p["object_yaw_deg"] = float(obj.get("yaw_deg", 0.0)) + _uniform(rng, (-a, a))
    if rand.object_pose:
        data.setdefault("mission", {})["object_pose"] = rand.object_pose
    elif (rand.object_position_m or rand.object_yaw_deg) and data.get("mission", {}).get("object_pose",
                                                                                           "config") == "config":
        raise ConfigError("[randomize] moves or turns the object (object_position_m, object_yaw_deg) but the "
                          "team plans from the scenario's [object] pose, blind to where it is: set "
                          "[randomize].object_pose = \"mocap\" (the motion capture's measurement), or \"config\" "
                          "to fly blind on purpose")
    sc = data.setdefault("scenario", {})
    sc["seed"] = p["seed"] = int(rng.integers(0, 2**31 - 1))
    sc["name"] = f"{str(sc.get('name', 'trial'))[:26]}-{index:04d}"
    return data, p


def _merged(under: dict, over: dict) -> dict:
    """Table `under` with `over`'s keys on top, sub-tables merged key by key."""
    out = copy.deepcopy(under)
    for k, v in over.items():
        out[k] = _merged(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else copy.deepcopy(v)
    return out


def relocate(data: dict, src: Path, dst_dir: Path) -> dict:
    """Scenario data read next to `src`, with its relative paths (the vehicle file, a link
    key file) rewritten for a file written in `dst_dir`."""
    import os

    out = copy.deepcopy(data)
    for table, key in SCENARIO_PATH_KEYS:
        t = out.get(table, {})
        if t.get(key):
            t[key] = os.path.relpath((src.parent / t[key]).resolve(), dst_dir.resolve())
    return out
