"""The servos' joint-effort reading (simulator.devices.JointEffortSensor): its lag, noise and quantization have
the statistics its parameters state, and its draws follow its seed alone."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amcore.config import JointEffortSpec
from simulator.devices import JointEffortSensor

DT = 0.001


def test_exact_without_parameters():
    s = JointEffortSensor(JointEffortSpec(), 1.0, 3, DT, 1, 4)
    for u in ([0.1, -0.2, 0.3], [1.0, 2.0, -3.0]):
        np.testing.assert_array_equal(s.sample(u), u)


@pytest.mark.parametrize("lag_s", [0.002, 0.01])
def test_the_lag_is_first_order_with_its_time_constant(lag_s):
    """A unit step from rest: the reading reaches 1 - exp(-t / lag_s) at every step."""
    s = JointEffortSensor(JointEffortSpec(lag_s=lag_s), 1.0, 1, DT, 1, 4)
    s.sample([0.0])
    for k in range(1, 50):
        y = s.sample([1.0])[0]
        assert y == pytest.approx(1.0 - math.exp(-k * DT / lag_s), rel=1e-12)


def test_the_noise_has_its_stated_rms_and_no_mean_and_is_white():
    s = JointEffortSensor(JointEffortSpec(noise_nm=0.013), 1.0, 3, DT, 7, 5)
    y = np.array([s.sample([0.5, -0.5, 0.0]) for _ in range(20000)]) - [0.5, -0.5, 0.0]
    assert np.all(np.abs(y.std(axis=0) / 0.013 - 1.0) < 0.03)  # 20000 samples: std's rel. error ~0.5 %
    assert np.all(np.abs(y.mean(axis=0)) < 5 * 0.013 / math.sqrt(20000))
    lag1 = np.mean(y[1:, 0] * y[:-1, 0]) / np.mean(y[:, 0] ** 2)
    assert abs(lag1) < 0.03


def test_the_scale_multiplies_the_noise_and_the_reading_is_quantized():
    r = 0.0065
    s = JointEffortSensor(JointEffortSpec(noise_nm=0.01, resolution_nm=r), 2.0, 2, DT, 3, 4)
    assert s.noise_nm == 0.02
    y = np.array([s.sample([0.3, 0.0123]) for _ in range(2000)])
    np.testing.assert_allclose(y / r, np.round(y / r), atol=1e-9)
    assert abs(y[:, 0].mean() - 0.3) < 3 * 0.02 / math.sqrt(2000) + r / 2


def test_same_seed_same_reading_other_sysid_other_draws():
    spec = JointEffortSpec(lag_s=0.002, noise_nm=0.013, resolution_nm=0.0065)
    a, b, c = (JointEffortSensor(spec, 1.0, 3, DT, 11, s) for s in (4, 4, 5))
    ya = [a.sample([0.1, 0.2, 0.3]).tolist() for _ in range(100)]
    assert ya == [b.sample([0.1, 0.2, 0.3]).tolist() for _ in range(100)]
    assert ya != [c.sample([0.1, 0.2, 0.3]).tolist() for _ in range(100)]


class LiteralEffort:
    """The reading as the module doc writes it, in numpy, one draw call per step."""

    def __init__(self, spec, scale, n, dt, seed, sysid):
        from simulator.devices import _EFFORT_STREAM as _STREAM
        self.noise, self.res = scale * spec.noise_nm, spec.resolution_nm
        self.alpha = 1.0 if spec.lag_s <= 0.0 else -math.expm1(-dt / spec.lag_s)
        self.rng, self.n, self.x = np.random.default_rng([seed, sysid, _STREAM]), n, None

    def sample(self, u):
        u = np.asarray(u, dtype=float)
        self.x = u.copy() if self.x is None else self.x + self.alpha * (u - self.x)
        y = self.x + self.noise * self.rng.standard_normal(self.n) if self.noise > 0.0 else self.x.copy()
        return self.resolution(y)

    def resolution(self, y):
        return self.res * np.round(y / self.res) if self.res > 0.0 else y


@pytest.mark.parametrize("spec", [JointEffortSpec(), JointEffortSpec(lag_s=0.002, noise_nm=0.013, resolution_nm=0.0065),
                                  JointEffortSpec(noise_nm=0.01)])
def test_readings_formed_when_read_equal_the_literal_ones_bit_for_bit(spec):
    """Every step advances; a frame reads the reading every 4th step (attitude mode)."""
    fast, slow = JointEffortSensor(spec, 1.5, 3, DT, 2, 4), LiteralEffort(spec, 1.5, 3, DT, 2, 4)
    rng = np.random.default_rng(0)
    for k in range(1000):
        u = rng.normal(scale=0.5, size=3).tolist()
        y = slow.sample(u)
        fast.advance(u)
        if k % 4 == 0 or k > 900:
            assert fast.last.tolist() == y.tolist(), f"step {k}"
