"""Shared fixtures of the simulator tests: the scenario, the pinocchio model, a world factory."""
from __future__ import annotations


import pytest

from simulator.world import World



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
