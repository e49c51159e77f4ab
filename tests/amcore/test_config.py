"""Typed configuration: every scenario loads; malformed files name the file and key;
the scenario fingerprint that companions check against the simulator's."""
from __future__ import annotations

from pathlib import Path

import pytest

from amcore.config import ConfigError, load_scenario, load_vehicle, scenario_id

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = sorted((ROOT / "configs" / "scenarios").glob("*.toml"))
VEHICLE = ROOT / "configs" / "vehicles" / "am3dof.toml"


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_every_scenario_loads(path):
    spec = load_scenario(path)
    assert spec.name == path.stem
    assert len({a.sysid for a in spec.ams}) == len(spec.ams)


def _write(tmp_path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text.replace('vehicle = "../vehicles/am3dof.toml"', f'vehicle = "{VEHICLE}"'))
    return p


BASE = (ROOT / "configs" / "scenarios" / "two_am_comp.toml").read_text()


@pytest.mark.parametrize("old,new,key", [
    ("mass_kg = 1.0", "mass_kg = 1.0\ncolour = 3", "[object]: unknown key 'colour'"),
    ("mass_kg = 1.0", 'mass_kg = "heavy"', "[object].mass_kg: expected a number"),
    ("mass_kg = 1.0", "mass_kg = -1.0", "[object].mass_kg: must be in [0.01, 100] kg"),
    ("sysid = 5", "sysid = 4", "sysid: duplicate sysid 4"),
    ("sysid = 5", "sysid = 1", "must be in 2..255"),
    ("squeeze_m = 0.03", "squeeze_m = [0.03]", "[mission].squeeze_m: expected a number"),
    ("[object]", "[objekt]", "unknown table [objekt]"),
    ("approach_end_s = 5.0", "approach_end_s = 15.0", "approach_end_s < grasp_end_s"),
    ("squeeze_m = 0.03", "squeeze_m = 0.03\njoin_blend_s = 0.0", "[mission].join_blend_s: must be > 0"),
    ("mass_kg = 1.0", "mass_kg = 1.0\npad_friction = -0.5", "[object].pad_friction: must be >= 0"),
    ("[mission]", "[success]\nmin_slip = 1.0\n[mission]", "[success]: unknown key 'min_slip'"),
    ("[mission]", "[success]\nmax_slip_m = -1.0\n[mission]", "[success].max_slip_m: must be >= 0"),
    ("[mission]", "[sensors]\nforce_noise_n = -1.0\n[mission]", "[sensors].force_noise_n: must be >= 0"),
    ("[mission]", "[sensors]\ngps_noise_m = 1.0\n[mission]", "[sensors]: unknown key 'gps_noise_m'"),
    ("[mission]", "[devices.imu]\ngyro_noise = 1.0\n[mission]", "[devices.imu]: unknown key 'gyro_noise'"),
    ("[mission]", "[devices.mocap]\nrate_hz = 0.0\n[mission]", "[devices.mocap].rate_hz: must be in [1, 1000] Hz"),
    ("[mission]", "[devices]\nscale = -1.0\n[mission]", "[devices].scale: must be >= 0"),
    ("[mission]", "[devices]\nenabled = true\n[sensors]\nforce_noise_n = 0.1\n[mission]",
     "[devices].enabled: the device models replace [sensors]"),
    ("sysid = 4\n", "sysid = 4\nmisalignment_deg = 50.0\n", "misalignment_deg: must be in (-45, 45) deg"),
    ("sysid = 4\n", "sysid = 4\nstart_offset_m = [0.1]\n", "start_offset_m: expected 3 entries"),
    ("[object]", '[flight_controller]\nmode = "rates"\n[object]', "[flight_controller].mode: expected one of torque"),
    ("[object]", "[flight_controller]\nrate_hz = 300.0\n[object]", "[flight_controller].rate_hz: 300 Hz must divide"),
    ("[object]", "[flight_controller]\nMC_ROLLRATE_D = -0.1\n[object]", "MC_ROLLRATE_D: must be >= 0"),
    ("[object]", "[flight_controller]\nMC_YAW_WEIGHT = 1.5\n[object]", "MC_YAW_WEIGHT: must be in [0, 1]"),
    ("[object]", "[flight_controller]\nMC_ROLL_RATE_P = 0.1\n[object]", "unknown key 'MC_ROLL_RATE_P'"),
    ("[object]", "[flight_controller]\nactuation_delay_steps = -1\n[object]", "actuation_delay_steps: must be >= 0, got -1"),
    ("[object]", "[flight_controller]\nactuation_delay_steps = 0.5\n[object]", "actuation_delay_steps"),
    ("[object]", "[flight_controller]\nactuation_delay_steps = 2\n[object]",
     "actuation_delay_steps: at most the control period, 1 physics step here, got 2"),
    ("time_constant_s = 0.0", "time_constant_s = -0.01", "[rotors].time_constant_s: must be in [0, 1] s"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\ncontrol_rate_hz = 400.0", "control_rate_hz: 400 Hz must divide"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\ncontrol_rate_hz = 2000.0", "control_rate_hz: 2000 Hz must divide"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nphysics_substeps = 3", "[scenario].physics_substeps: expected one of 1, 2, got 3"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nphysics_substeps = 0", "[scenario].physics_substeps: expected one of"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nphysics_substeps = 2.0", "[scenario].physics_substeps: expected an integer"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nphysics_substeps = true", "[scenario].physics_substeps: expected an integer"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nphysics_substeps = 4", "[scenario].physics_substeps: expected one of 1, 2, got 4"),
    ("rate_hz = 1000.0", "rate_hz = 100000.0\nphysics_substeps = 2",
     "[scenario].physics_substeps: rate_hz x physics_substeps = 200000 Hz, above 100000 Hz"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nsolver_iterations = 9", "[scenario].solver_iterations: must be in 10..1000, got 9"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nsolver_iterations = 1001", "[scenario].solver_iterations: must be in 10..1000"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nsolver_iterations = 25.0", "[scenario].solver_iterations: expected an integer"),
    ("rate_hz = 1000.0", "rate_hz = 1000.0\nsolver_iterations = false", "[scenario].solver_iterations: expected an integer"),
    ("[object]", "[options]\nlateral_admittance_hz = -0.3\n[object]", "[options].lateral_admittance_hz: must be >= 0"),
    ("[object]", "[options]\nlateral_admittance_zeta = 0.0\n[object]", "lateral_admittance_zeta: must be > 0"),
    ("[object]", "[options]\ntrim_hz = -0.1\n[object]", "[options].trim_hz: must be >= 0"),
    ("[object]", "[options]\ntrim_hz = nan\n[object]", "[options].trim_hz: must be finite"),
])
def test_malformed_scenario_names_file_and_key(tmp_path, old, new, key):
    assert old in BASE
    p = _write(tmp_path, BASE.replace(old, new, 1))
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    assert str(p) in str(e.value) and key in str(e.value)


def test_missing_urdf_and_missing_file_are_config_errors(tmp_path):
    v = tmp_path / "v.toml"
    v.write_text(VEHICLE.read_text().replace('urdf = "am3dof.urdf"', 'urdf = "nowhere.urdf"'))
    p = tmp_path / "s.toml"
    p.write_text(BASE.replace('vehicle = "../vehicles/am3dof.toml"', f'vehicle = "{v}"'))
    with pytest.raises(ConfigError, match=r"urdf: file not found"):
        load_scenario(p)
    with pytest.raises(ConfigError, match="file not found"):
        load_scenario(tmp_path / "absent.toml")


def test_a_scenario_copied_away_from_its_vehicle_names_the_key_that_points_there(tmp_path):
    """A user's copy of a shipped scenario keeps its relative vehicle path, read from the copy's folder."""
    (tmp_path / "sub").mkdir()
    p = tmp_path / "sub" / "my.toml"
    p.write_text(BASE)
    assert 'vehicle = "../vehicles/am3dof.toml"' in BASE
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    assert str(e.value) == (f"{p}: [scenario].vehicle = '../vehicles/am3dof.toml': {tmp_path / 'vehicles' / 'am3dof.toml'}: "
                            f"file not found (a relative path is read from the scenario's folder, {tmp_path / 'sub'})")


def test_impossible_gains_are_rejected(tmp_path):
    v = tmp_path / "v.toml"
    v.write_text(VEHICLE.read_text().replace("k_R = 30.0", "k_R = 0.0").replace('urdf = "am3dof.urdf"',
                                                                             f'urdf = "{VEHICLE.parent / "am3dof.urdf"}"'))
    p = tmp_path / "s.toml"
    p.write_text(BASE.replace('vehicle = "../vehicles/am3dof.toml"', f'vehicle = "{v}"'))
    with pytest.raises(ConfigError, match=r"\[gains\].k_R: must be > 0"):
        load_scenario(p)


def test_scenario_id_ignores_formatting_and_location_but_not_content(tmp_path):
    a = scenario_id(load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml"))
    moved = _write(tmp_path, "# a comment\n" + BASE.replace("mass_kg = 1.0", "mass_kg   =   1.0"))
    assert scenario_id(load_scenario(moved)) == a
    heavier = _write(tmp_path, BASE.replace("mass_kg = 1.0", "mass_kg = 1.01"))
    assert scenario_id(load_scenario(heavier)) != a
    assert scenario_id(load_scenario(ROOT / "configs" / "scenarios" / "two_am_nocomp.toml")) != a


def test_controller_option_selects_the_law_and_defaults_to_the_papers():
    base = load_scenario(ROOT / "configs" / "scenarios" / "two_am_baseline.toml")
    assert base.vehicle.options.controller == "baseline"
    assert len(base.vehicle.baseline.K_q) == base.vehicle.n_joints
    assert load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml").vehicle.options.controller == "passivity"
    assert scenario_id(base) != scenario_id(load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml"))


def test_unknown_controller_is_rejected_naming_the_key(tmp_path):
    p = _write(tmp_path, BASE + '\n[options]\ncontroller = "pid"\n')
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    assert "[options].controller: expected one of passivity, baseline, got 'pid'" in str(e.value)


def _vehicle_variant(tmp_path, old: str, new: str, options: str = "") -> Path:
    text = VEHICLE.read_text()
    assert old in text
    v = tmp_path / "v.toml"
    urdf = VEHICLE.parent / "am3dof.urdf"
    v.write_text(text.replace(old, new, 1).replace('urdf = "am3dof.urdf"', f'urdf = "{urdf}"'))
    p = tmp_path / "s.toml"
    p.write_text(BASE.replace('vehicle = "../vehicles/am3dof.toml"', f'vehicle = "{v}"') + options)
    return p


@pytest.mark.parametrize("old,new,key", [
    ("ik_damping = 0.01", "ik_damping = 0.01\nk_d = 1.0", "[baseline]: unknown key 'k_d'"),
    ("K_q = [20.0, 5.0, 6.0]", "K_q = [20.0, 5.0]", "[baseline].K_q: expected 3 entries"),
    ("k_x = [86.4, 86.4, 86.4]", "k_x = [86.4, 0.0, 86.4]", "[baseline].k_x: must be > 0"),
    ("k_i = [40.0, 40.0, 40.0]", "k_i = [40.0, -1.0, 40.0]", "[baseline].k_i: must be >= 0"),
    ("ik_iterations = 3", "ik_iterations = 0", "[baseline].ik_iterations: must be >= 1"),
    ("ik_damping = 0.01", 'ik_damping = 0.01\narm = "spline"', "[baseline].arm: expected one of joint, cartesian"),
    ("ik_damping = 0.01", 'ik_damping = 0.01\narm = "cartesian"', "[baseline].K_y: arm = 'cartesian' needs 3 entries"),
    ("ik_damping = 0.01", 'ik_damping = 0.01\narm = "cartesian"\nK_y = [300.0, 300.0, 1.5]\nD_y = [14.0, 0.0, 0.03]',
     "[baseline].D_y: must be > 0"),
    ("ik_damping = 0.01", "ik_damping = 0.01\nreaction_feedforward = true",
     "[baseline].reaction_feedforward: needs arm = 'cartesian'"),
])
def test_malformed_baseline_table_names_file_and_key(tmp_path, old, new, key):
    p = _vehicle_variant(tmp_path, old, new)
    with pytest.raises(ConfigError) as e:
        load_scenario(p)
    assert str(tmp_path / "v.toml") in str(e.value) and key in str(e.value)


def test_baseline_controller_needs_its_gains(tmp_path):
    text = VEHICLE.read_text()
    cut = text.index("\n[baseline]")
    end = text.index("ik_damping = 0.01") + len("ik_damping = 0.01")
    p = _vehicle_variant(tmp_path, text[cut:end], "", options='\n[options]\ncontroller = "baseline"\n')
    with pytest.raises(ConfigError, match=r"controller = 'baseline' needs a \[baseline\] table"):
        load_scenario(p)
    p.write_text(p.read_text().replace('controller = "baseline"', 'controller = "passivity"'))
    assert load_scenario(p).vehicle.baseline is None  # the paper's law does not need it
def test_scenario_overrides_the_vehicles_flight_controller_and_rotors_key_by_key(tmp_path):
    """The paper's scenarios keep ideal rotors although the vehicle's lag; an attitude-mode
    variant changes only what it names."""
    base = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    vehicle_only = _write(tmp_path, BASE.replace("[rotors]\ntime_constant_s = 0.0", ""))
    assert base.vehicle.rotors.time_constant_s == 0.0
    assert load_scenario(vehicle_only).vehicle.rotors.time_constant_s > 0.0  # the vehicle file's value
    text = BASE.replace("rate_hz = 1000.0", "rate_hz = 1000.0\ncontrol_rate_hz = 250.0").replace(
        "[object]", '[flight_controller]\nmode = "attitude"\nMC_ROLL_P = 9.0\n[object]')
    spec = load_scenario(_write(tmp_path, text))
    fc, fc0 = spec.vehicle.flight_controller, base.vehicle.flight_controller
    assert (fc.mode, fc.MC_ROLL_P, fc0.mode) == ("attitude", 9.0, "torque")
    assert fc.MC_PITCH_P == fc0.MC_PITCH_P and spec.vehicle.rotors == base.vehicle.rotors
    assert (spec.control_every, base.control_every) == (4, 1) and spec.control_dt_s == pytest.approx(0.004)


# ----------------------------------------------------------------------------- rotor tables
QUAD_ROWS = VEHICLE.read_text()


def _vehicle_with(tmp_path, text: str) -> Path:
    v = tmp_path / "v.toml"
    v.write_text(text.replace('urdf = "am3dof.urdf"', f'urdf = "{VEHICLE.parent / "am3dof.urdf"}"'))
    return v


FL = 'position_m = [0.21213203435596426, 0.21213203435596426, 0.0]\naxis = [0.0, 0.0, 1.0]\nspin = "cw"'


@pytest.mark.parametrize("old,new,words", [
    (FL, FL.replace("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.0, 0.0]"), "rotor[0].axis: must be a nonzero"),
    (FL, FL.replace("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.0, -1.0]"), "rotor[0].axis: every rotor must thrust upward"),
    (FL, FL.replace('spin = "cw"', 'spin = "left"'), "rotor[0].spin: expected one of ccw, cw"),
    (FL, FL.replace('spin = "cw"', 'spin = "ccw"').replace("0.21213203435596426, 0.21213203435596426",
                                                         "-0.21213203435596426, 0.21213203435596426"),
     "entered twice"),
    ('spin = "cw"', 'spin = "ccw"', "cannot make yaw torque"),  # every rotor ccw: yaw only with thrust
    ("0.21213203435596426, 0.21213203435596426", "0.3, 0.0", None),  # still a valid layout: control
    ("0.21213203435596426, -0.21213203435596426", "0.3, 0.0", None),
    ("moment_ratio_m = 0.016", "moment_ratio_m = -0.016", "moment_ratio_m: must be in (0, 1]"),
    ("thrust_min_n = 0.0", "thrust_min_n = 13.0", "thrust_min_n < thrust_max_n"),
    ("thrust_max_n = 12.0 ", "arm_length_m = 0.3\nthrust_max_n = 12.0 ", "unknown key 'arm_length_m' (the rotors are now"),
    ("thrust_max_n = 12.0 ", "yaw_moment_coeff_m = 0.02\nthrust_max_n = 12.0 ", "being each row's moment_ratio_m"),
])
def test_bad_rotor_geometry_names_file_and_key(tmp_path, old, new, words):
    assert old in QUAD_ROWS
    count = QUAD_ROWS.count(old) if words == "cannot make yaw torque" else 1
    v = _vehicle_with(tmp_path, QUAD_ROWS.replace(old, new, count))
    if words is None:
        load_vehicle(v)
        return
    with pytest.raises(ConfigError) as e:
        load_vehicle(v)
    assert str(v) in str(e.value) and "[rotors]" in str(e.value) and words in str(e.value), str(e.value)


def test_rotors_on_one_line_cannot_roll(tmp_path):
    d = "0.21213203435596426"
    text = QUAD_ROWS
    for (sx, sy), x in zip([("", ""), ("-", ""), ("-", "-"), ("", "-")], ["0.3", "0.1", "-0.1", "-0.3"]):
        old = f"position_m = [{sx}{d}, {sy}{d}, 0.0]"
        assert old in text
        text = text.replace(old, f"position_m = [{x}, 0.0, 0.0]")  # all on the x axis: no roll
    with pytest.raises(ConfigError, match=r"\[rotors\].rotor: this layout cannot make roll torque"):
        load_vehicle(_vehicle_with(tmp_path, text))


def test_old_rotor_keys_say_what_replaced_them(tmp_path):
    start, end = QUAD_ROWS.index("[rotors]"), QUAD_ROWS.index("[task]")
    old = "[rotors]\narm_length_m = 0.30\nthrust_max_n = 12.0\nyaw_moment_coeff_m = 0.016\ncount = 4\nlayout = \"x\"\n\n"
    with pytest.raises(ConfigError, match=r"missing key 'rotor' \(the rotors are now one \[\[rotors.rotor\]\] row"):
        load_vehicle(_vehicle_with(tmp_path, QUAD_ROWS[:start] + old + QUAD_ROWS[end:]))


def test_am_vehicle_prints_authority_and_exits_2_on_bad_geometry(tmp_path, capsys):
    from companion.vehicle import main

    assert main([str(ROOT / "configs" / "vehicles" / "hex3dof.toml"), "--squeeze", "9", "--load", "0.5"]) == 0
    out = capsys.readouterr().out
    line = [x for x in out.splitlines() if x.startswith("yaw authority at hover:")]
    assert len(line) == 1 and float(line[0].split()[-3]) >= 1.0
    assert "thrust margin" in out and "thrust lost to cant: 6.0 %" in out and "loaded hover (squeeze 9 N" in out
    bad = _vehicle_with(tmp_path, QUAD_ROWS.replace("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.0, 0.0]", 1))
    assert main([str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "rotor[0].axis" in err
    with pytest.raises(SystemExit) as e:
        main([str(bad), "--squeeze", "-1"])
    assert e.value.code == 2


def test_am_vehicle_prints_a_teams_payload_and_the_team_an_object_needs(capsys):
    from companion.vehicle import main

    hexa = str(ROOT / "configs" / "vehicles" / "hex3dof.toml")
    assert main([hexa, "--team", "2", "--friction", "0.5", "--mass", "2.5"]) == 4  # outside the envelope: cannot
    out = capsys.readouterr().out.splitlines()
    assert out[-2].startswith("team of 2 at friction 0.5 (margin 1.2) holds up to ")
    assert out[-1].startswith("2.5 kg at friction 0.5 (margin 1.2) needs 29.4 N per pad from 2 AMs")
    assert out[-1].endswith("use 4 AMs")  # three would carry 0.83 kg each: under the pitch reserve
    with pytest.raises(SystemExit) as e:
        main([hexa, "--mass", "2.0"])
    assert e.value.code == 2


@pytest.mark.parametrize("old,new,words", [
    ("\n[options]\n", '\n[options]\noffboard_inputs = "measured"\n', "offboard_inputs: expected one of sent, reported"),
    ("\n[options]\n", "\n[options]\noffboard_torque_cutoff_hz = -1.0\n", "offboard_torque_cutoff_hz: must be >= 0"),
    ("[flight_controller]", "[flight_controller]\nCOM_OF_LOSS_T = 0.0", "COM_OF_LOSS_T: must be > 0"),
    ("\n[options]\n", '\n[options]\noffboard_inputs = "reported"\noffboard_torque_cutoff_hz = 40.0\n'
                       "discrete_damping = true\n", None),
])
def test_attitude_mode_options_are_checked(tmp_path, old, new, words):
    assert QUAD_ROWS.count(old) == 1
    v = _vehicle_with(tmp_path, QUAD_ROWS.replace(old, new))
    if words is None:
        o = load_vehicle(v).options
        assert (o.offboard_inputs, o.offboard_torque_cutoff_hz, o.discrete_damping) == ("reported", 40.0, True)
        return
    with pytest.raises(ConfigError) as e:
        load_vehicle(v)
    assert words in str(e.value) and "v.toml" in str(e.value)


LITERAL = ("sent", 0.0, False)  # the law as first written ([options] offboard_inputs, offboard_torque_cutoff_hz, discrete_damping)
SAMPLED = ("reported", 40.0, True)  # attitude mode's defaults (amcore.config.MODE_OPTION_DEFAULTS)


def _sampling(spec_or_vehicle) -> tuple:
    o = getattr(spec_or_vehicle, "vehicle", spec_or_vehicle).options
    return o.offboard_inputs, o.offboard_torque_cutoff_hz, o.discrete_damping


def test_the_sampling_options_default_by_mode_and_a_file_s_own_values_win(tmp_path):
    """Torque mode keeps the paper's law; attitude mode defaults to the autopilot's reports, the
    40 Hz estimate and the discretized damping; a scenario that writes the literal values (all
    three, or one of them) flies them, and the mode's defaults fill only what it leaves unset."""
    from amcore.config import ControllerOptions

    scenarios = ROOT / "configs" / "scenarios"
    assert _sampling(load_vehicle(VEHICLE)) == LITERAL  # the vehicle file says mode = "torque"
    assert (ControllerOptions().offboard_inputs, ControllerOptions().offboard_torque_cutoff_hz,
            ControllerOptions().discrete_damping) == LITERAL
    assert _sampling(load_scenario(scenarios / "two_am_comp.toml")) == LITERAL
    assert _sampling(load_scenario(scenarios / "two_am_comp_attitude.toml")) == SAMPLED
    attitude = BASE.replace("rate_hz = 1000.0", "rate_hz = 1000.0\ncontrol_rate_hz = 250.0").replace(
        "[object]", '[flight_controller]\nmode = "attitude"\n[object]')
    assert _sampling(load_scenario(_write(tmp_path, attitude))) == SAMPLED
    literal = attitude + '\n[options]\noffboard_inputs = "sent"\noffboard_torque_cutoff_hz = 0.0\ndiscrete_damping = false\n'
    assert _sampling(load_scenario(_write(tmp_path, literal))) == LITERAL
    one = attitude + "\n[options]\ndiscrete_damping = false\n"
    assert _sampling(load_scenario(_write(tmp_path, one))) == ("reported", 40.0, False)
    # a vehicle file in attitude mode takes the same defaults, and its own values win over them
    v = _vehicle_with(tmp_path, QUAD_ROWS.replace('mode = "torque"', 'mode = "attitude"'))
    assert _sampling(load_vehicle(v)) == SAMPLED
    v = _vehicle_with(tmp_path, QUAD_ROWS.replace('mode = "torque"', 'mode = "attitude"').replace(
        "\n[options]\n", '\n[options]\noffboard_inputs = "sent"\n'))
    assert _sampling(load_vehicle(v)) == ("sent", 40.0, True)
