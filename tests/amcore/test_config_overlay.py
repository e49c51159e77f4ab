"""Scenarios as overlays (amcore.config.resolve_base): the merge rule, `unset`, paths in a base
read from the base's folder, every error naming its files and key, and the shipped overlays
resolving to exactly the scenarios their former full copies defined."""
from __future__ import annotations

import copy
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amcore.config import (SCENARIOS_DIR, ConfigError, _read_toml, load_scenario, merge_tables, read_scenario,
                           scenario_from_dict, scenario_id)

ROOT = Path(__file__).resolve().parents[2]
VEHICLES = ROOT / "configs" / "vehicles"
COMP = SCENARIOS_DIR / "two_am_comp.toml"

# scenario_id of every shipped scenario as its full copy defined it, recorded before the copies
# became overlays. A change to a scenario, a vehicle file, a URDF or the spec's fields (a new key,
# even with a default) changes fingerprints: then record them again, scenario_id(load_scenario(p)).
# The four 4dof ones were recorded again when the allocation's pseudo-inverse became exact
# (amcore.allocation.pinv_exact): am4dof leaves its attitude-mode gains to the loader, which
# derives them from the mix's torque units, and LAPACK's last bits had depended on the CPU's
# BLAS kernel. With LAPACK's pinv on OpenBLAS's SkylakeX kernel the overlays still give their
# full copies' former values (0x1fe7e05d, 0x47e677b0, 0x4f227f23, 0x1863b22b).
FINGERPRINTS = {
    "ten_am": 0x48197161,
    "ten_am_attitude": 0xA9296F41,
    "ten_am_robust": 0xA4C41715,
    "ten_am_robust_attitude": 0x6757C2D8,
    "two_am_baseline": 0xA7249978,
    "two_am_comp": 0xBD8FAB8A,
    "two_am_comp_4dof": 0xCEA8A424,
    "two_am_comp_4dof_attitude": 0x96787342,
    "two_am_comp_attitude": 0xDF29BE17,
    "two_am_comp_hex": 0x898F7D6D,
    "two_am_comp_hex_attitude": 0x3C5EF5BE,
    "two_am_nocomp": 0x88E42674,
    "two_am_nocomp_attitude": 0x612C2457,
    "two_am_nocomp_hex": 0x36FBCBDA,
    "two_am_nocomp_hex_attitude": 0x8C7F74C3,
    "two_am_robust": 0xF750D906,
    "two_am_robust_4dof": 0xD70373BC,
    "two_am_robust_4dof_attitude": 0xA342719E,
    "two_am_robust_attitude": 0xE974E78E,
    "two_am_robust_quad": 0x010144B1,
    "two_am_robust_quad_attitude": 0x4261B20F,
    "two_am_short": 0x306E9D37,
}
GUIDE_FINGERPRINTS = {"four_am": 0x99AC2C66}  # docs/guides/four_am.toml


def test_every_shipped_scenario_resolves_to_the_fingerprint_its_full_copy_had():
    paths = {name: SCENARIOS_DIR / f"{name}.toml" for name in FINGERPRINTS}
    paths |= {name: ROOT / "docs" / "guides" / f"{name}.toml" for name in GUIDE_FINGERPRINTS}
    now = {name: scenario_id(load_scenario(p)) for name, p in paths.items()}
    assert {k: f"{v:#010x}" for k, v in now.items()} == \
        {k: f"{v:#010x}" for k, v in (FINGERPRINTS | GUIDE_FINGERPRINTS).items()}


def test_each_attitude_scenario_is_an_overlay_of_its_torque_mode_twin_that_says_so():
    """... and changes only what attitude mode needs: the companions' rate, the mode, the rotors."""
    for p in sorted(SCENARIOS_DIR.glob("*_attitude.toml")):
        raw, twin = _read_toml(p), p.with_name(p.name.replace("_attitude", ""))
        assert raw["base"] == twin.name, p.name
        assert p.read_text().startswith("#") and "overlay of" in p.read_text(), p.name
        ours, theirs = read_scenario(p), read_scenario(twin)
        assert ours["flight_controller"]["mode"] == "attitude" and "rotors" not in ours
        assert {k: v for k, v in ours.items() if k not in ("scenario", "flight_controller")} == \
            {k: v for k, v in theirs.items() if k not in ("scenario", "rotors", "flight_controller")}, p.name
        assert load_scenario(p).vehicle.rotors.lagging and not load_scenario(twin).vehicle.rotors.lagging


def test_a_resolved_scenario_has_no_base_and_a_file_without_one_reads_as_it_is():
    assert read_scenario(COMP) == _read_toml(COMP)
    data = read_scenario(SCENARIOS_DIR / "two_am_robust_4dof_attitude.toml")  # five bases deep
    assert "base" not in data and "unset" not in data
    assert data["scenario"]["vehicle"] == "../vehicles/am4dof.toml" and data["pad"]["shape"] == "crowned"


# ----------------------------------------------------------------------------- the merge rule
def test_tables_merge_key_by_key_and_everything_else_replaces_the_whole():
    base = {"a": 1, "t": {"x": 1, "y": [1, 2], "sub": {"p": 1, "q": 2}}, "am": [{"sysid": 4}, {"sysid": 5}],
            "s": "text"}
    over = {"t": {"y": [3], "sub": {"q": 3}}, "am": [{"sysid": 7}], "s": "other", "new": {"k": True}}
    before = copy.deepcopy((base, over))
    assert merge_tables(base, over) == {
        "a": 1, "t": {"x": 1, "y": [3], "sub": {"p": 1, "q": 3}}, "am": [{"sysid": 7}], "s": "other",
        "new": {"k": True}}
    assert (base, over) == before  # neither argument changed
    assert merge_tables({"t": {"x": 1}}, {"t": 5}) == {"t": 5}  # a value for a table replaces it
    assert merge_tables({"t": 5}, {"t": {"x": 1}}) == {"t": {"x": 1}}


_values = st.one_of(st.integers(-5, 5), st.booleans(), st.text(max_size=3), st.lists(st.integers(0, 3), max_size=2))
_tables = st.recursive(st.dictionaries(st.sampled_from("abc"), _values, max_size=3),
                       lambda inner: st.dictionaries(st.sampled_from("abc"), st.one_of(_values, inner), max_size=3),
                       max_leaves=8)


def _literal_merge(base: dict, over: dict) -> dict:
    """The rule as the reference states it, one key at a time."""
    out = dict(base)
    for k in over:
        both_tables = isinstance(base.get(k), dict) and isinstance(over[k], dict)
        out[k] = _literal_merge(base[k], over[k]) if both_tables else over[k]
    return out


@settings(max_examples=200, deadline=None)
@given(_tables, _tables)
def test_the_merge_is_the_literal_rule_and_laying_an_overlay_twice_changes_nothing(a, b):
    ab = merge_tables(a, b)
    assert ab == _literal_merge(a, b)
    assert merge_tables(ab, b) == ab
    assert merge_tables(a, {}) == a and merge_tables({}, b) == b


# ----------------------------------------------------------------------------- files and paths
def _vehicle(tmp_path: Path) -> Path:
    """am3dof.toml copied to tmp_path/vehicles/ (its URDF where it is)."""
    v = tmp_path / "vehicles" / "v.toml"
    v.parent.mkdir(parents=True, exist_ok=True)
    v.write_text((VEHICLES / "am3dof.toml").read_text().replace('urdf = "am3dof.urdf"',
                                                                f'urdf = "{VEHICLES / "am3dof.urdf"}"'))
    return v


def _write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_paths_in_a_base_stay_relative_to_the_file_that_wrote_them(tmp_path):
    """A base in one folder, its overlay two folders away: the base's vehicle and key file are
    the base's; a vehicle the overlay names is read from the overlay's folder."""
    _vehicle(tmp_path)
    key = _write(tmp_path / "bases" / "link.key", "ab" * 32 + "\n")
    base = _write(tmp_path / "bases" / "base.toml", COMP.read_text().replace(
        'vehicle = "../vehicles/am3dof.toml"', 'vehicle = "../vehicles/v.toml"') + '\n[link]\nkey_file = "link.key"\n')
    over = _write(tmp_path / "variants" / "deep" / "over.toml",
                  'base = "../../bases/base.toml"\n\n[scenario]\nname = "over"\n')
    spec, ref = load_scenario(over), load_scenario(base)
    assert spec.link.key_path(spec.path) == key.resolve() == ref.link.key_path(ref.path)
    assert spec.vehicle == ref.vehicle and spec.name == "over"
    data = read_scenario(over)
    assert data["scenario"]["vehicle"] == "../../vehicles/v.toml" and data["link"]["key_file"] == "../../bases/link.key"
    assert scenario_from_dict(data, over) == spec  # the resolved data loads alone, from the overlay's folder
    hex_vehicle = _write(tmp_path / "variants" / "deep" / "hex.toml", (VEHICLES / "hex3dof.toml").read_text().replace(
        'urdf = "hex3dof.urdf"', f'urdf = "{VEHICLES / "hex3dof.urdf"}"'))
    over.write_text(over.read_text() + 'vehicle = "hex.toml"\n')
    assert load_scenario(over).vehicle.urdf == (VEHICLES / "hex3dof.urdf").resolve() != spec.vehicle.urdf
    assert read_scenario(over)["scenario"]["vehicle"] == "hex.toml" and hex_vehicle.is_file()


def test_a_base_may_have_a_base_and_unset_removes_keys_and_tables_of_the_base(tmp_path):
    v = _vehicle(tmp_path)
    _write(tmp_path / "a.toml", COMP.read_text().replace('vehicle = "../vehicles/am3dof.toml"', f'vehicle = "{v}"'))
    _write(tmp_path / "b.toml", 'base = "a.toml"\n\n[mission]\nsqueeze_max_n = 12.0\nenvelope_check = true\n')
    c = _write(tmp_path / "c.toml", 'base = "b.toml"\nunset = ["rotors", "mission.envelope_check"]\n\n'
                                    '[scenario]\nname = "c"\n')
    data = read_scenario(c)
    assert "rotors" not in data and "envelope_check" not in data["mission"]
    assert data["mission"]["squeeze_max_n"] == 12.0 and data["mission"]["squeeze_m"] == 0.03
    spec = load_scenario(c)
    assert spec.vehicle.rotors.lagging and spec.mission.squeeze_max_n == 12.0 and not spec.mission.envelope_check
    # unset comes first: the overlay may then give the table anew, replacing the base's whole
    c.write_text('base = "b.toml"\nunset = ["mission"]\n\n[mission]\nsqueeze_m = 0.02\n')
    assert read_scenario(c)["mission"] == {"squeeze_m": 0.02}


# ----------------------------------------------------------------------------- errors
def _overlay(tmp_path: Path, text: str) -> Path:
    return _write(tmp_path / "over" / "o.toml", text)


@pytest.mark.parametrize("text,words", [
    ("base = 3\n", "base: expected the path of a scenario TOML (relative to this file's folder), got 3"),
    ('base = ""\n', "base: expected the path of a scenario TOML"),
    ('base = ["a.toml"]\n', "base: expected the path of a scenario TOML"),
    ('unset = ["rotors"]\n', "unset: needs a base"),
    (f'base = "{COMP}"\nunset = "rotors"\n', "unset: expected a list of dotted keys of the base"),
    (f'base = "{COMP}"\nunset = [1]\n', "unset: expected a list of dotted keys of the base"),
    (f'base = "{COMP}"\nunset = ["pad"]\n', f"unset: 'pad' is not in the base ({COMP})"),
    (f'base = "{COMP}"\nunset = ["mission.nothing"]\n', "unset: 'mission.nothing' is not in the base"),
    (f'base = "{COMP}"\nunset = ["mission.squeeze_m.x"]\n', "unset: 'mission.squeeze_m.x' is not in the base"),
])  # fmt: skip
def test_a_bad_base_or_unset_is_a_config_error_naming_the_file_and_key(tmp_path, text, words):
    p = _overlay(tmp_path, text)
    for read in (load_scenario, read_scenario):
        with pytest.raises(ConfigError) as e:
            read(p)
        assert str(e.value).startswith(f"{p}: ") and words in str(e.value), str(e.value)


def test_a_base_that_cannot_be_read_names_both_files(tmp_path):
    missing = tmp_path / "over" / "nowhere.toml"
    p = _overlay(tmp_path, 'base = "nowhere.toml"\n')
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    assert str(e.value) == f"{p}: base = 'nowhere.toml': {missing}: file not found"
    _write(tmp_path / "over" / "bad.toml", "[scenario\nname = 1\n")
    p.write_text('base = "bad.toml"\n')
    with pytest.raises(ConfigError, match=r"o\.toml: base = 'bad.toml': .*bad\.toml: not valid TOML"):
        load_scenario(p)
    (tmp_path / "over" / "dir.toml").mkdir()
    p.write_text('base = "dir.toml"\n')
    with pytest.raises(ConfigError, match=r"o\.toml: base = 'dir.toml': .*dir\.toml: is a directory"):
        read_scenario(p)
    # two bases deep: every file on the way is named
    _write(tmp_path / "over" / "mid.toml", 'base = "nowhere.toml"\n')
    p.write_text('base = "mid.toml"\n')
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    assert str(e.value) == f"{p}: base = 'mid.toml': {p.with_name('mid.toml')}: base = 'nowhere.toml': {missing}: file not found"


def test_a_cycle_of_bases_is_refused_naming_the_chain(tmp_path):
    a = _write(tmp_path / "a.toml", 'base = "sub/b.toml"\n')
    b = _write(tmp_path / "sub" / "b.toml", 'base = "../a.toml"\n')
    with pytest.raises(ConfigError) as e:
        load_scenario(a)
    assert f"a cycle of bases: {a} -> {b} -> {a}" in str(e.value) and str(e.value).startswith(f"{a}: ")
    a.write_text('base = "a.toml"\n')
    with pytest.raises(ConfigError, match=r"base = 'a.toml': a cycle of bases: .*a\.toml -> .*a\.toml$"):
        load_scenario(a)


def test_an_error_in_a_key_the_base_set_names_the_overlay_and_its_bases(tmp_path):
    v = _vehicle(tmp_path)
    _write(tmp_path / "a.toml", COMP.read_text().replace('vehicle = "../vehicles/am3dof.toml"', f'vehicle = "{v}"')
           .replace("mass_kg = 1.0", "mass_kg = -1.0"))
    _write(tmp_path / "b.toml", 'base = "a.toml"\n')
    c = _write(tmp_path / "c.toml", 'base = "b.toml"\n')
    with pytest.raises(ConfigError) as e:
        load_scenario(c)
    assert str(e.value).startswith(f"{c} (over b.toml, a.toml): [object].mass_kg: must be in [0.01, 100] kg")
    c.write_text('base = "b.toml"\n\n[object]\nmass_kg = 1.0\ncolour = 3\n')  # the overlay's own key
    with pytest.raises(ConfigError, match=r"c\.toml \(over b\.toml, a\.toml\): \[object\]: unknown key 'colour'"):
        load_scenario(c)


def test_the_clis_exit_2_on_a_bad_base_naming_both_files(tmp_path, capsys):
    from sitl import inprocess
    from trials import cli

    p = _overlay(tmp_path, 'base = "nowhere.toml"\n')
    assert inprocess.main([str(p)]) == 2
    err = capsys.readouterr().err
    assert str(p) in err and str(p.with_name("nowhere.toml")) in err and "file not found" in err
    assert cli.main([str(p), "--trials", "1", "--seed", "1", "--out", str(tmp_path / "out"), "--workers", "1",
                     "--no-plots", "--no-progress"]) == 2
    assert "base = 'nowhere.toml'" in capsys.readouterr().err
