"""The wrench low-pass (exact derivatives) and the C3 reference trajectories."""
from __future__ import annotations

import numpy as np
import pytest

from amcore.filters import LowPass2, lowpass_accel, lowpass_update
from amcore.mission import path_through


@pytest.mark.parametrize("zeta", [0.7, 1.0, 1.5])
def test_lowpass_converges_and_its_derivatives_are_consistent(zeta):
    f = LowPass2(20.0, zeta)
    dt = 1e-3
    st = lowpass_update(f, None, np.array([0.0]), dt)
    xs, xds, xdds = [], [], []
    for k in range(400):
        u = np.array([1.0 + 0.2 * np.sin(2 * np.pi * 3 * k * dt)])
        st = lowpass_update(f, st, u, dt)
        xs.append(st.x[0]), xds.append(st.xdot[0]), xdds.append(lowpass_accel(f, st, u)[0])
    xs, xds = np.array(xs), np.array(xds)
    # the carried derivative is the derivative of the filtered signal
    assert np.abs(np.gradient(xs, dt)[5:-5] - xds[5:-5]).max() < 0.02 * np.abs(xds).max() + 1e-3
    assert np.abs(np.gradient(xds, dt)[5:-5] - np.array(xdds)[5:-5]).max() < 0.05 * np.abs(xdds).max() + 1e-2
    # a step settles at the input
    st2 = lowpass_update(f, None, np.array([0.0]), dt)
    for _ in range(500):
        st2 = lowpass_update(f, st2, np.array([2.0]), dt)
    assert st2.x[0] == pytest.approx(2.0, abs=1e-6)


def test_trajectory_is_C3_and_derivatives_match():
    p = path_through(np.zeros(3), [(0.0, 2.0, np.array([1.0, -1, 0.5])), (3.0, 4.0, np.array([0.0, 0, 0]))])
    h = 1e-5
    for t in np.linspace(-0.5, 4.5, 41) + 0.0123:  # off the junctions, where snap jumps
        v = p.eval(t, 4)
        vp, vm = p.eval(t + h, 4), p.eval(t - h, 4)
        for k in range(4):
            assert np.abs((vp[k] - vm[k]) / (2 * h) - v[k + 1]).max() < 1e-3 * (1 + np.abs(v[k + 1]).max())
    for tj in (0.0, 2.0, 3.0, 4.0):  # junctions: position..jerk continuous
        a, b = p.eval(tj - 1e-9, 3), p.eval(tj + 1e-9, 3)
        for k in range(4):
            assert np.abs(a[k] - b[k]).max() < 1e-6
    assert np.allclose(p.eval(10.0, 0)[0], 0.0)
    assert np.allclose(p.eval(2.5, 0)[0], [1.0, -1, 0.5])


def _expm_series(A):
    """exp(A) by scaling and squaring of a long Taylor series (slow, literal)."""
    k = max(0, int(np.ceil(np.log2(max(np.abs(A).max(), 1e-300)))) + 1)
    B = A / 2**k
    E, term = np.eye(2), np.eye(2)
    for i in range(1, 40):
        term = term @ B / i
        E = E + term
    for _ in range(k):
        E = E @ E
    return E


@pytest.mark.parametrize("zeta", [0.5, 1.0, 1.0 + 1e-9, 2.0])
def test_lowpass_transition_is_the_matrix_exponential(zeta):
    f = LowPass2(20.0, zeta)
    w = f.omega
    for dt in (1e-4, 1e-3, 4e-3, 2e-2):
        A = np.array([[0.0, 1.0], [-w * w, -2.0 * zeta * w]]) * dt
        E = _expm_series(A)
        assert np.abs(f.transition(dt) - E).max() < 1e-12 * np.abs(E).max()  # the series loses ~1e-13


def _eval_literal(path, t, orders):
    """SmoothPath.eval as first written: every started move overwrites, np.polyval per order."""
    S = np.array([0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0])

    def s(tau, order):
        if tau <= 0.0 or tau >= 1.0:
            return (1.0 if tau >= 1.0 else 0.0) if order == 0 else 0.0
        c = S.copy()
        for _ in range(order):
            c = c[1:] * np.arange(1, len(c))
        return float(np.polyval(c[::-1], tau))

    out = [np.array(path.start, dtype=float)] + [np.zeros_like(path.start, dtype=float) for _ in range(orders)]
    for mv in path.moves:
        if t < mv.t0:
            break
        T = mv.t1 - mv.t0
        tau = (t - mv.t0) / T
        d = mv.p1 - mv.p0
        out[0] = mv.p0 + d * s(tau, 0)
        for k in range(1, orders + 1):
            out[k] = d * (s(tau, k) / T**k)
    return out


def test_trajectory_evaluation_is_bit_identical_to_the_literal_one():
    p = path_through(np.array([0.3, -0.2, 1.0]), [(0.5, 2.0, np.array([1.0, -1, 0.5])),
                                                  (3.0, 4.5, np.array([0.0, 0.2, 0.7])),
                                                  (4.5, 6.0, np.array([-0.4, 0.2, 0.1]))])
    for t in np.concatenate([np.linspace(-1.0, 7.0, 801), [0.5, 2.0, 3.0, 4.5, 6.0]]):
        for orders in (0, 2, 4, 6):
            got, ref = p.eval(t, orders), _eval_literal(p, t, orders)
            assert len(got) == orders + 1
            for a, b in zip(got, ref):
                assert np.array_equal(a, b)


def test_float_filter_update_is_the_array_one():
    """lowpass_update_floats (the controller's) gives lowpass_update's values, including the
    first sample (no state) and a repeated time stamp (dt = 0)."""
    from amcore.filters import lowpass_update_floats

    f = LowPass2(15.0, 0.9)
    rng = np.random.default_rng(6)
    st = None
    for dt in (1e-3, 1e-3, 0.0, 2e-3, 1e-3):
        u = rng.normal(size=6)
        x, xd = lowpass_update_floats(f, st, u.tolist(), dt)
        st = lowpass_update(f, st, u, dt)
        assert np.array_equal(x, st.x) and np.array_equal(xd, st.xdot)
