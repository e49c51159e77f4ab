"""Fixtures shared by every test folder: the paper's two-AM scenario and its vehicle model."""
from __future__ import annotations

from pathlib import Path

import pytest

from amcore.config import load_scenario
from amcore.model import build_model

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "configs" / "scenarios" / "two_am_comp.toml"


@pytest.fixture(scope="session")
def spec():
    return load_scenario(SCENARIO)


@pytest.fixture(scope="session")
def model(spec):
    return build_model(spec.vehicle)


def pytest_collection_modifyitems(config, items):
    """Tests marked `slow` (a fresh install into a new environment: minutes) run only when the
    marker expression asks for them (`pytest -m slow`); the default run skips them, saying how."""
    if "slow" in (config.getoption("-m") or ""):
        return
    skip = pytest.mark.skip(reason="slow (minutes); run with: pytest -m slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
