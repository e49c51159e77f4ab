"""What a trial varies reaches the physics as the config says: the pad-object friction pair,
an AM's misalignment (its whole mission turned about the object), start offsets (the vehicle
moved, its references not)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pybullet as pb
import pytest

from amcore.config import load_scenario
from amcore.mission import am_mission
from amcore.model import build_model
from amcore.so3 import Rz
from simulator.core import SitlCore, initial_state

from ..conftest import SCENARIO


@pytest.mark.parametrize("lateral,pad,pair", [(1.0, 0.0, 1.0), (0.8, 0.0, 0.64), (0.8, 0.5, 0.5), (1.0, 1.2, 1.2)])
def test_the_pad_object_pair_gets_the_named_coefficient(lateral, pad, pair):
    spec = load_scenario(SCENARIO)
    spec = dataclasses.replace(spec, object=dataclasses.replace(spec.object, lateral_friction=lateral,
                                                                pad_friction=pad))
    assert spec.object.pad_object_friction == pytest.approx(pair)
    core = SitlCore(spec)
    core.connect()
    try:
        w = core.world
        am = w._am(4)
        mu_pad = pb.getDynamicsInfo(am.body_id, am.pad_link_id, physicsClientId=w._c())[1]
        mu_obj = pb.getDynamicsInfo(w._object_id, -1, physicsClientId=w._c())[1]
        assert mu_pad * mu_obj == pytest.approx(pair) and mu_obj == pytest.approx(lateral)
    finally:
        core.close()


def test_misalignment_turns_the_mission_about_the_object_centre():
    spec = load_scenario(SCENARIO)
    model = build_model(spec.vehicle)
    am = spec.am(4)
    straight = am_mission(spec, am, model)
    turned = am_mission(spec, dataclasses.replace(am, misalignment_deg=5.0), model)
    assert turned.psi - straight.psi == pytest.approx(np.deg2rad(5.0))
    R = Rz(np.deg2rad(5.0))
    c = np.array(spec.object.position_m)
    for t in (0.0, 7.0, 15.0):
        a, b = straight.reference(t), turned.reference(t)
        assert b.r_c == pytest.approx(c + R @ (a.r_c - c))
        assert b.y == pytest.approx(a.y)  # the same task in its own (turned) frame


def test_start_offsets_move_the_vehicle_not_its_references():
    spec = load_scenario(SCENARIO)
    model = build_model(spec.vehicle)
    am = spec.am(5)
    moved = dataclasses.replace(am, start_offset_m=(0.03, -0.02, 0.01), start_heading_deg=4.0)
    x0, x1 = initial_state(spec, am, model), initial_state(spec, moved, model)
    assert x1.p_WB - x0.p_WB == pytest.approx([0.03, -0.02, 0.01])
    assert x1.R_WB == pytest.approx(Rz(np.deg2rad(4.0)) @ x0.R_WB)
    assert am_mission(spec, moved, model).reference(0.0).r_c == pytest.approx(
        am_mission(spec, am, model).reference(0.0).r_c)


def test_a_crowned_pad_touches_with_its_front_line_and_a_rubber_facing_is_soft():
    """[pad] shape = "crowned": PyBullet's pad collision is a vertical cylinder whose front
    line is the flat face's centre line; contact stiffness and damping reach the pad."""
    spec = load_scenario(SCENARIO)
    v = spec.vehicle
    pad = dataclasses.replace(v.pad, shape="crowned", crown_radius_m=0.05, contact_stiffness_n_per_m=3e4,
                              contact_damping_n_s_per_m=150.0)
    spec = dataclasses.replace(spec, vehicle=dataclasses.replace(v, pad=pad))
    core = SitlCore(spec)
    core.connect()
    try:
        w = core.world
        am = w._am(4)
        (shape,) = pb.getCollisionShapeData(am.body_id, am.pad_link_id, physicsClientId=w._c())
        assert shape[2] == pb.GEOM_CYLINDER and shape[3][:2] == pytest.approx((0.08, 0.05))  # length, radius
        # the shape's position is given in the pad's inertial frame, 0.01 m ahead of the link frame:
        # front line at the face, x = 0.02 in the link frame
        assert 0.01 + shape[5][0] + 0.05 == pytest.approx(0.02)
        info = pb.getDynamicsInfo(am.body_id, am.pad_link_id, physicsClientId=w._c())
        assert info[9] == pytest.approx(3e4) and info[8] == pytest.approx(150.0)  # stiffness, damping
    finally:
        core.close()


def test_saturation_reaches_the_ground_truth_telemetry_per_am():
    """Each AM's truth sample counts its saturated commands so far (rotors, joints), and the
    sample holds to the telemetry schema."""
    from telemetry import schema
    from telemetry.validate import errors

    spec = load_scenario(SCENARIO)
    core = SitlCore(spec)
    core.connect()
    try:
        w = core.world
        w.apply(4, 200.0, np.zeros(3), np.zeros(3))  # beyond the rotors' total: clamped
        w.apply(4, 10.0, np.zeros(3), np.array([50.0, 0.0, 0.0]))  # beyond joint 1's limit
        w.apply(5, 10.0, np.zeros(3), np.zeros(3))
        gt = w.ground_truth()
        a4, a5 = gt.ams[4], gt.ams[5]
        assert (a4.rotor_saturated_steps, a4.joint_saturated_steps) == (1, 1)
        assert (a5.rotor_saturated_steps, a5.joint_saturated_steps) == (0, 0)
        sample = schema.am_truth_sample(gt.time_s, 4, a4)
        assert sample["rotor_saturated_steps"] == 1 and sample["joint_saturated_steps"] == 1
        assert errors(sample, schema.AM_TRUTH_SCHEMA) == []
    finally:
        core.close()
