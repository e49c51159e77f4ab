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
