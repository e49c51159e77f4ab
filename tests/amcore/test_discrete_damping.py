"""Eq. u3's task damping discretized for the control period (amcore.law.discrete_damping,
[options].discrete_damping): what it equals, and what it does to the sampled impedance loop
of the paper's vehicle when a setpoint is held over two periods."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from amcore import law
from amcore.control import step
from amcore.model import create_data

from .test_control import near_reference, steady_memory


def _expm_eig(A):
    w, V = np.linalg.eig(A)
    return (V @ np.diag(np.exp(w)) @ np.linalg.inv(V)).real


def _spd(rng, n, lo, hi):
    Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    return Q @ np.diag(np.exp(rng.uniform(np.log(lo), np.log(hi), n))) @ Q.T


def test_expm_small_against_the_eigendecomposition():
    rng = np.random.default_rng(1)
    for scale in (1e-3, 0.3, 3.0, 30.0):
        L, D = _spd(rng, 3, 1e-4, 1.0), np.diag(rng.uniform(0.01, 20.0, 3))
        A = -np.linalg.solve(L, D) * scale / np.abs(np.linalg.solve(L, D)).max()  # diagonalizable, real spectrum
        np.testing.assert_allclose(law.expm_small(A), _expm_eig(A), rtol=1e-10, atol=1e-12)


def test_it_takes_the_velocity_where_the_continuous_damper_does_and_is_symmetric():
    """I - dt Lambda^-1 D_dt = exp(-Lambda^-1 D dt): one held period of D_dt does to the task
    velocity what the continuous D does in that time; D_dt -> D as dt -> 0."""
    rng = np.random.default_rng(2)
    for _ in range(5):
        L, D = _spd(rng, 3, 2e-4, 0.5), np.diag(rng.uniform(0.01, 20.0, 3))
        for dt in (1e-3, 4e-3, 1e-2):
            Dd = law.discrete_damping(L, D, dt)
            np.testing.assert_allclose(Dd, Dd.T, rtol=1e-9, atol=1e-12 * np.abs(Dd).max())
            np.testing.assert_allclose(np.eye(3) - dt * np.linalg.solve(L, Dd), _expm_eig(-np.linalg.solve(L, D) * dt),
                                       atol=1e-9)
        h = 1e-9  # D_dt = D - dt/2 D Lambda^-1 D + O(dt^2)
        np.testing.assert_allclose(law.discrete_damping(L, D, h), D - 0.5 * h * D @ np.linalg.solve(L, D),
                                   rtol=1e-5, atol=1e-6)


def _sampled_loop(L, K, D, dt, hold):
    """Spectral radius of the task error's map over `hold` periods of one command computed from
    the state at the start (Lambda y'' = -K y - D y', the command held: a lost setpoint)."""
    n = L.shape[0]
    A = np.block([[np.zeros((n, n)), np.eye(n)], [np.zeros((n, n)), np.zeros((n, n))]])
    B = np.vstack([np.zeros((n, n)), np.linalg.inv(L)])
    Mx = np.zeros((3 * n, 3 * n))
    Mx[:2 * n, :2 * n], Mx[:2 * n, 2 * n:] = A, B
    E = law.expm_small(Mx * dt * hold)
    return max(abs(np.linalg.eigvals(E[:2 * n, :2 * n] + E[:2 * n, 2 * n:] @ np.hstack([-K, -D]))))


def test_at_250_hz_a_held_setpoint_rings_the_pads_pitch_mode_up_unless_the_damping_is_discretized(
        model, mission, params):
    """The paper's vehicle near its grasp pose: at 1 kHz every map contracts; at 250 Hz the
    mode of little task inertia sits near -1 with D_y, and a setpoint held over two periods
    makes it grow; with the discretized damping that map contracts."""
    rng = np.random.default_rng(3)
    st = near_reference(mission, model, 8.0, rng, scale=0.0)
    res = step(model, create_data(model), params, st, mission.reference(8.0), np.zeros(6),
               steady_memory(model, st, np.zeros(6), 8.0), 8.0)
    L, K, D = res.diagnostics.Lambda_y, params.K_y, params.D_y
    assert _sampled_loop(L, K, D, 1e-3, 2) < 1.0
    assert _sampled_loop(L, K, D, 4e-3, 1) < 1.0 < _sampled_loop(L, K, D, 4e-3, 2)
    Dd = law.discrete_damping(L, D, 4e-3)
    assert _sampled_loop(L, K, Dd, 4e-3, 1) < 1.0 and _sampled_loop(L, K, Dd, 4e-3, 2) < 1.0


def test_the_option_off_is_the_paper_s_law_and_on_changes_only_the_damping_term(model, mission, params):
    rng = np.random.default_rng(4)
    st = near_reference(mission, model, 8.0, rng, scale=0.5)
    F_e = rng.normal(size=6)
    mem, ref = steady_memory(model, st, F_e, 8.0), mission.reference(8.0)
    paper = step(model, create_data(model), params, st, ref, F_e, mem, 8.0)
    on = step(model, create_data(model), dataclasses.replace(params, damping_dt=4e-3), st, ref, F_e, mem, 8.0)
    np.testing.assert_array_equal(on.diagnostics.u[:6], paper.diagnostics.u[:6])  # eqs. Com_, ori_controller untouched
    assert np.abs(on.command.tau_q_nm - paper.command.tau_q_nm).max() > 1e-6  # the arm's law did change
    resting = st._replace(qdot=np.zeros_like(st.qdot), v_B=np.zeros(3), w_B=np.zeros(3))
    ref0 = ref._replace(y_d1=np.zeros_like(ref.y_d1)) if hasattr(ref, "_replace") else dataclasses.replace(
        ref, y_d1=np.zeros_like(ref.y_d1))
    a = step(model, create_data(model), params, resting, ref0, F_e, mem, 8.0)
    b = step(model, create_data(model), dataclasses.replace(params, damping_dt=4e-3), resting, ref0, F_e, mem, 8.0)
    np.testing.assert_allclose(b.command.tau_q_nm, a.command.tau_q_nm, atol=1e-12)  # no task velocity: no change
