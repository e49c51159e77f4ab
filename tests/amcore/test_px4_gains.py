"""Attitude mode's PX4 gains derived from the vehicle (amcore.px4_gains): the rule gives back
hex3dof's hand-made values and am3dof's own; a key a vehicle file gives wins over the rule."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from amcore import px4_gains
from amcore.config import load_vehicle, px4_units

VEHICLES = Path(__file__).resolve().parents[2] / "configs" / "vehicles"


@pytest.mark.parametrize("name", ["am3dof", "hex3dof"])
def test_the_rule_gives_back_the_hand_made_gains(name):
    """hex3dof's gains were carried over from am3dof by hand (its file says how, 4 digits kept):
    the rule at hex3dof's inertia and torque units gives each within 0.1 %."""
    v = load_vehicle(VEHICLES / f"{name}.toml")
    rule = px4_gains.derived_gains(*px4_units(v))
    for key, value in rule.items():
        assert getattr(v.flight_controller, key) == pytest.approx(value, rel=1e-3, abs=1e-9), key


def test_the_rule_scales_with_inertia_and_units():
    J, S = px4_gains.REFERENCE_J_KG_M2, px4_gains.REFERENCE_S_NM
    twice = px4_gains.derived_gains([2 * j for j in J], S)
    half_units = px4_gains.derived_gains(J, [2 * s for s in S])
    for key in ("MC_ROLLRATE_P", "MC_PITCHRATE_I", "MC_PITCHRATE_D", "MC_YAWRATE_P"):
        assert twice[key] == pytest.approx(2 * px4_gains.REFERENCE[key])
        assert half_units[key] == pytest.approx(px4_gains.REFERENCE[key] / 2)
    assert twice["MC_PR_INT_LIM"] == px4_gains.REFERENCE["MC_PR_INT_LIM"]  # a moment: units only
    assert half_units["MC_PR_INT_LIM"] == pytest.approx(px4_gains.REFERENCE["MC_PR_INT_LIM"] / 2)
    assert twice["MC_PITCH_P"] == px4_gains.REFERENCE["MC_PITCH_P"]


def test_a_file_key_overrides_the_rule(tmp_path):
    """am4dof gives no gains: all derived; one given in its file is used as given."""
    text = (VEHICLES / "am4dof.toml").read_text()
    v = load_vehicle(VEHICLES / "am4dof.toml")
    rule = px4_gains.derived_gains(*px4_units(v))
    assert v.flight_controller.MC_PITCHRATE_P == pytest.approx(rule["MC_PITCHRATE_P"], rel=1e-12)
    (tmp_path / "am4dof.urdf").write_text((VEHICLES / "am4dof.urdf").read_text())
    p = tmp_path / "am4dof.toml"
    p.write_text(re.sub(r"^body_rate_feedforward = true$", "body_rate_feedforward = true\nMC_PITCHRATE_P = 0.2",
                        text, count=1, flags=re.M))
    w = load_vehicle(p)
    assert w.flight_controller.MC_PITCHRATE_P == 0.2
    assert w.flight_controller.MC_ROLLRATE_P == pytest.approx(rule["MC_ROLLRATE_P"], rel=1e-12)
