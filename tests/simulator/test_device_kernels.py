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
    assert fast.compiled and not slow.compiled
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


def test_the_kernels_products_round_as_numpys():
    """`mat_vec` and `mat_t_vec` are numpy's R @ v and R.T @ u bit for bit (the sign of a zero
    included), on rotations and vectors of every scale and on the zeros of a vehicle at rest;
    where they would not be (numpy's BLAS summing in another order: another OpenBLAS kernel, or
    another BLAS), `DeviceSuite` runs its Python devices and this test is skipped, saying so;
    the test below checks that fallback."""
    if not dk.products_match_numpy():
        pytest.skip("numpy's BLAS rounds R @ v otherwise on this machine: DeviceSuite runs its Python devices")
    rng = np.random.default_rng(12)
    y = np.empty(3)

    def same(a, b):
        return all(x == e and np.copysign(1.0, x) == np.copysign(1.0, e) for x, e in zip(a.tolist(), b.tolist()))
    cases = []
    for i in range(20000):
        q = rng.normal(size=4)
        q[rng.integers(0, 4, size=i % 3)] = 0.0  # none, one or two zeros: level, about one axis ...
        R = dk.rotation(q / np.linalg.norm(q)) if q.any() else np.eye(3)
        v = rng.normal(size=3) * 10.0 ** rng.uniform(-6.0, 6.0)
        v[rng.integers(0, 3, size=i % 4)] = 0.0
        cases.append((R, v if i % 7 else -0.0 * v))
    upside_down = dk.rotation(np.array([0.0, 1.0, 0.0, 0.0]))
    cases += [(np.eye(3), np.zeros(3)), (np.eye(3), np.array([0.0, 0.0, G])), (upside_down, np.array([-0.0, 0.0, G]))]
    for R, v in cases:
        dk.mat_vec(R, v, y)
        assert same(y, R @ v), (R, v)
        dk.mat_t_vec(R, v, y)
        assert same(y, R.T @ v), (R, v)


def test_the_kernels_rotation_is_the_estimators():
    from amcore.estimator import rotation
    rng = np.random.default_rng(13)
    for _ in range(2000):
        q = rng.normal(size=4) * rng.uniform(0.9, 1.1)
        assert np.array_equal(dk.rotation(q), rotation(q))


def test_the_specific_force_is_the_python_truths():
    """`specific_force` gives the f_B that `DeviceSuite._truth` and `Imu.sample` make in numpy,
    bit for bit, from the first step (a_W = 0) on."""
    values = moving_values(np.random.default_rng(14), 300)
    suite = DeviceSuite(FULL, 3, DT, G, 1, 2, values[0], compiled=False)
    s, f_B = np.zeros(dk.N_TRUTH), np.empty(3)
    v_W_prev = None
    for v in values:
        truth = suite._truth(v, v_W_prev)
        v_W_prev = truth.v_W
        dk.specific_force(np.array(v), DT, G, s, f_B)
        expected = truth.R_WB.T @ (truth.a_W + np.array([0.0, 0.0, G]))
        assert f_B.tolist() == expected.tolist()
        assert s[dk.TRUTH_V_W:dk.TRUTH_V_W + 3].tolist() == truth.v_W.tolist()


def test_a_run_with_compiled_devices_is_the_run_with_the_python_devices(monkeypatch):
    """A whole in-process run with [devices] at full levels (attitude mode: the autopilot flies
    on the estimate) gives the same state digest with the compiled devices as with the Python
    devices (`DeviceSuite` falls back to them where the kernels' products would not match)."""
    from pathlib import Path

    from amcore.config import load_scenario
    from simulator import devices
    from sitl.inprocess import run

    spec = load_scenario(Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_comp_attitude.toml")
    spec = dataclasses.replace(spec, devices=FULL)
    fast = run(spec, 0.6)
    monkeypatch.setattr(devices, "_products_match_numpy", lambda: False)
    slow = run(spec, 0.6)
    assert fast["state_digest"] == slow["state_digest"]
