"""am-vehicle: what a user needs to tune the vehicle, and exit 4 when it cannot do what it was
asked (2 stays for a bad file or bad arguments)."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pinocchio as pin

from amcore.config import load_vehicle
from amcore.model import build_model
from companion.vehicle import main

VEHICLES = Path(__file__).resolve().parents[2] / "configs" / "vehicles"


def test_it_prints_mass_inertia_torque_units_and_sigma_min(capsys):
    assert main([str(VEHICLES / "am4dof.toml")]) == 0
    out = capsys.readouterr().out
    v = load_vehicle(VEHICLES / "am4dof.toml")
    pm = build_model(v).pin_model
    q = pin.neutral(pm)
    q[7:] = v.q_nominal_rad
    data = pm.createData()
    pin.ccrba(pm, data, q, np.zeros(pm.nv))
    Ig = np.diag(data.Ig.inertia)
    line = re.search(r"whole AM at q_nominal_rad: ([0-9.]+) kg; inertia about its CoM diag\(([^)]*)\)", out)
    assert line, out
    assert float(line.group(1)) == round(sum(i.mass for i in pm.inertias), 3)
    np.testing.assert_allclose([float(x) for x in line.group(2).split(",")], Ig, atol=6e-5)
    assert "one unit of normalized torque is roll 7.200, pitch 7.200, yaw 0.768 N m" in out  # 2 L f_max, 4 k f_max
    sigma = float(re.search(r"sigma_min\(Jbar_3\) at q_nominal_rad: ([0-9.]+)", out).group(1))
    assert 0.45 < sigma < 0.7  # am3dof's arm away from a straight elbow (its [safety] comment: ~0.55)
    assert "MC_PITCHRATE_P = 0.451" in out and "(rule:" not in out  # am4dof's gains are the rule's


def test_it_shows_where_a_files_gains_differ_from_the_rule(tmp_path, capsys):
    text = (VEHICLES / "am4dof.toml").read_text()
    (tmp_path / "am4dof.urdf").write_text((VEHICLES / "am4dof.urdf").read_text())
    p = tmp_path / "am4dof.toml"
    p.write_text(text.replace("body_rate_feedforward = true\n", "body_rate_feedforward = true\nMC_PITCHRATE_P = 0.2\n", 1))
    assert main([str(p)]) == 0
    assert "MC_PITCHRATE_P = 0.2   (rule: 0.451)" in capsys.readouterr().out


def test_exit_4_when_the_vehicle_cannot(capsys):
    assert main([str(VEHICLES / "am3dof.toml"), "--squeeze", "9", "--load", "0.5"]) == 0
    capsys.readouterr()
    assert main([str(VEHICLES / "am3dof.toml"), "--squeeze", "40", "--load", "2"]) == 4
    err = capsys.readouterr().err
    assert "NOT FEASIBLE" in err and "the rotors cannot make it" in err and "torque limit" in err


def _two_joint_arm(tmp_path) -> Path:
    """am3dof with its wrist fixed (the pad facing forward at the nominal pose): task x z."""
    urdf = (VEHICLES / "am3dof.urdf").read_text()
    wrist = ('<joint name="joint3" type="revolute">\n    <parent link="link2"/>\n    <child link="link3"/>\n'
             '    <origin xyz="0.22 0 0" rpy="0 0 0"/>\n    <axis xyz="0 1 0"/>\n'
             '    <limit lower="-2.0" upper="2.0" effort="2.0" velocity="8.0"/>')
    assert urdf.count(wrist) == 1
    (tmp_path / "am2dof.urdf").write_text(urdf.replace(wrist, '<joint name="joint3" type="fixed">\n'
                                                      '    <parent link="link2"/>\n    <child link="link3"/>\n'
                                                      '    <origin xyz="0.22 0 0" rpy="0 1.0 0"/>'))
    toml = (VEHICLES / "am3dof.toml").read_text()
    for old, new in (('urdf = "am3dof.urdf"', 'urdf = "am2dof.urdf"'),
                     ('["joint1", "joint2", "joint3"]', '["joint1", "joint2"]'),
                     ("[1.0, -2.0, 1.0]", "[1.0, -2.0]"), ("[6.0, 4.0, 2.0]", "[6.0, 4.0]"),
                     ('["x", "z", "pitch"]', '["x", "z"]'), ("[300.0, 300.0, 1.5]", "[300.0, 300.0]"),
                     ("[14.0, 14.0, 0.03]", "[14.0, 14.0]"), ("[0.15, 0.15, 0.5]", "[0.15, 0.15]"),
                     ("[1.0, 0.4, 0.1]", "[1.0, 0.4]"), ("[20.0, 5.0, 6.0]", "[20.0, 5.0]"),
                     ("[0.73, 0.26, 0.066]", "[0.73, 0.26]")):
        assert toml.count(old) == 1, old
        toml = toml.replace(old, new)
    p = tmp_path / "am2dof.toml"
    p.write_text(toml)
    return p


def test_an_arm_the_loaded_hover_cannot_model_is_refused_not_guessed(tmp_path, capsys):
    """Two planar joints cannot keep the pad's pose (position and pitch) while the base pitches:
    the hover is reported, a loaded hover is refused with exit 2 naming the arm."""
    p = _two_joint_arm(tmp_path)
    assert main([str(p)]) == 0
    capsys.readouterr()
    assert main([str(p), "--squeeze", "9", "--load", "0.5"]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "am2dof.urdf") in err and "[vehicle].arm_joints" in err and "cannot keep the pad's pose" in err
    assert "Traceback" not in err
