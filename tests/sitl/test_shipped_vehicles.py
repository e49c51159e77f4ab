"""Every vehicle in configs/vehicles, in torque and attitude mode: it hovers in free flight at
the approach's end with its pad where the mission puts it, and two of them grasp and lift the
paper's box in the short mission (two_am_short's timing) without saturating, the busiest
rotor below 95 % of its range in the hover window (am3dof's reached 90.4 % in torque mode)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amcore.config import read_scenario, scenario_from_dict
from amcore.mission import am_mission
from amcore.model import build_model
from sitl.inprocess import run

ROOT = Path(__file__).resolve().parents[2]
VEHICLES = sorted((ROOT / "configs" / "vehicles").glob("*.toml"))

pytestmark = pytest.mark.sitl


def short_grasp(vehicle: Path, mode: str):
    """two_am_short on `vehicle`; attitude mode as the *_attitude scenarios fly it (the companions
    at 250 Hz, the vehicle's own lagging rotors)."""
    path = ROOT / "configs" / "scenarios" / "two_am_short.toml"
    data = read_scenario(path)
    data["scenario"].update(vehicle=str(vehicle.resolve()), name=f"two_am_short_{vehicle.stem}_{mode}")
    if mode == "attitude":
        data["scenario"]["control_rate_hz"] = 250.0
        data["flight_controller"] = {"mode": "attitude"}
        data.pop("rotors")
    return scenario_from_dict(data, path)


@pytest.mark.parametrize("mode", ["torque", "attitude"])
@pytest.mark.parametrize("vehicle", VEHICLES, ids=lambda p: p.stem)
def test_every_shipped_vehicle_hovers_and_grasps(vehicle, mode):
    spec = short_grasp(vehicle, mode)
    t_hover = spec.mission.approach_end_s  # free flight, at rest 2 cm off the faces
    seen = {}

    def at_hover(gt):
        if abs(gt.time_s - t_hover) < 0.005:
            seen.update({s: am.p_WE.copy() for s, am in gt.ams.items()})

    out = run(spec, on_truth=at_hover)
    model = build_model(spec.vehicle)
    assert set(seen) == {am.sysid for am in spec.ams}
    comps = spec.vehicle.task.components
    for am in spec.ams:
        m = am_mission(spec, am, model)
        y = m.reference(t_hover).y
        p_T = [y[comps.index("x")], m.nominal.p_BE[1] - m.nominal.r_BC[1], y[comps.index("z")]]
        p_WE_d = m.frame.p_WT + m.frame.R_WT @ p_T
        assert np.linalg.norm(seen[am.sysid] - p_WE_d) < 0.01, (am.sysid, seen[am.sysid], p_WE_d)
    assert out["verdict"]["success"], out["verdict"]["text"]
    assert out["object"]["hover_min_lift_m"] >= 0.2
    share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
    for sysid, a in out["ams"].items():
        assert a["saturated_steps"] == 0, (sysid, a["saturated_steps"])
        assert 0.0 < a["hover_rotor_fraction_min"] and a["hover_rotor_fraction_max"] < 0.95
        assert abs(-a["hover_mean_ft_force_W_n"][2] - share) / share < 0.05
        assert a["slip_max_m"] < 5e-3
