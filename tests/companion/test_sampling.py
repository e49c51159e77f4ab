"""A step's inputs from the latest samples: the estimate carried over its age at constant twist."""
import math

import numpy as np
import pytest

from amcore.so3 import R_to_quat_wxyz, exp_so3, quat_wxyz_to_R
from companion.sampling import BaseEstimate, frame_values, predict_base


def _est(t_us, p=(1.0, 2.0, 3.0), R=np.eye(3), v_B=(0.5, 0.0, 0.1), w_B=(0.0, 0.0, 1.0)):
    return BaseEstimate(t_us, p, tuple(R_to_quat_wxyz(R).tolist()), v_B, w_B)


def test_age_zero_returns_the_sample():
    e = _est(1e6)
    out = predict_base(e, 1e6)
    assert np.allclose(out.p_WB, e.p_WB) and np.allclose(out.q_WB_wxyz, e.q_WB_wxyz)
    assert np.allclose(out.v_B, e.v_B) and out.w_B == e.w_B


def test_constant_twist_matches_the_exact_motion_of_a_constant_world_velocity_body():
    R0 = exp_so3(np.array([0.1, -0.2, 0.3]))
    v_W = np.array([0.3, -0.1, 0.2])
    w_B = np.array([0.0, 0.0, 2.0])
    e = BaseEstimate(0.0, (0.0, 0.0, 1.0), tuple(R_to_quat_wxyz(R0).tolist()), tuple((R0.T @ v_W).tolist()),
                     tuple(w_B.tolist()))
    age = 0.02  # 20 ms: two and a half 100 Hz periods... of a 50 Hz stream
    out = predict_base(e, age * 1e6)
    assert np.allclose(out.p_WB, np.array([0.0, 0.0, 1.0]) + v_W * age, atol=1e-12)
    R = quat_wxyz_to_R(np.array(out.q_WB_wxyz))
    assert np.allclose(R, R0 @ exp_so3(w_B * age), atol=1e-12)
    assert np.allclose(R @ np.array(out.v_B), v_W, atol=1e-12)  # the same world velocity


def test_fresher_attitude_sample_wins_for_attitude_and_rates():
    e = _est(0.0, w_B=(0.0, 0.0, 0.0))
    att = _est(9_000.0, R=exp_so3(np.array([0.0, 0.0, 0.5])), w_B=(0.0, 0.0, 1.0))
    out = predict_base(e, 10_000.0, att)
    R = quat_wxyz_to_R(np.array(out.q_WB_wxyz))
    assert np.allclose(R, exp_so3(np.array([0.0, 0.0, 0.5 + 0.001])), atol=1e-12)
    assert out.w_B == (0.0, 0.0, 1.0)


def test_a_sample_from_the_future_is_not_extrapolated_backwards():
    e = _est(2e6)
    out = predict_base(e, 1e6)
    assert np.allclose(out.p_WB, e.p_WB)


def test_frame_values_layout_and_non_finite_refused():
    e = _est(0.0)
    vals = frame_values(e, [0.1, 0.2], [0.0, 0.0], [1, 2, 3, 4, 5, 6])
    assert len(vals) == 13 + 2 + 2 + 6 and vals[-6:] == [1, 2, 3, 4, 5, 6]
    with pytest.raises(ValueError, match="non-finite"):
        frame_values(e, [math.nan, 0.0], [0.0, 0.0], [0.0] * 6)
