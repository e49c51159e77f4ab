"""The loader's checks of a vehicle's URDF and arm (amcore.vehicle_checks), each just inside
(loads) and just outside (refused: ConfigError naming the file, the element and the value;
am-vehicle exits 2), and the task components the arm cannot move (a warning)."""
from __future__ import annotations

import re
import warnings
from pathlib import Path

import pytest

from amcore.config import ConfigError, ConfigWarning, load_scenario, load_vehicle
from amcore.vehicle_checks import nominal_statics

ROOT = Path(__file__).resolve().parents[2]
VEHICLES = ROOT / "configs" / "vehicles"
URDF = (VEHICLES / "am3dof.urdf").read_text()
TOML = (VEHICLES / "am3dof.toml").read_text()


def _vehicle(tmp_path, urdf: str = URDF, toml: str = TOML, name: str = "v") -> Path:
    (tmp_path / f"{name}.urdf").write_text(urdf)
    p = tmp_path / f"{name}.toml"
    p.write_text(re.sub(r'^urdf = "am\ddof\.urdf"', f'urdf = "{name}.urdf"', toml, count=1, flags=re.M))
    return p


def _sub(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


BASE_ORIGIN = '<origin xyz="0 0 0" rpy="0 0 0"/>\n      <mass value="1.5"/>'
LINK3 = '<mass value="0.05"/>\n      <inertia ixx="5e-6" ixy="0" ixz="0" iyy="3.2e-5" iyz="0" izz="3.2e-5"/>'
LINK1_INERTIA = '<inertia ixx="1.5e-5" ixy="0" ixz="0" iyy="4.9e-4" iyz="0" izz="4.9e-4"/>'


def _link1_izz(izz: float) -> str:
    return _sub(URDF, LINK1_INERTIA, f'<inertia ixx="1.5e-5" ixy="0" ixz="0" iyy="4.9e-4" iyz="0" izz="{izz!r}"/>')


# (URDF just inside, URDF just outside, words the refusal must hold)
URDF_CASES = {
    "base inertial at the origin": (
        _sub(URDF, BASE_ORIGIN, BASE_ORIGIN.replace('xyz="0 0 0"', 'xyz="0 0 5e-10"')),
        _sub(URDF, BASE_ORIGIN, BASE_ORIGIN.replace('xyz="0 0 0"', 'xyz="0 0 2e-9"')),
        ["<link name='base_link'><inertial><origin xyz='0 0 2e-9'>", "at its origin"]),
    "a link's inertial present": (
        URDF,
        re.sub(r'<link name="link3">\s*<inertial>.*?</inertial>', '<link name="link3">', URDF, flags=re.S),
        ["<link name='link3'> has no <inertial>", "1 kg"]),
    "a positive mass": (
        _sub(URDF, LINK3, LINK3.replace('"0.05"', '"1e-6"')),
        _sub(URDF, LINK3, LINK3.replace('"0.05"', '"0"')),
        ["<link name='link3'><inertial><mass value='0'>", "positive"]),
    "a positive-definite inertia": (
        _sub(URDF, LINK3, LINK3.replace('ixx="5e-6"', 'ixx="1e-12"')),
        _sub(URDF, LINK3, LINK3.replace('ixx="5e-6"', 'ixx="-1e-12"')),
        ["<link name='link3'><inertia ixx='-1e-12'", "not positive definite"]),
    "the triangle inequality": (
        _link1_izz((1.5e-5 + 4.9e-4) * (1 - 1e-6)),
        _link1_izz((1.5e-5 + 4.9e-4) * (1 + 1e-6)),
        ["<link name='link1'><inertia", "triangle inequality"]),
}


@pytest.mark.parametrize("case", sorted(URDF_CASES))
def test_urdf_checks_just_inside_and_just_outside(tmp_path, case, capsys):
    from companion.vehicle import main

    inside, outside, words = URDF_CASES[case]
    load_vehicle(_vehicle(tmp_path, inside, name="inside"))
    bad = _vehicle(tmp_path, outside, name="outside")
    with pytest.raises(ConfigError) as e:
        load_vehicle(bad)
    for w in [str(bad), "[vehicle].urdf", str(tmp_path / "outside.urdf"), *words]:
        assert w in str(e.value), (w, str(e.value))
    assert main([str(bad)]) == 2
    err = capsys.readouterr().err
    assert words[0] in err and "Traceback" not in err


def test_q_nominal_inside_the_joint_limits(tmp_path):
    """joint1's <limit lower="-0.5" upper="2.6">: 2.6 loads, 2.6001 is refused."""
    q = "q_nominal_rad = [1.0, -2.0, 1.0]"
    load_vehicle(_vehicle(tmp_path, toml=_sub(TOML, q, "q_nominal_rad = [2.6, -2.0, 1.0]"), name="inside"))
    bad = _vehicle(tmp_path, toml=_sub(TOML, q, "q_nominal_rad = [2.6001, -2.0, 1.0]"), name="outside")
    with pytest.raises(ConfigError, match=r"outside\.toml: \[vehicle\]\.q_nominal_rad: 2\.6001 for 'joint1' is "
                                          r"outside its <limit lower='-0\.5' upper='2\.6'>"):
        load_vehicle(bad)


def test_joint_torque_limits_against_the_statics_at_the_nominal_pose(tmp_path):
    """joint1 holds the arm at q_nominal with |tau_1| (pinocchio's g(q), level hover): a limit
    1 % above loads, 1 % below is refused."""
    v = load_vehicle(VEHICLES / "am3dof.toml")
    tau1 = float(abs(nominal_statics(v.urdf, v.q_nominal_rad, v.gravity_mps2)[3][0]))
    assert 0.1 < tau1 < 6.0
    line = "joint_torque_max_nm = [6.0, 4.0, 2.0]"
    load_vehicle(_vehicle(tmp_path, toml=_sub(TOML, line, f"joint_torque_max_nm = [{tau1 * 1.01!r}, 4.0, 2.0]"),
                          name="inside"))
    bad = _vehicle(tmp_path, toml=_sub(TOML, line, f"joint_torque_max_nm = [{tau1 * 0.99!r}, 4.0, 2.0]"), name="outside")
    with pytest.raises(ConfigError, match=r"outside\.toml: \[vehicle\]\.joint_torque_max_nm: 'joint1' needs "
                                          r"[0-9.]+ N m to hold the arm at q_nominal_rad"):
        load_vehicle(bad)


def test_a_task_component_the_arm_cannot_move_is_warned_of(tmp_path):
    """am4dof's wrist rolls the pad about the task x axis: 'roll' moves, 'yaw' does not (every
    joint's axis is the body y or the forearm's x at the nominal pose)."""
    toml = (VEHICLES / "am4dof.toml").read_text()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConfigWarning)
        load_vehicle(VEHICLES / "am4dof.toml")
    assert not [w for w in caught if issubclass(w.category, ConfigWarning)]
    path = _vehicle(tmp_path, (VEHICLES / "am4dof.urdf").read_text(),
                    _sub(toml, 'components = ["x", "z", "pitch", "roll"]', 'components = ["x", "z", "pitch", "yaw"]'),
                    name="yaw")
    with pytest.warns(ConfigWarning, match=r"yaw\.toml: \[task\]\.components: 'yaw' cannot be moved"):
        load_vehicle(path)


@pytest.mark.parametrize("components,words", [
    ('["x", "pitch", "y"]', "the grasp mission needs 'z'"),
    ('["y", "z", "pitch"]', "the grasp mission needs 'x'"),
    ('["x", "x", "pitch"]', "named twice"),
])
def test_a_task_the_grasp_cannot_use_is_refused_at_load(tmp_path, components, words):
    bad = _vehicle(tmp_path, toml=_sub(TOML, 'components = ["x", "z", "pitch"]', f"components = {components}"))
    with pytest.raises(ConfigError, match=re.escape(f"{bad}: [task].components: ") + ".*" + re.escape(words)):
        load_vehicle(bad)


def test_the_baseline_refuses_an_arm_it_has_no_inverse_kinematics_for(tmp_path):
    toml = _sub(TOML, 'controller = "passivity"', 'controller = "baseline"')
    load_vehicle(_vehicle(tmp_path, toml=toml, name="planar"))
    four = _sub(toml, 'arm_joints = ["joint1", "joint2", "joint3"]', 'arm_joints = ["joint1", "joint2", "joint3", "joint4"]')
    four = _sub(four, "q_nominal_rad = [1.0, -2.0, 1.0]", "q_nominal_rad = [1.0, -2.0, 1.0, 0.0]")
    four = _sub(four, "joint_torque_max_nm = [6.0, 4.0, 2.0]", "joint_torque_max_nm = [6.0, 4.0, 2.0, 0.5]")
    four = _sub(four, 'components = ["x", "z", "pitch"]', 'components = ["x", "z", "pitch", "roll"]')
    for key, extra in (("K_y", "0.22"), ("D_y", "0.0043"), ("y_err_max", "0.5"), ("failsafe_joint_damping", "0.01"),
                       ("K_q", "0.5"), ("D_q", "0.01")):
        four = re.sub(rf"^({key} = \[[^\]]*)\]", rf"\1, {extra}]", four, count=1, flags=re.M)
    bad = _vehicle(tmp_path, (VEHICLES / "am4dof.urdf").read_text(), four, name="wrist")
    with pytest.raises(ConfigError, match=r"wrist\.toml: \[options\]\.controller = 'baseline': its inverse kinematics "
                                          r"is for the planar task"):
        load_vehicle(bad)


def test_every_shipped_scenario_loads_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConfigWarning)
        for path in sorted((ROOT / "configs" / "scenarios").glob("*.toml")):
            load_scenario(path)
