"""Sensor realism (simulator.sensors): exact frames unless asked; noise and bias of the stated
size, reproducible from the seed and separate per AM; latency of whole steps."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from amcore.config import SensorSpec, load_scenario
from amcore.so3 import quat_wxyz_to_R
from simulator.core import SitlCore
from simulator.sensors import SensorModel

from ..conftest import SCENARIO

N = 3  # arm joints
TRUTH = [0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0, 0.5, 0.6, 0.7, 0.01, 0.02, 0.03, 1.0, -2.0, 1.0, 0.0, 0.0, 0.0,
         1.0, 2.0, 3.0, 0.1, 0.2, 0.3]


def _draws(model, k=4000, truth=TRUTH):
    return np.array([model(list(truth)) for _ in range(k)])


def test_no_sensor_table_means_exact_frames_and_no_model():
    core = SitlCore(load_scenario(SCENARIO))
    assert all(v.sensor is None for v in core.vehicles.values())


def test_noise_and_bias_have_the_stated_size():
    spec = SensorSpec(position_noise_m=0.01, force_noise_n=0.5, angular_velocity_bias_radps=0.2)
    x = _draws(SensorModel(spec, N, 0.001, seed=3, sysid=4))
    err = x - np.array(TRUTH)
    assert err[:, 0:3].std(axis=0) == pytest.approx([0.01] * 3, rel=0.06)
    assert abs(err[:, 0:3].mean()) < 1e-3
    assert err[:, 19:22].std(axis=0) == pytest.approx([0.5] * 3, rel=0.06)
    w_err = err[:, 10:13]
    assert np.ptp(w_err, axis=0) == pytest.approx([0.0] * 3, abs=1e-12)  # a constant bias, no noise
    assert np.any(np.abs(w_err[0]) > 1e-3)
    assert np.all(err[:, 13:19] == 0.0)  # joint encoders exact
    assert np.all(err[:, 7:10] == 0.0) and np.all(err[:, 22:25] == 0.0)  # no velocity or torque error asked


def test_attitude_error_is_a_rotation_of_the_stated_size_and_quaternions_stay_unit():
    spec = SensorSpec(attitude_noise_rad=0.01)
    q_true = np.array([np.cos(0.4), 0.0, 0.0, np.sin(0.4)])
    truth = TRUTH[:3] + q_true.tolist() + TRUTH[7:]
    x = _draws(SensorModel(spec, N, 0.001, seed=1, sysid=4), 3000, truth)
    q = x[:, 3:7]
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0) and np.all(q[:, 0] >= 0.0)
    R0 = quat_wxyz_to_R(q_true)
    angles = [np.arccos(np.clip((np.trace(R0.T @ quat_wxyz_to_R(qq)) - 1) / 2, -1, 1)) for qq in q]
    # the angle of a 3-D Gaussian rotation vector with per-axis sigma has rms sqrt(3) sigma
    assert np.sqrt(np.mean(np.square(angles))) == pytest.approx(np.sqrt(3) * 0.01, rel=0.06)


def test_streams_are_reproducible_and_separate_per_am_and_seed():
    spec = SensorSpec(position_noise_m=0.01, force_bias_n=0.3)
    a = _draws(SensorModel(spec, N, 0.001, 3, 4), 50)
    assert np.array_equal(a, _draws(SensorModel(spec, N, 0.001, 3, 4), 50))
    assert not np.array_equal(a, _draws(SensorModel(spec, N, 0.001, 3, 5), 50))
    assert not np.array_equal(a, _draws(SensorModel(spec, N, 0.001, 4, 4), 50))


def test_latency_hands_out_the_values_of_whole_steps_ago():
    m = SensorModel(SensorSpec(latency_s=0.0031), N, 0.001, 1, 4)  # rounds to 3 steps
    assert m.delay_steps == 3
    out = [m([float(k)] + TRUTH[1:])[0] for k in range(8)]
    assert out == [0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0]


def test_the_core_feeds_companions_measured_frames_and_keeps_the_truth_for_the_digest():
    spec = load_scenario(SCENARIO)
    noisy = dataclasses.replace(spec, sensors=SensorSpec(position_noise_m=0.01))
    digests, frames = [], []
    for s in (spec, noisy):
        core = SitlCore(s)
        core.connect()
        try:
            frames.append(core.frames(0))
            core.observe()
            digests.append(core.digest.hexdigest())
        finally:
            core.close()
    assert digests[0] == digests[1]  # same state: the digest is of the truth
    assert not np.allclose(frames[0][4].p_WB, frames[1][4].p_WB, atol=1e-4)
