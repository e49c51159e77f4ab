"""The wrench low-pass (exact derivatives) and the C3 reference trajectories."""
from __future__ import annotations

import numpy as np
import pytest

from amcore.filters import LowPass2, lowpass_accel, lowpass_update
from amcore.trajectory import path_through


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
