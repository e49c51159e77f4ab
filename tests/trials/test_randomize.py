"""Drawing trials (trials.randomize) and writing them as scenarios (amcore.toml_write):
reproducible per trial, inside the stated ranges, valid scenarios, replayable bit for bit."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amcore.config import ConfigError, read_scenario, scenario_from_dict
from trials.randomize import draw_trial, load_randomize, randomize_from_table, relocate
from amcore.toml_write import dumps

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "configs" / "scenarios" / "two_am_comp.toml"
TEN = ROOT / "configs" / "scenarios" / "ten_am.toml"
ROBUST = ROOT / "configs" / "scenarios" / "two_am_robust.toml"
DEFAULT = load_randomize(ROOT / "configs" / "randomize" / "default.toml")


def test_a_trial_is_a_function_of_seed_and_index_alone():
    base = read_scenario(SCENARIO)
    a = [draw_trial(base, DEFAULT, 5, i) for i in range(6)]
    b = [draw_trial(base, DEFAULT, 5, i) for i in (5, 3, 1, 0, 2, 4)]
    assert a[3] == b[1] and a[0] == b[3] and a[5] == b[0]
    assert draw_trial(base, DEFAULT, 6, 0) != a[0]
    assert len({p["seed"] for _, p in a}) == 6  # each trial its own sensor and link noise


def test_draws_stay_in_the_default_ranges_and_make_valid_scenarios():
    base = read_scenario(SCENARIO)  # a paper scenario: the draws make it plan from the measured object
    assert base.get("mission", {}).get("object_pose", "config") == "config"
    for i in range(40):
        data, p = draw_trial(base, DEFAULT, 1, i)
        spec = scenario_from_dict(data, SCENARIO)
        assert 0.5 <= spec.object.mass_kg <= 1.5 and 0.5 <= spec.object.pad_object_friction <= 1.2
        assert spec.object.size_m[0] == pytest.approx(0.2 * p["object_size_scale"]) and 0.16 <= spec.object.size_m[0] <= 0.24
        assert 0.0 <= spec.link.loss <= 0.05 and spec.sensors.exact
        assert spec.devices.enabled and spec.devices.mocap.latency_s == DEFAULT.devices["mocap"]["latency_s"]
        assert spec.devices.imu.gyroscope_noise_density == DEFAULT.devices["imu"]["gyroscope_noise_density"]
        assert spec.mission.object_pose == "mocap"
        for am in spec.ams:
            assert am.misalignment_deg == 0.0 and abs(am.start_heading_deg) <= 5.0
            assert max(map(abs, am.start_offset_m)) <= 0.05
        assert spec.seed == p["seed"] and spec.name == f"two_am_comp-{i:04d}"


def test_a_table_that_moves_the_object_sets_or_demands_where_the_team_takes_its_pose_from():
    base = read_scenario(SCENARIO)
    moved = {"object_position_m": 0.1, "object_yaw_deg": 30.0}
    with pytest.raises(ConfigError) as e:  # a blind team would miss the moved object: refused, named
        draw_trial(base, randomize_from_table(moved, "r.toml"), 1, 0)
    assert "object_pose" in str(e.value) and "mocap" in str(e.value)
    blind, _ = draw_trial(base, randomize_from_table({**moved, "object_pose": "config"}, "r.toml"), 1, 0)
    assert scenario_from_dict(blind, SCENARIO).mission.object_pose == "config"  # on purpose: allowed
    measured, _ = draw_trial(base, randomize_from_table({**moved, "object_pose": "mocap"}, "r.toml"), 1, 0)
    assert scenario_from_dict(measured, SCENARIO).mission.object_pose == "mocap"
    # the key draws nothing: the same trial with or without it, but for where the pose comes from
    assert {k: v for k, v in measured.items() if k != "mission"} == {k: v for k, v in blind.items() if k != "mission"}
    robust = read_scenario(ROBUST)  # a scenario that plans from the measurement already needs no key
    assert scenario_from_dict(draw_trial(robust, randomize_from_table(moved, "r.toml"), 1, 0)[0],
                              ROBUST).mission.object_pose == "mocap"


def test_a_cylinder_scales_radius_and_height():
    data, p = draw_trial(read_scenario(TEN), DEFAULT, 2, 0)
    spec = scenario_from_dict(data, TEN)
    assert spec.object.radius_m == pytest.approx(0.6 * p["object_size_scale"])
    assert spec.object.height_m == pytest.approx(0.3 * p["object_size_scale"])
    assert len([k for k in p if k.endswith("_start_heading_deg")]) == 10


def test_a_written_trial_reads_back_as_the_same_scenario(tmp_path):
    data, _ = draw_trial(read_scenario(SCENARIO), DEFAULT, 3, 17)
    out = tmp_path / "deep" / "t.toml"
    out.parent.mkdir(parents=True)
    moved = relocate(data, SCENARIO, out.parent)
    out.write_text(dumps(moved))
    assert tomllib.loads(out.read_text()) == moved
    a, b = scenario_from_dict(data, SCENARIO), scenario_from_dict(tomllib.loads(out.read_text()), out)
    assert a.vehicle == b.vehicle and a.object == b.object and a.ams == b.ams and a.sensors == b.sensors
    assert a.devices == b.devices
    assert a.link == b.link and a.seed == b.seed


def test_the_trials_of_an_overlay_are_self_contained_and_its_campaign_may_be_its_bases(tmp_path):
    """A trial of an overlay is written resolved (no base, the vehicle's rotors where the overlay
    unset the base's) and loads alone; an overlay's [randomize] is its base's unless it gives one."""
    from trials.cli import build_tasks

    overlay = ROOT / "configs" / "scenarios" / "ten_am_robust_attitude.toml"
    own = tomllib.loads(overlay.read_text())
    assert "base" in own and "randomize" not in own
    rand = load_randomize(overlay)
    assert rand == load_randomize(ROOT / "configs" / "scenarios" / "ten_am_robust.toml") and rand.object_mass_kg
    tasks = build_tasks(read_scenario(overlay), overlay, rand, 4, 2, tmp_path, None)
    for task in tasks:
        data = tomllib.loads(Path(task.path).read_text())
        assert not {"base", "unset", "rotors", "randomize"} & set(data)
        spec = scenario_from_dict(data, Path(task.path))
        assert spec.vehicle.flight_controller.mode == "attitude" and spec.vehicle.rotors.lagging
        assert spec.vehicle.urdf.parent == tmp_path / "scenarios" / "vehicle"  # its own copy (snapshot_vehicle)


@settings(max_examples=60, deadline=None)
@given(st.recursive(
    st.one_of(st.integers(-2**62, 2**62), st.floats(allow_nan=False), st.booleans(), st.text(max_size=8)),
    lambda inner: st.lists(inner, max_size=3), max_leaves=6))
def test_toml_writer_round_trips_values(value):
    doc = {"t": {"v": value}}
    assert tomllib.loads(dumps(doc)) == doc


@pytest.mark.parametrize("table,words", [
    ({"object_mass_kg": [2.0, 1.0]}, "object_mass_kg: expected [low, high] with low <= high"),
    ({"object_mass_kg": [0.0, 1.0]}, "object_mass_kg: [0.0, 1.0] is out of range (values > 0)"),
    ({"setpoint_loss": [0.0, 1.5]}, "setpoint_loss: [0.0, 1.5] is out of range"),
    ({"misalignment_deg": -1.0}, "misalignment_deg: must be >= 0"),
    ({"misalignment_deg": 50.0}, "misalignment_deg: must be < 45"),
    ({"object_colour": [1.0, 2.0]}, "unknown key 'object_colour'"),
    ({"sensors": {"gps_noise_m": 1.0}}, "[randomize.sensors]: unknown key 'gps_noise_m'"),
    ({"sensors": {"force_noise_n": -1.0}}, "force_noise_n: must be >= 0"),
    ({"pad_friction": "high"}, "pad_friction: expected a list"),
    ({"planned_mass_tolerance": 0.6}, "planned_mass_tolerance: must be in [0, 0.5]"),
    ({"planned_mass_tolerance": -0.1}, "planned_mass_tolerance: must be in [0, 0.5]"),
    ({"object_yaw_deg": 200.0}, "object_yaw_deg: must be in [0, 180]"),
    ({"object_position_m": -0.1}, "object_position_m: must be in [0, 1]"),
    ({"object_position_m": "far"}, "object_position_m: expected a number"),
    ({"object_pose": "gps"}, "object_pose: expected one of config, mocap, got 'gps'"),
])
def test_a_bad_randomize_table_names_the_key(table, words):
    with pytest.raises(ConfigError) as e:
        randomize_from_table(table, "r.toml")
    assert "r.toml" in str(e.value) and words in str(e.value)


def test_the_stress_option_draws_white_noise_on_the_states():
    stress = load_randomize(ROOT / "configs" / "randomize" / "stress_states.toml")
    data, _ = draw_trial(read_scenario(SCENARIO), stress, 1, 0)
    spec = scenario_from_dict(data, SCENARIO)
    assert not spec.devices.enabled and spec.sensors.force_noise_n == stress.sensors["force_noise_n"]
    assert 0.0 <= spec.sensors.latency_s <= 0.002


def test_the_sensors_only_campaign_has_the_default_device_levels_and_nothing_else():
    only = load_randomize(ROOT / "configs" / "randomize" / "sensors_only.toml")
    assert only.devices == DEFAULT.devices  # one set of levels: the two files may not drift apart
    assert only.ranges() == {} and not only.sensors
    assert (only.misalignment_deg, only.start_offset_m, only.start_heading_deg) == (0.0, 0.0, 0.0)


def test_a_scenarios_own_device_keys_win_over_the_randomized_ones():
    base = read_scenario(SCENARIO)
    base["devices"] = {"scale": 3.0, "estimator": {"gyro_cutoff_hz": 0.0}}
    spec = scenario_from_dict(draw_trial(base, DEFAULT, 1, 0)[0], SCENARIO)
    assert spec.devices.scale == 3.0 and spec.devices.estimator.gyro_cutoff_hz == 0.0
    assert spec.devices.estimator.history_steps == DEFAULT.devices["estimator"]["history_steps"]
    assert spec.devices.imu.gyroscope_noise_density == DEFAULT.devices["imu"]["gyroscope_noise_density"]


STRESS = load_randomize(ROOT / "configs" / "randomize" / "stress.toml")


def test_the_default_draws_on_two_am_robust_make_deployment_trials():
    base = read_scenario(ROBUST)
    yaws = []
    for i in range(40):
        data, p = draw_trial(base, DEFAULT, 11, i)
        spec = scenario_from_dict(data, ROBUST)
        m, plan = spec.object.mass_kg, spec.mission.planned_mass_kg
        assert 0.5 <= m <= 1.5 and abs(plan / m - 1.0) <= 0.1 and spec.mission.mass_tolerance == 0.1
        assert plan / (1.0 - 0.1) >= m  # the plan's worst case covers the true mass
        x, y, z = spec.object.position_m
        assert max(abs(x), abs(y)) <= 0.1 and z == 0.6 and (x, y) == (p["object_dx_m"], p["object_dy_m"])
        assert abs(spec.object.yaw_deg) <= 180.0
        yaws.append(spec.object.yaw_deg)
        assert 0.0 <= spec.link.loss <= 0.05 and spec.devices.enabled and spec.sensors.exact
        assert spec.mission.object_pose == "mocap" and spec.mission.envelope_check
        for am in spec.ams:
            assert am.misalignment_deg == 0.0 and max(map(abs, am.start_offset_m)) <= 0.05
    assert max(yaws) - min(yaws) > 180.0  # the draws reach across the whole turn


def test_the_stress_and_ten_am_files_keep_the_default_device_levels():
    ten = load_randomize(ROOT / "configs" / "scenarios" / "ten_am_robust.toml")
    assert ten.devices == DEFAULT.devices
    assert {k: v for k, v in STRESS.devices.items() if k != "scale"} == DEFAULT.devices
    assert STRESS.devices["scale"] == 2.0 and STRESS.misalignment_deg == 5.0 and STRESS.setpoint_loss == (0.1, 0.1)
    for name in ("object_mass_kg", "object_size_scale", "pad_friction"):  # the same ranges otherwise
        assert getattr(STRESS, name) == getattr(DEFAULT, name) == getattr(ten, name) or name == "object_mass_kg"
    assert ten.object_mass_kg == tuple(10 / 2 * m for m in DEFAULT.object_mass_kg)  # the mass scales with the team
    assert STRESS.object_pose == DEFAULT.object_pose == ten.object_pose == "mocap"
    for name in ("planned_mass_tolerance", "object_position_m", "object_yaw_deg", "start_offset_m"):
        assert getattr(STRESS, name) == getattr(DEFAULT, name) == getattr(ten, name) > 0.0


def test_a_table_without_the_new_keys_draws_none_of_them():
    old = randomize_from_table({"object_mass_kg": [0.5, 2.0], "misalignment_deg": 5.0, "setpoint_loss": [0.0, 0.1]}, "r")
    _, p = draw_trial(read_scenario(SCENARIO), old, 5, 0)
    assert not {"planned_mass_kg", "object_dx_m", "object_yaw_deg"} & set(p)


def test_the_setpoint_loss_campaigns_lose_ten_percent_on_every_trial_and_nothing_else_varies():
    loss = load_randomize(ROOT / "configs" / "randomize" / "setpoint_loss.toml")
    assert loss.ranges() == {"setpoint_loss": (0.1, 0.1)} and not loss.devices and not loss.sensors
    assert (loss.misalignment_deg, loss.start_offset_m, loss.start_heading_deg) == (0.0, 0.0, 0.0)
    sensors = load_randomize(ROOT / "configs" / "randomize" / "setpoint_loss_sensors.toml")
    assert sensors.ranges() == loss.ranges() and sensors.devices == DEFAULT.devices and not sensors.sensors


def test_am_trials_refuses_a_campaign_that_moves_the_object_for_a_blind_team(tmp_path, capsys):
    from trials import cli

    rand = tmp_path / "moved.toml"
    rand.write_text("[randomize]\nobject_yaw_deg = 30.0\n")
    assert cli.main([str(SCENARIO), "--trials", "2", "--seed", "1", "--out", str(tmp_path / "c"),
                     "--randomize", str(rand), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "am-trials: error:" in err and "object_pose" in err and "blind" in err
    assert not (tmp_path / "c" / "trials.csv").exists()  # nothing flew
