"""A link that delays every setpoint, the arm's torques with them ([link].delay_s, jitter_s,
joints = "link"), and the arm law's prediction over it ([options].offboard_latency_s,
amcore.offboard): in the in-process SITL, the law on the measured error sends implausible joint
torques within half a second, the law on the predicted error none (docs/flight_controller.md,
"Latency"). With the arm on its own servo bus (the default) the same delay reaches the
autopilot's setpoints only, and the grasp holds without a prediction."""
from __future__ import annotations

import pytest

from amcore.config import load_scenario
from sitl.inprocess import run

from .runner import SCENARIOS

pytestmark = pytest.mark.sitl


def _delayed(tmp_path, latency_s: float):
    text = f'base = "{SCENARIOS / "two_am_comp_attitude.toml"}"\n'
    path = tmp_path / f"delayed-{latency_s}.toml"
    path.write_text(text + f"\n[link]\ndelay_s = 0.005\njitter_s = 0.002\njoints = 'link'\n\n[options]\noffboard_latency_s = {latency_s}\n")
    return load_scenario(path)


def test_a_prediction_over_the_link_s_latency_keeps_the_arm_s_torques_plausible(tmp_path):
    blind = run(_delayed(tmp_path, 0.0), duration_s=0.5)
    assert blind["fc_link"]["4"]["delayed"] == blind["fc_link"]["4"]["sent"] > 0  # every setpoint came late
    assert blind["rejected_setpoints"] > 0
    predicted = run(_delayed(tmp_path, 0.006), duration_s=0.5)
    assert predicted["rejected_setpoints"] == 0 and predicted["events"] == []
    assert predicted["verdict"]["status"] == "incomplete"  # nothing failed
