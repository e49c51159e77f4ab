"""Shared fixtures of the simulator tests: the scenario, the pinocchio model, a world factory."""
from __future__ import annotations

from pathlib import Path

import pytest

from amcore.config import load_scenario
from amcore.model import build_model
from simulator.world import World

REPO = Path(__file__).resolve().parents[2]
SCENARIO = REPO / "configs" / "scenarios" / "two_am_comp.toml"


@pytest.fixture(scope="session")
def spec():
    return load_scenario(SCENARIO)


@pytest.fixture(scope="session")
def model(spec):
    return build_model(spec.vehicle)


@pytest.fixture
def make_world(spec):
    """Factory of connected worlds, closed at the end of the test."""
    worlds = []

    def make(initial, scenario=None):
        w = World(scenario or spec, initial)
        w.connect()
        worlds.append(w)
        return w

    yield make
    for w in worlds:
        w.close()
