"""The arm law's task error predicted over the link's latency ([options].offboard_latency_s,
amcore.offboard.predicted_task_error): exact for piecewise-constant task accelerations, off
at 0, and what it does to the sampled impedance loop when every command acts L late."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from amcore import law
from amcore.config import ConfigError, load_scenario
from amcore.control import step
from amcore.model import create_data
from amcore.offboard import OffboardMemory, OffboardParams, offboard_step, predicted_task_error

from .test_control import near_reference, steady_memory

ROOT = Path(__file__).resolve().parents[2]


def _superposed(y, v, pending, t0, L):
    """The same prediction by superposition: each a_j acts on [s_j, e_j] within [t0, t0 + L] (s_j =
    t_j + L, e_j the next one's start) and adds a_j ((end - s_j)^2 - (end - e_j)^2) / 2 to y~ and
    a_j (e_j - s_j) to y~'."""
    y, v = np.array(y, float) + np.asarray(v, float) * L, np.array(v, float)
    end = t0 + L
    starts = [t_j + L for t_j, _ in pending] + [end]
    for (_, a_j), s_j, e_j in zip(pending, starts, starts[1:]):
        s_j, e_j = min(max(s_j, t0), end), min(max(e_j, t0), end)
        y += np.asarray(a_j) * ((end - s_j) ** 2 - (end - e_j) ** 2) / 2.0
        v += np.asarray(a_j) * (e_j - s_j)
    return y, v


def test_the_prediction_integrates_the_commands_in_flight_exactly():
    rng = np.random.default_rng(5)
    for L in (0.003, 0.010, 0.021):
        t = 1.0
        sent = t - L - 0.004 + 0.004 * np.arange(int(L / 0.004) + 2)  # one acting before t, the rest in flight
        pending = [(float(t_j), rng.normal(size=3) * 50.0) for t_j in sent if t_j < t]
        y0, v0 = rng.normal(size=3) * 1e-2, rng.normal(size=3) * 0.1
        y, v = predicted_task_error(y0, v0, pending, t, L)
        y_ref, v_ref = _superposed(y0, v0, pending, t, L)
        np.testing.assert_allclose(y, y_ref, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(v, v_ref, rtol=1e-12, atol=1e-15)
    y, v = predicted_task_error(np.ones(3), np.full(3, 2.0), (), 0.0, 0.01)  # nothing known in flight: coasting
    np.testing.assert_allclose(y, 1.02)
    np.testing.assert_allclose(v, 2.0)


def test_at_rest_on_the_reference_nothing_is_predicted_and_the_command_is_the_law_s(model, mission, params):
    """No task error, no task velocity and nothing in flight: the prediction moves nothing, and
    the command equals the one without it (the prediction acts only through the task error)."""
    st = near_reference(mission, model, 8.0, np.random.default_rng(6), scale=0.0)
    ref = mission.reference(8.0)
    base = step(model, create_data(model), params, st, ref, np.zeros(6), steady_memory(model, st, np.zeros(6), 8.0), 8.0)
    mem = OffboardMemory(steady_memory(model, st, np.zeros(6), 8.0))
    ref0 = ref._replace(y_d1=base.diagnostics.ydot.copy())  # the task's own rate: no y~'
    ref0 = ref0._replace(y=ref0.y + base.diagnostics.y_err)  # ... and no y~
    off = offboard_step(model, create_data(model), params, st, ref0, np.zeros(6), mem, 8.0, oparams=OffboardParams())
    on = offboard_step(model, create_data(model), params, st, ref0, np.zeros(6), mem, 8.0,
                       oparams=OffboardParams(latency_s=0.01))
    np.testing.assert_allclose(on.result.command.tau_q_nm, off.result.command.tau_q_nm, atol=1e-9)
    assert len(on.memory.pending) == 1 and off.memory.pending == ()
    np.testing.assert_allclose(on.result.diagnostics.y_err, off.result.diagnostics.y_err, atol=1e-12)


def _delayed_loop(L_y, K, D, h, latency, predict, periods=400, sub=4):
    """Largest |y~| over the last 50 periods of Lambda y~'' = u, each command computed at t_k from
    the measured (or predicted) error, held, and acting from t_k + latency; y~(0) = 1 mm."""
    n = L_y.shape[0]
    y, v = np.full(n, 1e-3), np.zeros(n)
    pending: list[tuple[float, np.ndarray]] = []
    dt = h / sub
    peak = 0.0
    for k in range(periods):
        t = k * h
        yp, vp = predicted_task_error(y, v, pending, t, latency) if predict else (y, v)
        pending.append((t, np.linalg.solve(L_y, -K.dot(yp) - D.dot(vp))))
        pending = [p for p in pending if p[0] + latency > t - h]  # keep the one acting and those to come
        for i in range(sub):  # the plant, exact for piecewise-constant y~''
            tau = t + i * dt
            a = next((a_j for t_j, a_j in reversed(pending) if t_j + latency <= tau + 1e-12), np.zeros(n))
            y, v = y + v * dt + 0.5 * a * dt * dt, v + a * dt
        if k >= periods - 50:
            peak = max(peak, float(np.abs(y).max()))
    return peak


def test_with_a_latency_of_two_and_a_half_periods_the_prediction_keeps_the_sampled_loop_contracting(
        model, mission, params):
    """The paper's vehicle near its grasp pose, 250 Hz, every command 10 ms late: with the
    measured error the pad's pitch mode (Lambda_y ~2.4e-4) grows; with the predicted one the
    error decays as without latency."""
    st = near_reference(mission, model, 8.0, np.random.default_rng(3), scale=0.0)
    res = step(model, create_data(model), params, st, mission.reference(8.0), np.zeros(6),
               steady_memory(model, st, np.zeros(6), 8.0), 8.0)
    L_y, h = res.diagnostics.Lambda_y, 4e-3
    K, D = params.K_y, law.discrete_damping(L_y, params.D_y, h)
    assert _delayed_loop(L_y, K, D, h, 0.010, predict=False) > 1e-2  # grown tenfold and more
    assert _delayed_loop(L_y, K, D, h, 0.010, predict=True) < 1e-6
    assert _delayed_loop(L_y, K, D, h, 0.0, predict=False) < 1e-6


def test_the_latency_option_is_checked_and_off_by_default(tmp_path):
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp_attitude.toml")
    assert spec.vehicle.options.offboard_latency_s == 0.0
    assert OffboardParams.from_vehicle(spec.vehicle).latency_s == 0.0
    v = dataclasses.replace(spec.vehicle, options=dataclasses.replace(spec.vehicle.options, offboard_latency_s=0.011))
    assert OffboardParams.from_vehicle(v).latency_s == 0.011
    p = tmp_path / "s.toml"
    p.write_text(f'base = "{ROOT / "configs" / "scenarios" / "two_am_comp_attitude.toml"}"\n'
                 f"\n[options]\noffboard_latency_s = -0.01\n")
    with pytest.raises(ConfigError, match=r"\[options\].offboard_latency_s: must be in \[0, 0.5\] s"):
        load_scenario(p)
