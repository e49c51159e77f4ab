"""Real payload sources for the telemetry tests: one controller step, one ground truth with contact."""
from __future__ import annotations

import numpy as np
import pytest

from amcore.control import ControllerMemory, ControllerParams, step
from amcore.mission import am_mission
from amcore.model import create_data
from simulator.world import World
from tests.simulator.sim_testing import facing_object


@pytest.fixture(scope="session")
def step_result(spec, model):
    """A controller step off the reference (nonzero errors everywhere), with a measured wrench."""
    m = am_mission(spec, spec.ams[0], model)
    params = ControllerParams.from_vehicle(spec.vehicle, m.frame)
    x = m.initial_state()
    x = type(x)(p_WB=x.p_WB + np.array([0.03, -0.02, 0.01]), R_WB=x.R_WB, v_B=x.v_B + 0.1, w_B=x.w_B + 0.05,
                q=x.q + 0.05, qdot=x.qdot)
    return step(model, create_data(model), params, x, m.reference(0.7), np.array([-3.0, 0.2, 1.0, 0.0, 0.01, 0.0]),
                ControllerMemory(), 0.7)


@pytest.fixture(scope="session")
def ground_truth(spec, model):
    """Both pads placed 1 cm into the box; after the first step both push on it."""
    with World(spec, facing_object(spec, model, depth_m=0.01)) as w:
        w.step()
        gt = w.ground_truth()
    assert all(a.pad_object_contact.normal_force_n > 0 for a in gt.ams.values())
    return gt
