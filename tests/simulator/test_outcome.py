"""The run outcome computed from ground truth: lift, slip in the object frame, force means."""
from __future__ import annotations

import types

import numpy as np
import pytest

from amcore.so3 import R_to_quat_wxyz, Rz
from simulator.outcome import RunOutcome


def _gt(t, p_WO, yaw, p_WE, normal=9.0, wrench_z=-4.9):
    contact = types.SimpleNamespace(normal_force_n=normal, tangential_force_W=np.array([0, 0, 4.9]))
    am = types.SimpleNamespace(p_WB=np.array([0, 0, 1.0]), p_WE=np.array(p_WE, float), R_WE=np.eye(3),
                               pad_object_contact=contact, base_contacts=(), pad_other_contacts=())
    obj = types.SimpleNamespace(p_WO=np.array(p_WO, float), quat_WO_wxyz=R_to_quat_wxyz(Rz(yaw)), touching=("am4",))
    return types.SimpleNamespace(time_s=t, ams={4: am}, object=obj), {4: np.array([0, 0, wrench_z, 0, 0, 0])}


def test_pad_moving_with_the_object_is_not_slip():
    o = RunOutcome([4], hover_window=(1.0, 3.0), slip_from_s=0.5)
    for t in np.linspace(0.0, 3.0, 31):
        yaw = 0.3 * t  # object turns and rises; the pad rides along rigidly
        p_WO = np.array([0.0, 0.0, 0.6 + 0.1 * t])
        p_WE = p_WO + Rz(yaw) @ np.array([-0.1, 0.0, 0.0])
        o.add(*_gt(t, p_WO, yaw, p_WE))
    d = o.to_dict()
    assert d["ams"]["4"]["slip_max_m"] < 1e-12
    assert d["object"]["final_lift_m"] == pytest.approx(0.3)
    assert d["object"]["hover_min_lift_m"] == pytest.approx(0.1)
    assert d["ams"]["4"]["hover_mean_ft_force_W_n"] == pytest.approx([0, 0, -4.9])


def test_pad_sliding_down_the_object_is_slip():
    o = RunOutcome([4], hover_window=(1.0, 3.0), slip_from_s=1.0)
    for t in np.linspace(0.0, 3.0, 31):
        p_WO = np.array([0.0, 0.0, 0.6])
        slide = 0.004 * max(0.0, t - 2.0)  # 4 mm over the last second
        o.add(*_gt(t, p_WO, 0.0, p_WO + np.array([-0.1, 0.0, -slide])))
    assert o.to_dict()["ams"]["4"]["slip_max_m"] == pytest.approx(0.004)


def test_saturation_counts_stay_python_integers_whatever_bools_they_get():
    """The allocation reports numpy bools; the counts must still go into outcome.json."""
    import json

    o = RunOutcome([4], (1.0, 2.0), slip_from_s=0.5)
    o.saturation(4, 0.1, np.bool_(True), np.bool_(False), tuple(np.array([True, False, True, False])))
    o.saturation(4, 0.2, True, True, (False, True, False, False))
    a = o.to_dict()["ams"]["4"]
    json.dumps(a)
    assert (a["saturated_steps"], a["rotor_saturated_steps"], a["joint_saturated_steps"]) == (2, 2, 1)
    assert list(a["axis_saturated_steps"].values()) == [1, 1, 1, 0]
