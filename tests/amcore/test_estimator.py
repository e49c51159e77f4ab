"""The flight controller's estimator (amcore.estimator): quaternion helpers against SciPy-free
identities, the gyro low-pass against PX4's, and the filter against an exact trajectory: it
tracks the truth, delayed fusion removes the motion capture's latency, and the IMU biases
are estimated."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amcore.estimator import Estimator, biquad_coefficients, biquad_reset, biquad_step
from amcore.quat_kernels import quat_exp, quat_log, quat_mul, rotation

DT = 0.001
G = 9.81
W_B = np.array([0.3, -0.2, 0.5])  # a constant body rate: q(t) = q0 exp(W_B t)
A, OMEGA = np.array([0.2, -0.1, 0.15]), 2.0  # p(t) = A sin(OMEGA t)


def truth(t):
    q = np.array(quat_exp(W_B * t))
    p = A * math.sin(OMEGA * t)
    v = A * OMEGA * math.cos(OMEGA * t)
    a = -A * OMEGA ** 2 * math.sin(OMEGA * t)
    return p, q, v, a


def run(lag, seconds=6.0, gyro_bias=np.zeros(3), accel_bias=np.zeros(3), fuse_lag=None, every=10, cutoff=0.0):
    """Errors (position [m], attitude [rad], velocity [m/s], rate [rad/s]) per step of a filter
    fed the exact IMU (plus constant biases) and exact poses lag steps old every `every` steps;
    fuse_lag: the lag the filter is told (default: the true one)."""
    p0, q0, _, _ = truth(0.0)
    est = Estimator(p0, q0, DT, every * DT, G, 4.0, 8.0, cutoff, 64)
    # the velocity at rest is unknown to the filter at start; it starts at zero: give it the true one
    est.x[0]["v"] = truth(0.0)[2]
    errs = []
    for k in range(int(seconds / DT)):
        t = k * DT
        p, q, v, a = truth(t)
        R = rotation(q)
        f = R.T @ (a + np.array([0.0, 0.0, G]))
        pose = None
        if k >= lag and (k - lag) % every == 0:
            pt, qt, _, _ = truth((k - lag) * DT)
            pose = (pt, qt)
        out = est.step(k, W_B + gyro_bias, f + accel_bias, pose, lag if fuse_lag is None else fuse_lag)
        e_q = quat_log(quat_mul(np.array([q[0], -q[1], -q[2], -q[3]]), out[3:7]))
        errs.append(np.concatenate([out[0:3] - p, [np.linalg.norm(e_q)], R @ out[7:10] - v, out[10:13] - W_B]))
    return np.array(errs), est


def test_quaternion_exp_and_log_invert_each_other():
    rng = np.random.default_rng(0)
    for _ in range(50):
        d = rng.uniform(-3.0, 3.0, 3)
        if np.linalg.norm(d) >= math.pi:
            continue
        assert np.array(quat_log(quat_exp(d))) == pytest.approx(d, abs=1e-12)
    R = rotation(quat_exp(np.array([0.0, 0.0, math.pi / 2])))
    assert R @ np.array([1.0, 0.0, 0.0]) == pytest.approx([0.0, 1.0, 0.0], abs=1e-12)


def test_gyro_lowpass_is_px4s_butterworth():
    c = biquad_coefficients(1000.0, 40.0)
    b0, b1, b2, a1, a2 = (c[0][name] for name in ("b0", "b1", "b2", "a1", "a2"))
    assert b0 + b1 + b2 == pytest.approx(1.0 + a1 + a2)  # unit gain at DC
    d = np.zeros((2, 3))
    biquad_reset(d, c, np.zeros(3))
    # the gain at the cutoff is 1/sqrt(2): drive it with a sine and measure the steady amplitude
    ys = [biquad_step(d, c, np.full(3, math.sin(2 * math.pi * 40.0 * k / 1000.0)))[0] for k in range(4000)]
    assert max(ys[2000:]) == pytest.approx(1.0 / math.sqrt(2.0), rel=0.01)
    through = biquad_coefficients(1000.0, 0.0)[0]
    assert [through[name] for name in ("b0", "b1", "b2", "a1", "a2")] == [1.0, 0.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError):
        biquad_coefficients(1000.0, 600.0)



def test_the_gyro_lowpass_is_its_recursion_by_name():
    """biquad_reset and biquad_step against the direct form II written out on the coefficients'
    names, bit for bit; the Butterworth's numerator is b0 (1 + z^-1)^2."""
    coef = biquad_coefficients(1000.0, 40.0)
    c = {name: float(coef[0][name]) for name in ("b0", "b1", "b2", "a1", "a2")}
    assert c["b1"] == 2.0 * c["b0"] and c["b2"] == c["b0"] and c["a1"] != c["a2"]
    rng = np.random.default_rng(7)
    xs = rng.normal(size=(200, 3))
    d = np.zeros((2, 3))
    biquad_reset(d, coef, xs[0])
    d1 = [x / (c["b0"] + c["b1"] + c["b2"]) for x in xs[0].tolist()]
    d2 = list(d1)
    for x in xs:
        y = biquad_step(d, coef, x)
        for i in range(3):
            d0 = x[i] - d1[i] * c["a1"] - d2[i] * c["a2"]
            assert y[i] == d0 * c["b0"] + d1[i] * c["b1"] + d2[i] * c["b2"]
            d2[i], d1[i] = d1[i], d0

def test_exact_sensors_give_the_truth():
    e, _ = run(lag=10)
    assert np.abs(e[:, 0:3]).max() < 1e-5
    assert e[:, 3].max() < 1e-6
    assert np.abs(e[:, 4:7]).max() < 1e-4
    assert np.abs(e[:, 7:10]).max() < 1e-12


def test_delayed_fusion_removes_the_latency():
    e_right, _ = run(lag=20)
    e_wrong, _ = run(lag=20, fuse_lag=0)  # the same poses fused as if they were current
    right = np.abs(e_right[2000:, 0:3]).max()
    wrong = np.abs(e_wrong[2000:, 0:3]).max()
    assert right < 1e-5 and wrong > 100 * right


def test_imu_biases_are_estimated_and_removed():
    b_g, b_a = np.array([0.01, -0.008, 0.005]), np.array([0.2, -0.15, 0.1])
    e, est = run(lag=10, seconds=8.0, gyro_bias=b_g, accel_bias=b_a)
    assert est.b_g == pytest.approx(b_g, abs=2e-4)
    assert est.b_a == pytest.approx(b_a, abs=5e-3)
    late = e[6000:]
    assert np.abs(late[:, 0:3]).max() < 2e-4
    assert late[:, 3].max() < 2e-4
    assert np.abs(late[:, 7:10]).max() < 2e-4


def test_the_rate_output_is_filtered_when_asked():
    rng = np.random.default_rng(1)
    p0, q0, _, _ = truth(0.0)
    outs = {}
    for cutoff in (0.0, 40.0):
        est = Estimator(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), DT, 0.01, G, 4.0, 8.0, cutoff, 64)
        noise = rng.standard_normal((3000, 3)) * 0.01
        outs[cutoff] = np.array([est.step(k, noise[k], np.array([0.0, 0.0, G]))[10:13].copy()
                                 for k in range(3000)])
    # white noise through a 2nd-order Butterworth keeps sqrt(ENBW / Nyquist), ENBW = (pi / 4) / sin(pi / 4) f_c
    ratio = outs[40.0][500:].std() / outs[0.0][500:].std()
    assert ratio == pytest.approx(math.sqrt(math.pi / 4.0 / math.sin(math.pi / 4.0) * 40.0 / 500.0), rel=0.1)


def test_a_lag_beyond_the_history_is_refused():
    est = Estimator(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), DT, 0.01, G, 4.0, 8.0, 0.0, 16)
    with pytest.raises(ValueError, match="history"):
        est.step(0, np.zeros(3), np.array([0.0, 0.0, G]), (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])), 16)


def test_the_step_in_place_is_the_step_returning_its_innovations():
    """`Estimator.step` (`estimator_update`: odometry and innovations into the filter's arrays,
    the odometry into a caller's view) gives what `estimator_step` gives, bit for bit."""
    from amcore.estimator import estimator_step

    rng = np.random.default_rng(4)
    p0, q0, _, _ = truth(0.0)
    frame = np.zeros(20)
    est = Estimator(p0, q0, DT, 10 * DT, G, 4.0, 8.0, 30.0, 64, out=frame[:13])
    ref = Estimator(p0, q0, DT, 10 * DT, G, 4.0, 8.0, 30.0, 64)
    poses = 0
    for k in range(600):
        p, q, v, a = truth(k * DT)
        omega, f = W_B + 0.01 * rng.normal(size=3), rotation(q).T @ (a + np.array([0.0, 0.0, G]))
        pose = (p + 0.001 * rng.normal(size=3), np.array(quat_mul(q, quat_exp(0.002 * rng.normal(size=3))))) \
            if k % 10 == 3 else None
        out = est.step(k, omega, f, pose, 3 if pose else 0)
        assert out.base is frame and np.array_equal(frame[:13], out)
        dt = DT if k else 0.0
        if k == 0:
            biquad_reset(ref.lpf, ref.coef, omega)
        p_m, q_m = pose if pose else (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
        nu = estimator_step(ref.x, ref.hist, ref.lpf, ref.coef, k, omega, f, dt, G, pose is not None, 3 if pose else 0,
                            p_m, q_m, ref.gains, ref.out)
        assert ref.out.tolist() == out.tolist() and nu.tolist() == est.innovation.tolist(), f"step {k}"
        poses += pose is not None and bool(np.all(nu != 0.0))
    assert poses == 60
