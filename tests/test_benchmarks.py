"""The benchmarks' scenarios load as the runs they time: `benchmarks.bench_sitl.scenario_with`
copies a shipped scenario, an overlay of its base among them, with N AMs into another folder
(bench_targets, bench_perf, bench_hosts and bench_inplace fly what it writes)."""
from __future__ import annotations

import pytest

from amcore.config import load_scenario
from benchmarks import bench_sitl


@pytest.mark.parametrize("attitude", [False, True])
@pytest.mark.parametrize("robust", [False, True])
def test_a_benchmark_scenario_loads_with_its_team_and_its_light_object(tmp_path, attitude, robust):
    base = bench_sitl.base_scenario(attitude, robust)
    spec = load_scenario(bench_sitl.scenario_with(5, tmp_path, base, devices=True, delay_steps=1))
    shipped = load_scenario(base)
    assert [am.sysid for am in spec.ams] == [2, 3, 4, 5, 6]
    assert spec.object.mass_kg == 1.0 and spec.devices.enabled
    assert spec.vehicle.flight_controller.mode == shipped.vehicle.flight_controller.mode
    assert spec.vehicle.flight_controller.actuation_delay_steps == 1
    assert spec.vehicle.rotors == shipped.vehicle.rotors
