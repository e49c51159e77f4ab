"""The approach planned from the object's pose (amcore.mission.am_mission with an ObjectPose):
each AM faces the box face nearest its azimuth, wherever the object stands and however it is
turned; two AMs at opposite azimuths take opposite faces; an AM's plan depends on the shared
pose and its own [[am]] entry only (decentralized)."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amcore.config import face_azimuth, load_scenario
from amcore.mission import ObjectPose, am_mission, config_object_pose
from amcore.model import build_model

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def robust():
    return load_scenario(ROOT / "configs" / "scenarios" / "two_am_robust.toml")


@pytest.fixture(scope="module")
def model(robust):
    return build_model(robust.vehicle)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-0.1, 0.1), y=st.floats(-0.1, 0.1), yaw=st.floats(-math.pi, math.pi))
def test_each_am_faces_a_face_and_its_pad_touches_that_face(robust, model, x, y, yaw):
    pose = ObjectPose((x, y, 0.6), yaw)
    hx = 0.5 * robust.object.size_m[0]
    headings = []
    for am in robust.ams:
        m = am_mission(robust, am, model, pose)
        # the heading is a face's inward normal: a multiple of pi/2 from the object's yaw
        k = (m.psi - yaw) / (0.5 * math.pi)
        assert abs(k - round(k)) < 1e-9
        # the planned contact point lies on that face, at its centre, in the object's frame
        c, s = math.cos(yaw), math.sin(yaw)
        d = m.contact_point_W - np.array([x, y, 0.6])
        local = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])
        assert max(abs(local[0]), abs(local[1])) == pytest.approx(hx, abs=1e-9)
        assert min(abs(local[0]), abs(local[1])) == pytest.approx(0.0, abs=1e-9) and local[2] == 0.0
        headings.append(m.psi)
    assert abs(_wrap(headings[0] - headings[1])) == pytest.approx(math.pi, abs=1e-9)  # opposite faces


@pytest.mark.parametrize("yaw_deg", [45.0, -45.0, 135.0, 44.999999, 45.000001])
def test_opposite_azimuths_take_opposite_faces_even_at_a_tie(yaw_deg):
    y = math.radians(yaw_deg)
    for az in (0.0, 0.3, 1.0, -2.0):
        assert abs(_wrap(face_azimuth(az + math.pi, y) - face_azimuth(az, y))) == pytest.approx(math.pi, abs=1e-12)
        assert abs(_wrap(face_azimuth(az, y) - az)) <= math.pi / 4 + 1e-12  # the nearest face


def test_an_ams_plan_uses_the_pose_and_its_own_entry_only(robust, model):
    pose = ObjectPose((0.03, -0.05, 0.601), 0.7)
    mine = am_mission(robust, robust.ams[0], model, pose)
    other = dataclasses.replace(robust.ams[1], azimuth_deg=10.0, misalignment_deg=3.0, start_offset_m=(0.05, 0, 0))
    changed = dataclasses.replace(robust, ams=(robust.ams[0], other))
    again = am_mission(changed, changed.ams[0], model, pose)
    t = 7.3
    assert np.array_equal(mine.reference(t).r_c, again.reference(t).r_c) and mine.psi == again.psi


def test_the_config_pose_plans_as_before_for_an_unturned_box(robust, model):
    """Exact measurement of an unturned box on the x axis: the same plan, bit for bit, as the
    config's pose (the paper's azimuths are face normals already)."""
    for am in robust.ams:
        a = am_mission(robust, am, model)
        b = am_mission(robust, am, model, config_object_pose(robust))
        assert a.psi == b.psi and a.psi == math.radians(am.azimuth_deg) + math.pi
        assert np.array_equal(a.reference(3.0).r_c, b.reference(3.0).r_c)
