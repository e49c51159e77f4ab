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


def test_impaired_link_is_deterministic_across_runs_and_transports(tmp_path):
    """[link] loss, delay, jitter, reordering and duplication act in simulation time: two
    multi-process runs and the in-process run of the same scenario and seed agree bit for bit."""
    text = (SCENARIOS / "two_am_comp.toml").read_text().replace(
        'vehicle = "../vehicles/am3dof.toml"', f'vehicle = "{SCENARIOS.parent / "vehicles" / "am3dof.toml"}"')
    text += "\n[link]\nloss = 0.3\ndelay_s = 0.001\njitter_s = 0.001\nreorder = 0.1\nduplicate = 0.1\n"
    path = tmp_path / "lossy.toml"
    path.write_text(text)
    ours = run(load_scenario(path), duration_s=0.4)
    assert ours["fc_link"]["4"]["lost"] > 50  # the impairment really acted
    digests = []
    for i in range(2):
        r = am_run(str(path), tmp_path / f"r{i}", "--duration", "0.4", "--no-telemetry", timeout_s=300)
        assert r.code == 0, r.stderr
        digests.append(r.outcome["state_digest"])
    assert digests[0] == digests[1] == ours["state_digest"]


def test_attitude_mode_in_process_run_is_bit_identical_to_the_multi_process_one(tmp_path):
    """Attitude mode at 250 Hz: the lockstep exchanges on control steps only, the emulated
    autopilot flies between them; SET_ATTITUDE_TARGET's float32 rounding is the same in both."""
    spec = load_scenario(SCENARIOS / "two_am_comp_attitude.toml")
    ours = run(spec, duration_s=0.4)
    sitl = am_run("two_am_comp_attitude.toml", tmp_path / "r", "--duration", "0.4", "--no-telemetry", timeout_s=300)
    assert sitl.code == 0, sitl.stderr
    assert ours["steps"] == sitl.outcome["steps"] == 400
    assert ours["flight_controller"] == sitl.outcome["flight_controller"] == "attitude"
    assert ours["fc_link"]["4"]["sent"] == sitl.outcome["fc_link"]["4"]["sent"] == 100  # one setpoint per 4 steps
    assert ours["state_digest"] == sitl.outcome["state_digest"]
