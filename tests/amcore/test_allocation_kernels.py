"""The compiled allocation (amcore.allocation_kernels, Allocation(compiled=True)) against the
Python allocation it transcribes: the same result and rotor thrusts bit for bit, inside the
limits and desaturated, for the quad and the canted hexarotor."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amcore.allocation import Allocation
from amcore.config import load_vehicle

VEHICLES = Path(__file__).resolve().parents[2] / "configs" / "vehicles"


@pytest.mark.parametrize("vehicle", ["am3dof.toml", "hex3dof.toml"])
def test_compiled_allocation_equals_the_python_one(vehicle):
    rotors = load_vehicle(VEHICLES / vehicle).rotors
    fast, slow = Allocation(rotors, compiled=True), Allocation(rotors, compiled=False)
    rng = np.random.default_rng(2)
    saturated = 0
    for scale in (0.05, 0.3, 1.0, 3.0):
        for _ in range(2000):
            roll, pitch, yaw = (scale * rng.normal(size=3)).tolist()
            thrust = float(rng.uniform(-0.2, 1.3))
            a, b = fast.allocate(roll, pitch, yaw, thrust), slow.allocate(roll, pitch, yaw, thrust)
            assert a == b, (roll, pitch, yaw, thrust)
            (a, f), (b, e) = fast.allocate_thrusts(roll, pitch, yaw, thrust), slow.allocate_thrusts(roll, pitch, yaw,
                                                                                                  thrust)
            assert a == b and f == e and f == tuple(u * m for u, m in zip(b.outputs, rotors.thrust_max()))
            saturated += b.saturated
        tau = (scale * rng.normal(size=3)).tolist()
        assert fast.allocate_wrench(20.0 * scale, tau) == slow.allocate_wrench(20.0 * scale, tau)
    assert 1000 < saturated < 7000  # both branches taken many times
