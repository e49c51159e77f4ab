"""Bad values, key by key: every one is a ConfigError naming the file and the key, raised
when the scenario is loaded (before anything starts), never another exception."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from amcore.config import ConfigError, load_scenario, read_scenario
from amcore.toml_write import dumps

ROOT = Path(__file__).resolve().parents[2]
SHORT = ROOT / "configs" / "scenarios" / "two_am_short.toml"
VEHICLE = ROOT / "configs" / "vehicles" / "am3dof.toml"
URDF = ROOT / "configs" / "vehicles" / "am3dof.urdf"


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"').replace("\0", "\\u0000") + '"'
    if isinstance(value, float):
        return repr(value) if value == value and abs(value) != float("inf") else \
            ("nan" if value != value else ("inf" if value > 0 else "-inf"))
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return str(value)


def _dump(data: dict) -> str:
    out = []
    for table, body in data.items():
        if isinstance(body, list):
            for entry in body:
                out.append(f"[[{table}]]")
                out += [f"{k} = {_toml(v)}" for k, v in entry.items()]
        else:
            out.append(f"[{table}]")
            out += [f"{k} = {_toml(v)}" for k, v in body.items()]
    return "\n".join(out) + "\n"


def _scenario(tmp_path, table: str, key: str, value, vehicle_table: str | None = None) -> Path:
    """two_am_short with one value changed; `vehicle_table`: change it in a copy of the vehicle."""
    data = read_scenario(SHORT)
    vdata = tomllib.loads(VEHICLE.read_text())
    vdata["vehicle"]["urdf"] = str(URDF)
    if vehicle_table is not None:
        vdata.setdefault(vehicle_table, {})[key] = value
    elif table == "am":
        data["am"][0][key] = value
    else:
        data.setdefault(table, {})[key] = value
    (tmp_path / "v.toml").write_text(dumps(vdata))  # the rotor rows are an array of tables in a table
    data["scenario"]["vehicle"] = str(tmp_path / "v.toml") if not (table == "scenario" and key == "vehicle") \
        else value
    path = tmp_path / "s.toml"
    path.write_text(_dump(data))
    return path


# (table, key, bad value, vehicle table or None) -- each must be refused naming the key
BAD = [
    ("scenario", "vehicle", 5, None),
    ("scenario", "name", "x" * 33, None),
    ("scenario", "name", "gr\u00fcn", None),
    ("scenario", "name", "a\0b", None),
    ("scenario", "name", "", None),
    ("scenario", "seed", -1, None),
    ("scenario", "seed", 2**32, None),
    ("scenario", "rate_hz", 1e39, None),
    ("scenario", "rate_hz", 1e-3, None),
    ("scenario", "rate_hz", float("nan"), None),
    ("scenario", "duration_s", 1e-6, None),
    ("scenario", "duration_s", float("inf"), None),
    ("scenario", "duration_s", -1.0, None),
    ("scenario", "control_rate_hz", 0.0, None),
    ("mission", "approach_move_s", 0.0, None),
    ("mission", "lift_move_s", -1.0, None),
    ("mission", "grasp_move_s", float("nan"), None),
    ("mission", "lift_m", 0.0, None),
    ("mission", "squeeze_m", -0.01, None),
    ("mission", "join_blend_s", 0.0, None),
    ("object", "position_m", [0.0, 0.0, -0.5], None),
    ("object", "mass_kg", 50.0, None),
    ("object", "mass_kg", 0.0, None),
    ("object", "lateral_friction", -1.0, None),
    ("object", "mass_kg", 1e-300, None),
    ("object", "mass_kg", 150.0, None),
    ("object", "size_m", [1e-9, 1e-9, 1e-9], None),
    ("object", "size_m", [0.2, 0.2, 5.0], None),
    ("object", "position_m", [50.0, 0.0, 0.6], None),
    ("object", "position_m", [0.0, 0.0, 20.0], None),
    ("scenario", "name", "../../escape", None),
    ("scenario", "name", "a/b", None),
    ("scenario", "name", ".hidden", None),
    ("am", "azimuth_deg", 0.0, None),
    ("am", "azimuth_deg", 30.0, None),
    ("am", "start_offset_m", [0.5, 0.0, 0.0], None),
    ("mission", "lift_m", 5.0, None),
    ("mission", "lift_m", 0.1, None),
    ("mission", "standoff_m", 3.0, None),
    ("mission", "squeeze_m", 0.1, None),
    ("sensors", "latency_s", -0.001, None),
    ("success", "max_slip_m", -1.0, None),
    ("link", "loss", 1.5, None),
    ("am", "misalignment_deg", 90.0, None),
    ("am", "sysid", 256, None),
    ("rotors", "arm_length_m", 0.3, None),
    ("rotors", "rotor", [], None),
    ("rotors", "thrust_min_n", 12.0, None),
    ("rotors", "thrust_max_n", 0.0, None),
    ("rotors", "time_constant_s", -0.1, None),
    ("options", "force_filter_zeta", -1.0, None),
    ("options", "force_filter_hz", 0.0, None),
    ("flight_controller", "rate_hz", 0.0, None),
    ("flight_controller", "failsafe_after_rejected", 0, None),
    ("flight_controller", "MC_ROLL_P", -1.0, None),
    ("safety", "sigma_damping", -0.1, None),
    ("vehicle", "gravity_mps2", 0.0, "vehicle"),
    ("vehicle", "gravity_mps2", -9.81, "vehicle"),
    ("vehicle", "base_link", "nowhere", "vehicle"),
    ("vehicle", "ee_frame", "nowhere", "vehicle"),
    ("vehicle", "arm_joints", ["joint1", "joint2", "elbow"], "vehicle"),
    ("gains", "k_R", -1.0, "gains"),
]


@pytest.mark.parametrize("table,key,value,vtable", BAD, ids=[f"{b[0]}.{b[1]}={b[2]!r}"[:60] for b in BAD])
def test_each_bad_value_is_a_config_error_naming_the_key(tmp_path, table, key, value, vtable):
    path = _scenario(tmp_path, table, key, value, vtable)
    with pytest.raises(ConfigError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert key in msg, msg
    assert "\n" not in msg
    assert str(tmp_path) in msg  # the file (the scenario's, or the vehicle's copy)


def test_the_unchanged_scenario_loads(tmp_path):
    """The sweep's own baseline: the files it writes are fine until one value changes."""
    spec = load_scenario(_scenario(tmp_path, "object", "mass_kg", 1.0))
    assert spec.object.mass_kg == 1.0 and spec.vehicle.urdf == URDF


@pytest.mark.parametrize("content,words", [
    (b"\xff\xfe[scenario]\n", "not UTF-8"),
    (None, "is a directory"),
])
def test_unreadable_scenario_files_name_the_file(tmp_path, content, words):
    path = tmp_path / "s.toml"
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    with pytest.raises(ConfigError, match=words) as err:
        load_scenario(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("urdf_text", ["", "<robot name='r'/>", "<robot><link name='base_link'/></robot>", "<nope/>"])
def test_an_empty_or_trivial_urdf_is_a_config_error(tmp_path, urdf_text):
    (tmp_path / "r.urdf").write_text(urdf_text)
    path = _scenario(tmp_path, "vehicle", "urdf", str(tmp_path / "r.urdf"), "vehicle")
    with pytest.raises(ConfigError, match=r"\[vehicle\]\.(urdf|base_link|arm_joints|ee_frame)"):
        load_scenario(path)


def test_the_lift_check_names_what_the_team_can_carry(tmp_path):
    """Two 1.8 kg AMs with 4 x 12 N rotors, 0.8 of it planned: about 4.2 kg of object at most."""
    with pytest.raises(ConfigError, match=r"\[object\]\.mass_kg: 5 kg is more than 2 AMs can lift.*at most 4\.\d\d kg"):
        load_scenario(_scenario(tmp_path, "object", "mass_kg", 5.0))
    assert load_scenario(_scenario(tmp_path, "object", "mass_kg", 4.0)).object.mass_kg == 4.0



# the implausible values that used to load, each with the plausible range its message must give
IMPLAUSIBLE = [
    ("object", "mass_kg", 1e-300, "[0.01, 100] kg"),
    ("object", "size_m", [1e-9, 1e-9, 1e-9], "[0.05, 3] m"),
    ("scenario", "name", "../../escape", "letters, digits, '_', '-' or '.'"),
    ("am", "azimuth_deg", 0.0, "at least a base's width (0.24 m) apart"),
]


@pytest.mark.parametrize("table,key,value,words", IMPLAUSIBLE, ids=[f"{i[0]}.{i[1]}" for i in IMPLAUSIBLE])
def test_implausible_values_exit_2_naming_file_key_and_range(tmp_path, capsys, table, key, value, words):
    """Through a process main, as a user meets them: exit 2, one line naming the file, the key
    and what would be plausible."""
    from simulator.main import main

    path = _scenario(tmp_path, table, key, value)
    assert main(["--config", str(path), "--run-dir", str(tmp_path / "run"), "--gcs", "none", "--insecure"]) == 2
    err = capsys.readouterr().err
    assert str(path) in err and key in err and words in err, err
    assert not (tmp_path / "run").exists()  # refused before anything started


def test_azimuths_closer_than_a_base_at_the_start_are_refused_and_the_rest_load(tmp_path):
    """Two AMs on the 0.2 m box, 0.25 m standoff: pads start 0.35 m from the centre, so a base's
    width (0.24 m, the URDF's collision box) between them needs about 40 deg of azimuth (more
    off the box's axes, where its faces are farther)."""
    for az, ok in ((45.0, True), (30.0, False)):
        path = _scenario(tmp_path, "am", "azimuth_deg", az)
        if ok:
            assert load_scenario(path).ams[0].azimuth_deg == az
        else:
            with pytest.raises(ConfigError, match=r"#2\.azimuth_deg: sysid 5 .* about 40 deg"):
                load_scenario(path)
