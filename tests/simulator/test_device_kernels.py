"""The devices (simulator.device_kernels, through `DeviceSuite` and `Mocap`) against their
readable reference (tests/simulator/reference_devices.py), step after step, through
motion-capture frames, drops, the F/T tare and encoder rounding.

Tolerance: 1e-12 on every frame value, relative to its size above 1. The kernels' 3x3 products
sum in their own order, numpy's (BLAS's) in another, so the two differ by ulps; a wrong bias,
noise or tare step moves a value by far more (the test of a wrong step shows it)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from amcore.config import MocapSpec, devices_from_table
from amcore.quat_kernels import quat_exp, quat_mul, rotation
from simulator import device_kernels as dk
from simulator.devices import CaptureDraws, DeviceSuite, Mocap, NoiseBlock

from .reference_devices import ReferenceDeviceSuite, reference_mocap, truth_of

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
        q = np.array(quat_mul(q, quat_exp(0.01 * rng.normal(size=3))))
        out.append([*rng.normal(size=3).tolist(), *q.tolist(), *rng.normal(size=6).tolist(),
                    *(0.5 * np.round(rng.normal(size=6), 1)).tolist(), *(3.0 * rng.normal(size=6)).tolist()])
    return out


def test_noise_blocks_give_the_draws_one_at_a_time_would():
    a, b = np.random.default_rng([1, 2, 3]), np.random.default_rng([1, 2, 3])
    block = NoiseBlock(a, 12, rows=7)
    for _ in range(30):
        assert np.array_equal(block.next(), b.standard_normal(12))


@pytest.mark.parametrize("with_drop", [False, True])
def test_capture_blocks_give_the_draws_one_capture_at_a_time_would(with_drop):
    """Per capture 6 standard normals, then a uniform if frames may drop: interleaved in the
    stream as the calls per capture take them."""
    a, b = np.random.default_rng([4, 5]), np.random.default_rng([4, 5])
    draws = CaptureDraws(a, 7, np.zeros((7, 7)), with_drop)
    for i in range(30):
        if i % 7 == 0:
            draws.fill()
        row = draws.block[i % 7]
        assert np.array_equal(row[:6], b.standard_normal(6))
        assert row[6] == (b.random() if with_drop else 0.0)


TOL = 1e-12


def close(a, b) -> bool:
    return len(a) == len(b) and all(abs(x - y) <= TOL * max(1.0, abs(y)) for x, y in zip(a, b))


@pytest.mark.parametrize("spec", [FULL, dataclasses.replace(FULL, scale=3.0),
                                  devices_from_table({"enabled": True}, "defaults.toml")])
def test_the_devices_give_their_references_frames(spec):
    values = moving_values(np.random.default_rng(5), 1500)
    fast = DeviceSuite(spec, 3, DT, G, 7, 4, values[0])
    slow = ReferenceDeviceSuite(spec, 3, DT, G, 7, 4, values[0])
    for k, v in enumerate(values):
        assert close(fast.step(v, k * DT), slow.step(v, k * DT)), f"step {k}"
        assert close(fast.autopilot_rate, slow.autopilot_rate), f"step {k}"
    assert fast.mocap.captured == slow.mocap.captured and fast.mocap.dropped == slow.mocap.dropped
    assert bool(fast._state["ft_tared"]) == slow.ft.tared


def test_a_wrong_step_is_seen():
    """The comparison can fail: a reference whose F/T sensor forgets its tare differs from the
    devices by the offset (1 N per axis at these levels) once the tare is done."""
    values = moving_values(np.random.default_rng(5), 700)
    fast = DeviceSuite(FULL, 3, DT, G, 7, 4, values[0])
    slow = ReferenceDeviceSuite(FULL, 3, DT, G, 7, 4, values[0])
    slow.ft.tared = True  # never tares: its readings keep the power-on offset
    worst = 0.0
    for k, v in enumerate(values):
        a, b = fast.step(v, k * DT), slow.step(v, k * DT)
        worst = max(worst, max(abs(x - y) for x, y in zip(a[-6:], b[-6:])))
    assert worst > 0.1


def test_steps_without_a_frame_read_the_base_alone_and_keep_the_draws_in_step():
    """Frames every 4th step (attitude mode): between them the suite gets the base's values
    alone, except while the F/T tare reads; the odometry and every frame stay the reference's,
    which reads everything every step."""
    values = moving_values(np.random.default_rng(6), 1200)
    fast = DeviceSuite(FULL, 3, DT, G, 3, 5, values[0])
    slow = ReferenceDeviceSuite(FULL, 3, DT, G, 3, 5, values[0])
    read_base_alone = 0
    for k, v in enumerate(values):
        t = k * DT
        frame = k % 4 == 0 or fast.needs_reading(t)
        read_base_alone += not frame
        a, b = fast.step(v if frame else v[:13], t), slow.step(v, t)
        assert close(a, b if frame else b[:13]), f"step {k}"
    assert read_base_alone > 600  # the tare (0.4 .. 0.5 s) read every step, then it was done
    with pytest.raises(ValueError, match="tare"):
        early = DeviceSuite(FULL, 3, DT, G, 3, 5, values[0])
        early.step(values[0][:13], 0.45)


def test_the_kernels_products_are_numpys_to_rounding():
    """`mat_vec` and `mat_t_vec` are R v and R^T u (numpy's products to a few ulps), on rotations
    and vectors of every scale and on the zeros of a vehicle at rest."""
    rng = np.random.default_rng(12)
    y = np.empty(3)
    for i in range(2000):
        q = rng.normal(size=4)
        q[rng.integers(0, 4, size=i % 3)] = 0.0  # none, one or two zeros: level, about one axis ...
        R = rotation(q / np.linalg.norm(q)) if q.any() else np.eye(3)
        v = rng.normal(size=3) * 10.0 ** rng.uniform(-6.0, 6.0)
        v[rng.integers(0, 3, size=i % 4)] = 0.0
        scale = 4.0 * np.finfo(float).eps * float(np.abs(v).sum())
        dk.mat_vec(R, v, y)
        np.testing.assert_allclose(y, R @ v, rtol=0.0, atol=scale)
        dk.mat_t_vec(R, v, y)
        np.testing.assert_allclose(y, R.T @ v, rtol=0.0, atol=scale)
    dk.mat_vec(np.eye(3), np.zeros(3), y)
    assert y.tolist() == [0.0, 0.0, 0.0]


def test_the_specific_force_is_the_references():
    """`specific_force` gives the f_B that the reference truth and IMU make in numpy, from the
    first step (a_W = 0) on."""
    values = moving_values(np.random.default_rng(14), 300)
    s, f_B = np.zeros(1, dk.STATE)[0], np.empty(3)
    v_W_prev = None
    for v in values:
        truth = truth_of(v, v_W_prev, DT)
        v_W_prev = truth.v_W
        dk.specific_force(np.array(v), DT, G, s, f_B)
        expected = truth.R_WB.T @ (truth.a_W + np.array([0.0, 0.0, G]))
        assert close(f_B.tolist(), expected.tolist())
        assert close(s["v_W"].tolist(), truth.v_W.tolist())


MOCAPS = [MocapSpec(latency_s=0.01, position_noise_m=0.00015, attitude_noise_rad=0.001, position_bias_m=0.001,
                    attitude_bias_rad=0.005, drop_probability=0.05),
          MocapSpec(rate_hz=1000.0, latency_s=0.0123, position_noise_m=0.01, attitude_noise_rad=0.05,
                    drop_probability=0.3),  # a frame every step, 12 in flight
          MocapSpec(rate_hz=300.0, latency_s=0.0, attitude_noise_rad=1e-13, attitude_bias_rad=1e-13),  # exp's small branch
          MocapSpec(rate_hz=30.0, latency_s=0.07, position_noise_m=0.002, attitude_bias_rad=0.2)]


@pytest.mark.parametrize("spec", MOCAPS)
def test_the_motion_capture_gives_its_references_frames(spec):
    """`Mocap` (`device_kernels.mocap_step`, its draws in blocks of 5 frames) gives the
    reference's frames bit for bit, at the same steps, with the same age, and loses the same
    ones, through several blocks."""
    values = moving_values(np.random.default_rng(9), 2000)
    fast = Mocap(spec, 2.0, DT, np.random.default_rng([3, 1]), rows=5)
    slow = reference_mocap(spec, 2.0, DT, np.random.default_rng([3, 1]))
    arrivals = 0
    for k, v in enumerate(values):
        x = np.array(v[:7])
        a, b = fast.sample_values(x), slow.sample_values(x)
        assert (a is None) == (b is None), f"step {k}"
        if a is not None:
            (p, q), lag = a
            (p_ref, q_ref), lag_ref = b
            assert p.tolist() == p_ref.tolist() and q.tolist() == q_ref.tolist() and lag == lag_ref, f"step {k}"
            arrivals += 1
        assert (fast.captured, fast.dropped) == (slow.captured, slow.dropped), f"step {k}"
    assert arrivals > 40 and (spec.drop_probability == 0.0 or slow.dropped > 5)
