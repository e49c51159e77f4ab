"""Rotor dynamics (simulator.actuators): the first-order thrust lag, alone and inside the world."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest

from simulator.actuators import RotorLag

from .sim_testing import at_rest


def with_rotor_lag(spec, tau_s: float):
    v = spec.vehicle
    return dataclasses.replace(spec, vehicle=dataclasses.replace(
        v, rotors=dataclasses.replace(v.rotors, time_constant_s=tau_s)))


def test_lag_starts_at_its_first_command_and_follows_the_exact_first_order_response():
    tau, dt = 0.025, 0.001
    lag = RotorLag(tau, dt)
    assert lag.step([1.0, 2.0, 3.0, 4.0]) == [1.0, 2.0, 3.0, 4.0]
    for n in range(1, 101):
        f = lag.step([5.0] * 4)
        for f0, fi in zip([1.0, 2.0, 3.0, 4.0], f):
            assert fi == pytest.approx(5.0 + (f0 - 5.0) * math.exp(-n * dt / tau), rel=1e-12)
    with pytest.raises(ValueError):
        RotorLag(0.0, dt)


def test_world_rotors_lag_the_command_and_the_vehicle_feels_the_lagging_thrust(spec, model, make_world):
    """A step from hover thrust to 1.2 times it: after one time constant the rotors have made
    63 % of the step, and the vertical speed gained is the integral of the lagging thrust."""
    tau = 0.025
    q_hang = [np.pi / 2, 0.0, 0.0]  # CoM on the thrust line: thrust alone, no torque
    initial = {a.sysid: at_rest([-2.0 + 4.0 * i, 0.0, 3.0], np.eye(3), q_hang) for i, a in enumerate(spec.ams)}
    m = pin.computeTotalMass(model.pin_model)
    hover = m * spec.vehicle.gravity_mps2
    runs = {}
    for name, scenario in (("ideal", spec), ("lag", with_rotor_lag(spec, tau))):
        w = make_world(initial, scenario)
        s = w.sysids[0]
        w.apply(s, hover, np.zeros(3), np.zeros(3))
        w.step()
        n = round(tau / spec.dt_s)
        for _ in range(n):
            w.apply(s, 1.2 * hover, np.zeros(3), np.zeros(3))
            w.step()
        x = w.state(s)
        runs[name] = ((x.R_WB @ x.v_B)[2], w.rotor_thrusts(s))
    assert runs["ideal"][1] is None  # ideal rotors: no lag state at all
    made = (sum(runs["lag"][1]) - hover) / (0.2 * hover)
    assert made == pytest.approx(1.0 - math.exp(-n * spec.dt_s / tau), rel=1e-9)
    # ideal: 0.2 g for n steps; lagging: 0.2 g times the mean fraction made over the steps
    dt, a = spec.dt_s, 0.2 * spec.vehicle.gravity_mps2
    assert runs["ideal"][0] == pytest.approx(a * n * dt, rel=1e-6)
    mean_made = np.mean([1.0 - math.exp(-k * dt / tau) for k in range(1, n + 1)])
    assert runs["lag"][0] == pytest.approx(a * n * dt * mean_made, rel=1e-6)
