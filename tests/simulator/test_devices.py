"""Sensor devices (simulator.devices; the IMU, F/T and encoders through their readable reference,
tests/simulator/reference_devices.py, which tests/simulator/test_device_kernels.py holds the
compiled devices to): the IMU's noise density, bias random walk and turn-on
bias at their stated sizes (Allan-like scaling), specific force in the body frame, motion
capture frames at their rate and exactly their latency old, dropped at their rate, the F/T
tare, encoder quantization, and the same seed giving the same output."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from amcore.config import (ConfigError, DevicesSpec, EncoderSpec, ForceTorqueSpec, ImuSpec, MocapSpec,
                           devices_from_table)
from amcore.quat_kernels import quat_exp, quat_log, quat_mul, rotation
from simulator.devices import DeviceSuite, Mocap

from .reference_devices import BodyTruth, ReferenceEncoders, ReferenceForceTorque, ReferenceImu

DT = 0.001
G = 9.81


def at_rest(p=(0.0, 0.0, 1.0), d=(0.0, 0.0, 0.0)) -> BodyTruth:
    q = np.array(quat_exp(np.array(d, dtype=float)))
    return BodyTruth(np.array(p, dtype=float), q, rotation(q), np.zeros(3), np.zeros(3), np.zeros(3))


def gyro_samples(spec, k, seed=0):
    imu = ReferenceImu(spec, 1.0, DT, G, np.random.default_rng(seed))
    truth = at_rest()
    return np.array([imu.sample(truth, i * DT)[0] for i in range(k)])


def test_white_noise_has_its_density_and_averages_down_as_white_noise():
    nd = 1.8665e-4
    x = gyro_samples(ImuSpec(gyroscope_noise_density=nd), 40000)
    assert x.std(axis=0) == pytest.approx([nd / math.sqrt(DT)] * 3, rel=0.03)
    # Allan-like: the mean over tau seconds has std nd / sqrt(tau) (white noise, no bias)
    for m in (10, 100):
        means = x.reshape(-1, m, 3).mean(axis=1)
        assert means.std() == pytest.approx(nd / math.sqrt(m * DT), rel=0.08)


def test_bias_random_walk_grows_as_sqrt_time():
    rw = 3.8785e-5
    spec = ImuSpec(gyroscope_random_walk=rw, gyroscope_bias_correlation_time_s=0.0)  # 0: a pure random walk
    ends = []
    for seed in range(300):
        imu = ReferenceImu(spec, 1.0, DT, G, np.random.default_rng(seed))
        truth = at_rest()
        for i in range(400):
            w = imu.sample(truth, i * DT)[0]
        ends.append(w)
    assert np.std(ends) == pytest.approx(rw * math.sqrt(400 * DT), rel=0.1)


def test_gauss_markov_bias_stays_bounded_by_its_correlation_time():
    imu = ReferenceImu(ImuSpec(accelerometer_random_walk=1.0, accelerometer_bias_correlation_time_s=0.01), 1.0, DT, G,
              np.random.default_rng(2))
    xs = np.array([imu.sample(at_rest(), i * DT)[1] for i in range(20000)])
    # stationary std of the Gauss-Markov process: sigma_rw sqrt(tau / 2)
    assert xs[:, 0].std() == pytest.approx(math.sqrt(0.01 / 2.0), rel=0.15)


def test_turn_on_bias_is_constant_and_of_its_size():
    firsts = []
    for seed in range(400):
        x = gyro_samples(ImuSpec(gyroscope_turn_on_bias_sigma=0.0087), 3, seed)
        assert np.ptp(x, axis=0) == pytest.approx([0.0] * 3, abs=1e-15)
        firsts.append(x[0])
    assert np.std(firsts) == pytest.approx(0.0087, rel=0.1)


def test_accelerometer_measures_specific_force_in_the_body_frame():
    imu = ReferenceImu(ImuSpec(), 1.0, DT, G, np.random.default_rng(0))
    tilt = at_rest(d=(0.3, 0.0, 0.0))
    f = imu.sample(tilt, 0.0)[1]
    assert f == pytest.approx([0.0, G * math.sin(0.3), G * math.cos(0.3)], abs=1e-12)
    falling = tilt._replace(a_W=np.array([0.0, 0.0, -G]))
    assert imu.sample(falling, 0.0)[1] == pytest.approx([0.0, 0.0, 0.0], abs=1e-12)


def test_motion_capture_frames_come_at_the_rate_and_exactly_the_latency_late():
    m = Mocap(MocapSpec(rate_hz=100.0, latency_s=0.013), 1.0, DT, np.random.default_rng(0))
    arrivals = []
    for k in range(200):
        got = m.sample_values(np.array([k, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))  # the position says when it was taken
        if got is not None:
            (p, _), lag = got
            arrivals.append((k, int(p[0]), lag))
    assert [a for a, _, _ in arrivals] == list(range(13, 200, 10))
    assert all(k - taken == 13 == lag and taken % 10 == 0 for k, taken, lag in arrivals)


def test_motion_capture_noise_bias_and_drops_have_their_sizes():
    spec = MocapSpec(rate_hz=1000.0, position_noise_m=0.00015, attitude_bias_rad=0.005, drop_probability=0.1)
    m = Mocap(spec, 1.0, DT, np.random.default_rng(3))
    got = [m.sample_values(np.array([0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0])) for k in range(20000)]
    frames = [g[0] for g in got if g is not None]
    assert len(frames) / len(got) == pytest.approx(0.9, abs=0.01)
    assert m.dropped == len(got) - len(frames)
    p = np.array([f[0] for f in frames])
    assert p.std(axis=0) == pytest.approx([0.00015] * 3, rel=0.05)
    d = np.array([quat_log(f[1]) for f in frames])
    assert np.ptp(d, axis=0) == pytest.approx([0.0] * 3, abs=1e-12)  # a fixed bias, no noise asked
    assert d[0] == pytest.approx(m.bias_R, abs=1e-12)


def test_force_torque_tare_removes_the_offset():
    spec = ForceTorqueSpec(force_noise_n=0.05, force_offset_n=1.0, torque_offset_nm=0.02, tare_at_s=0.5,
                           tare_window_s=0.2)
    ft = ReferenceForceTorque(spec, 1.0, DT, np.random.default_rng(4))
    offset = ft.offset.copy()
    xs = np.array([ft.sample(np.zeros(6), k * DT) for k in range(1000)])
    assert xs[:300].mean(axis=0) == pytest.approx(offset, abs=0.01)
    assert np.abs(offset[0:3]).max() > 0.1  # there was something to remove
    # the tare averages 200 samples of noise 0.05: a residual of 0.05 / sqrt(200) per axis
    assert np.abs(xs[600:].mean(axis=0)).max() < 5 * 0.05 / math.sqrt(200) + 0.01


def test_force_torque_drift_is_a_random_walk():
    spec = ForceTorqueSpec(force_drift_n_per_sqrt_s=0.1)
    ends = []
    for seed in range(200):
        ft = ReferenceForceTorque(spec, 1.0, DT, np.random.default_rng(seed))
        for k in range(1000):
            x = ft.sample(np.zeros(6), k * DT)
        ends.append(x[0:3])
    assert np.std(ends) == pytest.approx(0.1 * math.sqrt(1.0), rel=0.1)


def test_encoders_quantize_to_whole_counts_and_velocity_units():
    enc = ReferenceEncoders(EncoderSpec(counts_per_rev=4096, velocity_quantum_radps=0.0239809))
    q = np.linspace(-3.0, 3.0, 20001)
    qm, qdm = enc.sample(q, q)
    step = 2.0 * math.pi / 4096
    assert np.abs(qm - q).max() <= step / 2 + 1e-15
    assert np.allclose(qm / step, np.round(qm / step), atol=1e-9)
    assert np.abs(qdm - q).max() <= 0.0239809 / 2 + 1e-15
    assert len(np.unique(np.round(qm / step))) == pytest.approx(6.0 / step, rel=0.01)
    exact = ReferenceEncoders(EncoderSpec())
    assert np.array_equal(exact.sample(q, q)[0], q)


FULL = devices_from_table({
    "enabled": True,
    "imu": {"gyroscope_noise_density": 1.8665e-4, "gyroscope_random_walk": 3.8785e-5,
            "gyroscope_turn_on_bias_sigma": 0.0087, "accelerometer_noise_density": 1.86e-3,
            "accelerometer_random_walk": 6.0e-3, "accelerometer_turn_on_bias_sigma": 0.196},
    "mocap": {"latency_s": 0.01, "position_noise_m": 0.00015, "attitude_noise_rad": 0.001,
              "position_bias_m": 0.001, "attitude_bias_rad": 0.005, "drop_probability": 0.01},
    "ft": {"force_noise_n": 0.0625, "force_offset_n": 1.0}, "encoders": {"counts_per_rev": 4096}}, "t.toml")
VALUES = [0.1, 0.2, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, -1.0, 0.3, 0.0, 0.0, 0.0,
          0.0, 0.0, 1.0, 0.0, 0.0, 0.0]


def _suite_run(spec, seed, sysid, k=3000):
    suite = DeviceSuite(spec, 3, DT, G, seed, sysid, VALUES)
    return np.array([suite.step(VALUES, i * DT) for i in range(k)]), suite


def test_same_seed_same_output_other_seed_or_vehicle_other_output():
    a, _ = _suite_run(FULL, 7, 4, 300)
    b, _ = _suite_run(FULL, 7, 4, 300)
    c, _ = _suite_run(FULL, 8, 4, 300)
    d, _ = _suite_run(FULL, 7, 5, 300)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c) and not np.array_equal(a, d)


def test_the_suite_estimate_at_rest_stays_near_the_truth():
    x, suite = _suite_run(FULL, 1, 4, 5000)
    late = x[3000:]
    # position: the motion capture's bias (std 1 mm per axis) plus little noise
    assert np.abs(late[:, 0:3] - np.array(VALUES[0:3]) - suite.mocap.bias_p).max() < 3e-4
    att = np.array([np.linalg.norm(quat_log(quat_mul(quat_exp(-suite.mocap.bias_R), q))) for q in late[:, 3:7]])
    assert att.max() < 1e-3  # the attitude, up to the motion capture's fixed bias
    assert np.abs(late[:, 7:10]).max() < 5e-3  # velocity [m/s]
    # body rate [rad/s]: the gyro's white noise (no low-pass here), its bias removed
    sigma = 1.8665e-4 / math.sqrt(DT)
    assert np.sqrt((late[:, 10:13] ** 2).mean()) == pytest.approx(sigma, rel=0.1)
    assert np.abs(late[:, 10:13].mean(axis=0)).max() < 0.1 * sigma
    assert np.abs(late[:, 13:16] - np.array(VALUES[13:16])).max() <= math.pi / 4096 + 1e-12


@pytest.mark.parametrize("table, words", [
    ({"imu": {"gyroscope_noise_density": -1.0}}, "[devices.imu].gyroscope_noise_density: must be >= 0"),
    ({"mocap": {"rate_hz": 0.5}}, "[devices.mocap].rate_hz"),
    ({"mocap": {"drop_probability": 1.0}}, "drop_probability: must be in [0, 1), got 1.0"),
    ({"imu": {"gyro_noise": 1.0}}, "unknown key 'gyro_noise'"),
    ({"estimator": {"history_steps": 0}}, "history_steps"),
])
def test_a_bad_devices_table_names_the_key(table, words):
    with pytest.raises(ConfigError) as exc:
        devices_from_table(table, "s.toml")
    assert words in str(exc.value) and "s.toml" in str(exc.value)


def test_a_latency_beyond_the_estimator_history_is_refused():
    spec = dataclasses.replace(FULL, mocap=dataclasses.replace(FULL.mocap, latency_s=0.1))
    with pytest.raises(ValueError, match="history_steps"):
        DeviceSuite(spec, 3, DT, G, 0, 4, VALUES)


def test_closed_loop_estimate_tracks_the_truth_up_to_the_motion_capture_bias():
    """Two AMs flying their approach on the estimator's odometry, default device levels: after
    the first second, the estimate's error beyond the motion capture's fixed bias is small, and
    the ground truth handed to telemetry carries the estimate beside it."""
    from amcore.config import read_scenario, scenario_from_dict
    from companion.pilot import Pilot
    from simulator.core import SitlCore
    from sitl.inprocess import as_on_the_wire, setpoint_as_on_the_wire
    from trials.randomize import load_randomize

    from ..conftest import SCENARIO
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    data = read_scenario(SCENARIO)
    data["devices"] = load_randomize(root / "configs" / "randomize" / "default.toml").devices
    data["scenario"]["seed"] = 11
    spec = scenario_from_dict(data, SCENARIO)
    truths = []
    core = SitlCore(spec, on_truth=truths.append)
    pilots = {s: Pilot(spec, s, model=core.model) for s in core.sysids}
    core.connect()
    rows = []
    try:
        for k in range(2500):
            frames = core.frames(k)
            if k >= 1000:
                for s, f in frames.items():
                    x, dev = core.exact_values[s], core.vehicles[s].devices
                    q_true = np.array(x[3:7])
                    d = quat_log(quat_mul(quat_mul(np.array([q_true[0], *(-q_true[1:])]), f.quat_WB_wxyz),
                                          quat_exp(-dev.mocap.bias_R)))
                    v_err = rotation(np.asarray(f.quat_WB_wxyz)) @ f.v_B - rotation(q_true) @ np.array(x[7:10])
                    rows.append([np.linalg.norm(f.p_WB - np.array(x[0:3]) - dev.mocap.bias_p), np.linalg.norm(d),
                                 np.linalg.norm(v_err), np.linalg.norm(f.w_B - np.array(x[10:13]))])
            core.actuate(k, {s: setpoint_as_on_the_wire(pilots[s].step(as_on_the_wire(f))[0])
                             for s, f in frames.items()})
            if k % 10 == 0 and k >= 1000:  # telemetry: this step's estimate beside its truth
                for s, f in frames.items():
                    est = np.array(truths[-1].ams[s].estimate)
                    assert est == pytest.approx(np.concatenate([f.p_WB, f.quat_WB_wxyz, f.v_B, f.w_B]), abs=1e-12)
            core.step()
    finally:
        core.close()
    p99 = np.percentile(np.array(rows), 99, axis=0)
    assert p99[0] < 5e-4  # m: the motion capture's noise, filtered
    assert p99[1] < 1.5e-3  # rad: gyro bias and motion-capture noise, filtered
    assert p99[2] < 5e-3  # m/s
    assert p99[3] < 0.03  # rad/s: the gyro's noise through IMU_GYRO_CUTOFF, its bias removed


def test_the_autopilot_rate_is_the_gyro_less_its_estimated_bias_unfiltered():
    """The rate loop takes the gyro with the estimator's bias removed and filters it once itself
    (PX4: VehicleAngularVelocity with EKF2's bias, then IMU_GYRO_CUTOFF); the odometry's rate is
    the one low-passed for the law."""
    spec = dataclasses.replace(FULL, estimator=dataclasses.replace(FULL.estimator, gyro_cutoff_hz=40.0))
    suite = DeviceSuite(spec, 3, DT, G, 3, 4, VALUES)
    raw, odo = [], []
    for i in range(4000):
        out = suite.step(VALUES, i * DT)
        raw.append(suite.autopilot_rate.copy())
        odo.append(out[10:13])
    sigma = 1.8665e-4 / math.sqrt(DT)
    assert np.linalg.norm(suite.imu.turn_on_g) > 5e-3  # this draw has a bias worth removing
    assert np.abs(np.mean(raw[2000:], axis=0)).max() < 5e-4  # ... and it is removed (at rest: w = 0)
    assert np.sqrt((np.array(raw[1000:]) ** 2).mean()) == pytest.approx(sigma, rel=0.1)  # white: unfiltered
    assert np.sqrt((np.array(odo[1000:]) ** 2).mean()) < 0.5 * sigma  # the law's: through 40 Hz


def test_attitude_mode_with_devices_flies_its_rate_loop_without_saturating():
    """The emulated autopilot on the hexarotor with every device at its default level, the
    companion with attitude mode's default options: its take-off saturates the rotors on less than the
    verdict's 5 % of the steps (measured: 0 and 59 of 1500, the 59 in the first 70 ms on the
    ground, rotors near idle, before the estimator has the turn-on gyro bias). Fed the odometry's
    low-passed rate, which it filtered a second time, the rate loop oscillated: 552 of 1500."""
    from amcore.config import read_scenario, scenario_from_dict
    from sitl import inprocess
    from trials.randomize import load_randomize
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    path = root / "configs" / "scenarios" / "two_am_comp_hex_attitude.toml"
    data = read_scenario(path)
    data["devices"] = load_randomize(root / "configs" / "randomize" / "default.toml").devices
    data["scenario"]["seed"] = 17
    res = inprocess.run(scenario_from_dict(data, path), duration_s=1.5)
    for s, am in res["ams"].items():
        assert am["rotor_saturated_steps"] < 75, (s, am["axis_saturated_steps"])
