"""The compiled devices (simulator.device_kernels, DeviceSuite(compiled=True)) against the
Python devices they transcribe (simulator.devices): the same frames bit for bit, step after
step, through motion-capture frames, drops, the F/T tare and encoder rounding."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from amcore.config import devices_from_table
from amcore.estimator import quat_exp, quat_mul
from simulator import device_kernels as dk
from simulator.devices import DeviceSuite

DT = 0.001
G = 9.81
FULL = devices_from_table({
    "enabled": True,
    "imu": {"gyroscope_noise_density": 1.8665e-4, "gyroscope_random_walk": 3.8785e-5,
            "gyroscope_turn_on_bias_sigma": 0.0087, "accelerometer_noise_density": 1.86e-3,
            "accelerometer_random_walk": 6.0e-3, "accelerometer_turn_on_bias_sigma": 0.196,
            "gyroscope_bias_correlation_time_s": 1000.0, "accelerometer_bias_correlation_time_s": 0.0},
    "mocap": {"latency_s": 0.01, "position_noise_m": 0.00015, "attitude_noise_rad": 0.001,
              "position_bias_m": 0.001, "attitude_bias_rad": 0.005, "drop_probability": 0.05},
    "ft": {"force_noise_n": 0.0625, "force_offset_n": 1.0, "force_drift_n_per_sqrt_s": 0.01, "tare_at_s": 0.5,
           "tare_window_s": 0.1},
    "encoders": {"counts_per_rev": 4096, "velocity_quantum_radps": 0.01}}, "t.toml")


def moving_values(rng, k: int) -> list[list[float]]:
    """Exact values of a vehicle tumbling and moving about, arm swinging, a wrench acting."""
    out, q = [], np.array([1.0, 0.0, 0.0, 0.0])
    for _ in range(k):
        q = quat_mul(q, quat_exp(0.01 * rng.normal(size=3)))
        out.append([*rng.normal(size=3).tolist(), *q.tolist(), *rng.normal(size=6).tolist(),
                    *(0.5 * np.round(rng.normal(size=6), 1)).tolist(), *(3.0 * rng.normal(size=6)).tolist()])
    return out


def test_noise_blocks_give_the_draws_one_at_a_time_would():
    a, b = np.random.default_rng([1, 2, 3]), np.random.default_rng([1, 2, 3])
    block = dk.NoiseBlock(a, 12, rows=7)
    for _ in range(30):
        assert np.array_equal(block.next(), b.standard_normal(12))


@pytest.mark.parametrize("spec", [FULL, dataclasses.replace(FULL, scale=3.0),
                                  devices_from_table({"enabled": True}, "defaults.toml")])
def test_compiled_devices_give_the_python_devices_frames_bit_for_bit(spec):
    values = moving_values(np.random.default_rng(5), 1500)
    fast = DeviceSuite(spec, 3, DT, G, 7, 4, values[0], compiled=True)
    slow = DeviceSuite(spec, 3, DT, G, 7, 4, values[0], compiled=False)
    for k, v in enumerate(values):
        assert fast.step(v, k * DT) == slow.step(v, k * DT), f"step {k}"
    assert fast.mocap.captured == slow.mocap.captured and fast.mocap.dropped == slow.mocap.dropped
    assert bool(fast._ft_s[dk.FT_TARED]) == slow.ft.tared


def test_steps_without_a_frame_read_the_base_alone_and_keep_the_draws_in_step():
    """Frames every 4th step (attitude mode): between them the compiled suite gets the base's
    values alone, except while the F/T tare reads; the odometry and every frame stay the
    Python suite's, which reads everything every step."""
    values = moving_values(np.random.default_rng(6), 1200)
    fast = DeviceSuite(FULL, 3, DT, G, 3, 5, values[0], compiled=True)
    slow = DeviceSuite(FULL, 3, DT, G, 3, 5, values[0], compiled=False)
    read_base_alone = 0
    for k, v in enumerate(values):
        t = k * DT
        frame = k % 4 == 0 or fast.needs_reading(t)
        read_base_alone += not frame
        a, b = fast.step(v if frame else v[:13], t), slow.step(v, t)
        assert a == (b if frame else b[:13]), f"step {k}"
    assert read_base_alone > 600  # the tare (0.4 .. 0.5 s) read every step, then it was done
    with pytest.raises(ValueError, match="tare"):
        early = DeviceSuite(FULL, 3, DT, G, 3, 5, values[0], compiled=True)
        early.step(values[0][:13], 0.45)
