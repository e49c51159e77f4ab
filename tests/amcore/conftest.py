"""Shared fixtures: the paper's vehicle, random states, flow along a constant body twist."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from amcore.control import ControllerParams
from amcore.mission import am_mission
from amcore.model import AmState, create_data
from amcore.so3 import exp_so3



@pytest.fixture(scope="session")
def mission(spec, model):
    return am_mission(spec, spec.ams[0], model)


@pytest.fixture()
def params(spec, mission):
    return ControllerParams.from_vehicle(spec.vehicle, mission.frame)


def random_state(rng: np.random.Generator, n: int, q_center=None, spread: float = 0.6) -> AmState:
    """A random state around the nominal pose, away from arm singularities."""
    qc = np.zeros(n) if q_center is None else np.asarray(q_center)
    return AmState(
        p_WB=rng.normal(size=3),
        R_WB=exp_so3(rng.normal(size=3)),
        v_B=rng.normal(size=3),
        w_B=rng.normal(size=3),
        q=qc + spread * rng.uniform(-1, 1, size=n),
        qdot=rng.normal(size=n),
    )


def flow(model, state: AmState, h: float) -> AmState:
    """The state after moving for time h with constant V (body twist and joint rates)."""
    q = pin.integrate(model.pin_model, state.pin_q(), state.pin_v() * h)
    return AmState.from_pin(q, state.pin_v())


def states(model, count: int = 12, seed: int = 0):
    rng = np.random.default_rng(seed)
    qn = model.vehicle.q_nominal_rad
    return [random_state(rng, model.n, qn) for _ in range(count)]


@pytest.fixture()
def data(model):
    return create_data(model)
