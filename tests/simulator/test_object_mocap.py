"""The object as the world places it ([object].yaw_deg) and as the motion capture measures it
(simulator.object_mocap): exact without [devices], within the device's levels with them, the
object's own draw; the vehicles start where the plan from that measurement starts them."""
from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from amcore.config import devices_from_table, load_scenario
from amcore.so3 import quat_wxyz_to_R
from simulator.core import SitlCore
from simulator.object_mocap import measure_object

ROOT = Path(__file__).resolve().parents[2]
DEVICES = tomllib.loads((ROOT / "configs" / "randomize" / "default.toml").read_text())["randomize"]["devices"]


@pytest.fixture(scope="module")
def turned():
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_robust.toml")
    obj = dataclasses.replace(spec.object, position_m=(0.07, -0.04, 0.6), yaw_deg=63.0)
    return dataclasses.replace(spec, object=obj)


def test_without_devices_the_measurement_is_the_truth(turned):
    p = measure_object(turned)
    assert p.p_W_m == (0.07, -0.04, 0.6) and p.yaw_rad == math.radians(63.0)


def test_with_devices_the_error_is_the_motion_captures_and_the_objects_own(turned):
    spec = dataclasses.replace(turned, devices=devices_from_table(DEVICES, "default.toml"))
    m = spec.devices.mocap
    errs, yaws = [], []
    for seed in range(30):
        p = measure_object(dataclasses.replace(spec, seed=seed))
        errs.append(np.subtract(p.p_W_m, (0.07, -0.04, 0.6)))
        yaws.append(p.yaw_rad - math.radians(63.0))
    errs, yaws = np.array(errs), np.array(yaws)
    sigma_p = math.hypot(m.position_bias_m, m.position_noise_m)
    sigma_y = math.hypot(m.attitude_bias_rad, m.attitude_noise_rad)
    assert 0.3 * sigma_p < errs.std() < 2.0 * sigma_p and np.abs(errs).max() < 5.0 * sigma_p
    assert 0.3 * sigma_y < yaws.std() < 2.0 * sigma_y and np.abs(yaws).max() < 5.0 * sigma_y
    # the same seed measures the same; the AMs' number does not change the object's draw
    one_am = dataclasses.replace(spec, ams=spec.ams[:1])
    assert measure_object(spec) == measure_object(spec) == measure_object(one_am)


def test_the_world_turns_the_object_and_the_vehicles_start_at_their_faces(turned):
    spec = dataclasses.replace(turned, mission=dataclasses.replace(turned.mission, object_pose="mocap"))
    core = SitlCore(spec)
    core.connect()
    try:
        gt = core.world.ground_truth()
        R = quat_wxyz_to_R(np.asarray(gt.object.quat_WO_wxyz))
        assert math.degrees(math.atan2(R[1, 0], R[0, 0])) == pytest.approx(63.0, abs=1e-6)
        assert np.allclose(gt.object.p_WO, (0.07, -0.04, 0.6), atol=1e-6)
        for am in spec.ams:
            x = core.world.state(am.sysid)
            d = x.p_WB[:2] - np.array([0.07, -0.04])
            bearing = math.degrees(math.atan2(d[1], d[0])) - 63.0
            assert abs((bearing + 45.0) % 90.0 - 45.0) < 1.0  # on a face's normal line, not on its azimuth
    finally:
        core.close()
