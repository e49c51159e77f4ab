"""The rotors act on the base as the rotor table says: each rotor's force along its own axis
at its own position, with its drag torque; nothing else reaches the base."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from amcore.config import load_scenario
from amcore.model import build_model

from tests.amcore.literal import literal_rotor_wrench

from .sim_testing import at_rest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("scenario", ["two_am_comp", "two_am_comp_hex"])
def test_rotor_forces_move_the_base_as_a_rotor_by_rotor_sum(scenario, make_world):
    spec = load_scenario(ROOT / "configs" / "scenarios" / f"{scenario}.toml")  # ideal rotors
    model = build_model(spec.vehicle)
    rotors = spec.vehicle.rotors
    initial = {a.sysid: at_rest([-2.0 + 4.0 * i, 0.0, 3.0], np.eye(3), spec.vehicle.q_nominal_rad)
               for i, a in enumerate(spec.ams)}
    s = spec.ams[0].sysid
    rng = np.random.default_rng(3)
    for _ in range(3):  # one step from rest in a new world each
        w = make_world(initial, spec)
        f = rng.uniform(0.0, rotors.thrust_max_n, rotors.count)  # any thrusts: lateral force and all
        x0 = w.state(s)
        w.apply_rotors(s, f, [0.0] * spec.vehicle.n_joints)
        w.step()
        measured = (w.state(s).pin_v() - x0.pin_v()) / w.dt_s
        tau = np.concatenate([literal_rotor_wrench(rotors, f), np.zeros(spec.vehicle.n_joints)])
        predicted = pin.aba(model.pin_model, model.pin_model.createData(), x0.pin_q(), x0.pin_v(), tau)
        np.testing.assert_allclose(measured, predicted, rtol=1e-3, atol=1e-3)
    truth = w.ground_truth().ams[s]
    f_min, f_max = np.array(rotors.thrust_min()), np.array(rotors.thrust_max())
    assert truth.rotor_fraction_max == pytest.approx(np.max((f - f_min) / (f_max - f_min)))
    assert truth.rotor_fraction_min == pytest.approx(np.min((f - f_min) / (f_max - f_min)))


def test_a_torque_request_beyond_the_rotors_is_cut_per_axis_and_counted(make_world):
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp_hex.toml")
    initial = {a.sysid: at_rest([-2.0 + 4.0 * i, 0.0, 3.0], np.eye(3), spec.vehicle.q_nominal_rad)
               for i, a in enumerate(spec.ams)}
    w = make_world(initial, spec)
    s = spec.ams[0].sysid
    rep = w.apply(s, 25.0, [0.5, -0.2, 40.0], [0.0, 0.0, 0.0])  # far more yaw than the rotors make
    assert rep.mix.allocation.saturated_axes == (False, False, True, False)
    np.testing.assert_allclose(rep.mix.force_B_n, [0.0, 0.0, 25.0], atol=1e-9)  # no lateral force
    np.testing.assert_allclose(rep.mix.tau_B_nm[:2], [0.5, -0.2], atol=1e-9)
    assert 2.0 < rep.mix.tau_B_nm[2] < 40.0
    w.apply(s, 25.0, [0.5, -0.2, 0.1], [0.0, 0.0, 0.0])  # feasible: not counted
    w.step()
    truth = w.ground_truth().ams[s]
    assert truth.rotor_saturated_steps == 1 and truth.axis_saturated_steps == (0, 0, 1, 0)
