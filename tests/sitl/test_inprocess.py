"""The in-process runner is the SITL minus sockets: same digest as the multi-process run."""
from __future__ import annotations

import pytest

from amcore.config import load_scenario
from simulator.inprocess import run

from .runner import SCENARIOS, am_run

pytestmark = pytest.mark.sitl


def test_in_process_run_is_bit_identical_to_the_multi_process_one(tmp_path):
    spec = load_scenario(SCENARIOS / "two_am_comp.toml")
    ours = run(spec, duration_s=0.4)
    sitl = am_run("two_am_comp.toml", tmp_path / "r", "--duration", "0.4", "--no-telemetry", timeout_s=300)
    assert sitl.code == 0, sitl.stderr
    assert ours["steps"] == sitl.outcome["steps"] == 400
    assert ours["state_digest"] == sitl.outcome["state_digest"]
