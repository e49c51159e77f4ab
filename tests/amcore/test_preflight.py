"""The pre-flight envelope check (amcore.preflight) at the envelope's edge, both ways: at the
scenario's squeeze cap and at the vehicle's margins; what it tells the user; the runners refuse
before anything flies (exit 2)."""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path

import pytest

from amcore import preflight as pf
from amcore.config import ConfigError, design_mass_kg, load_scenario
from amcore.envelope import Envelope, Margins
from amcore.mission import squeeze_plan
from amcore.model import build_model

ROOT = Path(__file__).resolve().parents[2]
ROBUST = ROOT / "configs" / "scenarios" / "two_am_robust.toml"


@pytest.fixture(scope="module")
def robust():
    return load_scenario(ROBUST)


def with_(spec, obj=None, **mission):
    return dataclasses.replace(spec, object=dataclasses.replace(spec.object, **(obj or {})),
                               mission=dataclasses.replace(spec.mission, **mission))


def cap_edge_kg(spec) -> float:
    """The design mass whose required squeeze is exactly [mission].squeeze_max_n."""
    m, v = spec.mission, spec.vehicle
    return m.squeeze_max_n * len(spec.ams) * m.friction_assumed / (m.friction_margin * v.gravity_mps2)


def test_at_the_squeeze_cap_just_inside_flies_and_just_outside_is_refused_naming_the_cap(robust):
    # a cap below the vehicle's own edge (two_am_robust's 18 N lies beyond its pitch reserve's edge)
    robust = with_(robust, squeeze_max_n=12.0)
    edge = cap_edge_kg(robust)
    inside = pf.preflight(with_(robust, {"mass_kg": 0.995 * edge}))
    outside = pf.preflight(with_(robust, {"mass_kg": 1.005 * edge}))
    assert inside.inside and inside.message.endswith("inside the envelope")
    assert not outside.inside
    assert f"[mission].squeeze_max_n = {robust.mission.squeeze_max_n:g} N" in outside.message
    assert f"this team of 2 holds {robust.mission.squeeze_max_n:.1f} N per pad" in outside.message
    n = outside.smallest_team
    assert n == 3 and outside.message.endswith(f"use {n} AMs")
    heavy = with_(robust, {"mass_kg": 1.005 * edge})
    assert not pf.team_check(heavy, n - 1).holds and pf.team_check(heavy, n).holds


def test_at_the_vehicles_margins_just_inside_flies_and_just_outside_names_the_margin(robust):
    uncapped = with_(robust, squeeze_max_n=math.inf)
    m = Envelope(robust.vehicle, Margins(thrust_fraction_max=robust.mission.thrust_fraction_max)).payload_kg(
        2, robust.mission.friction_assumed, robust.mission.friction_margin)
    assert pf.preflight(with_(uncapped, {"mass_kg": m - 0.01})).inside
    out = pf.preflight(with_(uncapped, {"mass_kg": m + 0.01}))
    assert not out.inside and "each AM of this team of 2 can push" in out.message
    assert any(w in out.message for w in ("yaw", "pitch", "rotor", "joint")), out.message


def _with_pad(spec, **pad):
    v = spec.vehicle
    return dataclasses.replace(spec, vehicle=dataclasses.replace(v, pad=dataclasses.replace(v.pad, **pad)))


def test_a_squeeze_that_buckles_the_grasp_is_refused_at_the_edge_both_ways(robust):
    """5 cm crowns on a 0.2 m box: the sized squeeze just under N_cr / margin flies, just over
    it is refused, naming the buckling and the crown that would not buckle."""
    from amcore.envelope import buckling_squeeze_n
    small = with_(_with_pad(robust, crown_radius_m=0.05), squeeze_max_n=math.inf, mass_tolerance=0.0)
    edge_n = pf.team_check(small, 2).buckling_n
    K = pf._envelope(small.vehicle, small.mission.thrust_fraction_max).pad_side_stiffness_n_per_m
    assert edge_n == pytest.approx(buckling_squeeze_n(0.1, 0.05, K) / Margins().buckling_margin)
    m, v = small.mission, small.vehicle
    edge_kg = edge_n * 2 * m.friction_assumed / (m.friction_margin * v.gravity_mps2)
    inside = pf.preflight(with_(small, {"mass_kg": 0.99 * edge_kg}))
    outside = pf.preflight(with_(small, {"mass_kg": 1.01 * edge_kg}))
    assert inside.inside
    assert not outside.inside and "the grasp buckles" in outside.message
    assert "crowns of radius 0.10 m or more do not buckle" in outside.message
    # the same object between the scenario's own crowns (12 cm): nothing buckles
    assert pf.team_check(with_(robust, {"mass_kg": 1.01 * edge_kg}), 2).buckling_n == math.inf
    assert pf.preflight(with_(robust, {"mass_kg": 1.01 * edge_kg})).inside


def test_the_plan_covers_the_mass_it_is_not_sure_of(robust):
    robust = with_(robust, squeeze_max_n=12.0)
    edge = cap_edge_kg(robust)
    planned = 0.95 * edge  # inside as a certain mass; outside once it may be 10 % more
    assert pf.preflight(with_(robust, planned_mass_kg=planned)).inside
    unsure = with_(robust, planned_mass_kg=planned, mass_tolerance=0.1)
    assert design_mass_kg(unsure) == pytest.approx(planned / 0.9)
    p = pf.preflight(unsure)
    assert not p.inside and "known to +/-10%" in p.message
    # the squeeze the mission flies is sized for that mass too, not for the object's true one
    model = build_model(robust.vehicle)
    assert squeeze_plan(with_(robust, planned_mass_kg=0.5, mass_tolerance=0.1), model).required_n == pytest.approx(
        robust.mission.friction_margin * 0.5 / 0.9 * 9.81 / (2 * robust.mission.friction_assumed), rel=1e-3)


def test_without_the_option_nothing_is_refused(robust):
    heavy = with_(robust, {"mass_kg": 3.0}, envelope_check=False)
    assert not pf.preflight(heavy).inside and pf.refusal(heavy) is None
    with pytest.raises(ConfigError, match="outside the team's envelope: .* use [0-9]+ AMs"):
        pf.check(with_(robust, {"mass_kg": 3.0}))


def test_the_check_is_fast_enough_for_every_trial(robust):
    pf._envelope.cache_clear()
    t0 = time.perf_counter()
    pf.preflight(with_(robust, {"mass_kg": 3.0}))  # outside: the smallest team searched too
    assert time.perf_counter() - t0 < 2.0


def _outside_file(tmp_path: Path, mission: str = "") -> Path:
    """two_am_robust with a 2.5 kg box, outside the team's envelope (an overlay of it);
    `mission`: a line for its [mission]."""
    path = tmp_path / "heavy.toml"
    path.write_text(f'base = "{ROBUST}"\n\n[object]\nmass_kg = 2.5\n' + (f"\n[mission]\n{mission}\n" if mission else ""))
    return path


def test_the_runners_refuse_before_flight_with_exit_2(tmp_path, capsys):
    from sitl import inprocess, launch

    path = _outside_file(tmp_path)
    assert inprocess.main([str(path)]) == 2
    err = capsys.readouterr().err
    n = pf.preflight(load_scenario(path)).smallest_team
    assert "2.50 kg at friction 0.5" in err and f"use {n} AMs" in err and "this team of 2 holds" in err
    t0 = time.perf_counter()
    assert launch.main([str(path), "--run-dir", str(tmp_path / "run"), "--no-telemetry", "--gcs", "none"]) == 2
    assert "outside the team's envelope" in capsys.readouterr().err
    assert time.perf_counter() - t0 < 5.0 and not (tmp_path / "run").exists()  # nothing started


@pytest.mark.parametrize("line,words", [
    ('object_pose = "gps"', "[mission].object_pose: expected one of config, mocap"),
    ("mass_tolerance = 0.7", "[mission].mass_tolerance: must be in [0, 0.5]"),
    ("mass_tolerance = -0.1", "[mission].mass_tolerance: must be in [0, 0.5]"),
    ("planned_mass_kg = -1.0", "[mission].planned_mass_kg: must be in [0.01, 100]"),
    ("envelope_check = 1", "[mission].envelope_check: expected true or false"),
])
def test_the_new_mission_keys_are_checked_naming_file_and_key(tmp_path, line, words):
    path = _outside_file(tmp_path, mission=line)
    with pytest.raises(ConfigError) as e:
        load_scenario(path)
    assert str(path) in str(e.value) and words in str(e.value)


def test_an_object_turned_past_a_full_turn_is_refused(tmp_path):
    path = _outside_file(tmp_path)
    path.write_text(path.read_text().replace("[object]\n", "[object]\nyaw_deg = 400.0\n"))
    with pytest.raises(ConfigError, match=r"\[object\].yaw_deg: must be in \[-360, 360\]"):
        load_scenario(path)
