"""The paper's three scenarios, each run end to end through the console scripts (simulator +
one companion process per AM over MAVLink/UDP), checked against the simulator's ground truth
and the companions' own error reports (issue 3, 'What the runs must show')."""
from __future__ import annotations

import numpy as np
import pytest

from amcore.config import load_scenario

from .runner import SCENARIOS, am_run

pytestmark = pytest.mark.sitl


def _check_clean(run):
    assert run.code == 0, run.stderr[-3000:]
    assert run.outcome["status"] == "run complete"
    for sysid, a in run.outcome["ams"].items():
        assert a["base_contacts"] == [], f"AM {sysid}'s base hit {a['base_contacts']}"
    for sysid, c in run.companions.items():
        assert c["error"] is None, c["error"]


@pytest.fixture(scope="module")
def comp(tmp_path_factory):
    return am_run("two_am_comp.toml", tmp_path_factory.mktemp("comp"))


@pytest.fixture(scope="module")
def nocomp(tmp_path_factory):
    return am_run("two_am_nocomp.toml", tmp_path_factory.mktemp("nocomp"))


@pytest.fixture(scope="module")
def ten(tmp_path_factory):
    return am_run("ten_am.toml", tmp_path_factory.mktemp("ten"))


def test_two_am_comp_runs_to_completion_without_crash(comp):
    _check_clean(comp)
    assert sorted(comp.companions) == [4, 5]
    assert comp.outcome["steps"] == 20000


def test_two_am_comp_free_flight_converged_at_t5(comp):
    for c in comp.companions.values():
        a = c["at"]["approach_end"]
        assert abs(a["t"] - 5.0) < 1e-3
        assert a["r_c_err"] < 5e-3
        assert a["e_R"] < 0.01
        assert max(abs(a["y_err"][0]), abs(a["y_err"][1])) < 5e-3 and abs(a["y_err"][2]) < 0.01


def test_two_am_comp_object_lifted_and_held_without_slip(comp):
    obj = comp.outcome["object"]
    assert obj["hover_min_lift_m"] >= 0.2
    assert obj["touching_in_hover"] == []
    for a in comp.outcome["ams"].values():
        assert a["slip_max_m"] < 2e-3


def test_two_am_comp_each_am_carries_its_share(comp):
    spec = load_scenario(SCENARIOS / "two_am_comp.toml")
    share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
    for a in comp.outcome["ams"].values():
        up = -a["hover_mean_ft_force_W_n"][2]  # the F/T reading is the force ON the pad: the load pulls down
        assert up == pytest.approx(share, rel=0.02)


def test_two_am_comp_errors_return_to_zero_while_the_squeeze_holds_y_offset(comp):
    spec = load_scenario(SCENARIOS / "two_am_comp.toml")
    K_x = spec.vehicle.gains.K_y[0]
    for sysid, c in comp.companions.items():
        end = c["at"]["end"]
        assert end["t"] > 19.9
        assert end["r_c_err"] < 5e-3
        assert end["e_R"] < 0.01
        # eq. desired_task_behavior at rest: K_y y~ = F_y; along x, F_y is minus the squeeze
        normal = comp.outcome["ams"][str(sysid)]["hover_mean_normal_force_n"]
        assert normal > 5.0
        assert end["y_err"][0] == pytest.approx(-normal / K_x, rel=0.05)


def test_two_am_nocomp_grasp_holds_with_bounded_nonzero_offsets(nocomp):
    _check_clean(nocomp)
    obj = nocomp.outcome["object"]
    assert obj["hover_min_lift_m"] >= 0.15
    assert obj["touching_in_hover"] == []
    for c in nocomp.companions.values():
        end, before = c["at"]["end"], c["at"]["settle_check"]
        # bounded, not zero: nothing compensates the squeeze, the CoM spring takes it (9 N / K_t)
        assert 0.05 < end["r_c_err"] < 0.3
        # the attitude offset stays small here (the contact moment on the decoupled attitude
        # coordinates is small for this arm), but bounded: no saturation, no tumbling
        assert end["e_R"] < 0.05
        # settled: the offsets no longer change over the last two seconds
        assert end["r_c_err"] == pytest.approx(before["r_c_err"], rel=0.05)
        assert abs(end["e_R"] - before["e_R"]) < 1e-3
    for a in nocomp.outcome["ams"].values():
        assert a["saturated_steps"] == 0


def test_two_am_compensation_reduces_the_offsets(comp, nocomp):
    for s in (4, 5):
        assert comp.companions[s]["at"]["end"]["r_c_err"] < 0.1 * nocomp.companions[s]["at"]["end"]["r_c_err"]


def test_ten_am_lift_a_5kg_cylinder_each_carrying_a_tenth(ten):
    _check_clean(ten)
    spec = load_scenario(SCENARIOS / "ten_am.toml")
    share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
    obj = ten.outcome["object"]
    assert obj["hover_min_lift_m"] >= 0.2
    assert obj["touching_in_hover"] == []
    ups = np.array([-a["hover_mean_ft_force_W_n"][2] for a in ten.outcome["ams"].values()])
    assert len(ups) == 10
    np.testing.assert_allclose(ups, share, rtol=0.05)


def test_ten_am_log_holds_every_controller_sample_at_full_rate(ten):
    """Issue 4: ten AMs at 1 kHz each recorded without loss (or the loss is stated)."""
    import json
    import subprocess

    from .runner import script

    r = subprocess.run([script("ground-station"), "review", str(ten.run_dir / "run.mcap"), "--json"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    rv = json.loads(r.stdout)
    assert rv["loss"]["missing"] == 0, rv["loss"]
    for s in range(2, 12):
        assert sum(rv["phases"][p]["ams"][str(s)]["samples"] for p in ("approach", "grasp", "hover")) == 20000


def test_two_am_comp_log_holds_the_topic_contract_and_agrees_with_ground_truth(comp):
    """Issue 4 round trip on a real run: every documented topic in the MCAP, nothing lost in
    transit at 1 kHz per AM, and the review's contact forces and lift match the simulator's."""
    import json
    import subprocess

    from ground_station.mcap_io import read_log

    from .runner import script

    mcap = comp.run_dir / "run.mcap"
    log = read_log(mcap)
    for topic, schema in [("/sim/object/pose", "foxglove.PoseInFrame"), ("/am/4/controller", "amstack/ControllerState"),
                          ("/am/5/controller", "amstack/ControllerState"), ("/sim/am/4/contact", "amstack/PadContact"),
                          ("/tf", "foxglove.FrameTransforms"), ("/scene", "foxglove.SceneUpdate"),
                          ("/events", "foxglove.Log")]:
        assert log.channels.get(topic) == schema, (topic, log.channels.get(topic))
        assert log.encodings[topic] == ("protobuf" if schema.startswith("foxglove.") else "ros1"), topic
        times = [ns for ns, _ in log.messages[topic]]
        assert times and all(b >= a for a, b in zip(times, times[1:])), topic  # simulation time, monotonic
    r = subprocess.run([script("ground-station"), "review", str(mcap), "--json"], capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    rv = json.loads(r.stdout)
    assert rv["log"]["salvaged"] is False
    assert rv["loss"]["missing"] == 0
    hover = rv["phases"]["hover"]
    assert hover["ams"]["4"]["samples"] == 10000  # every controller sample of the phase, 1 kHz
    assert hover["object_lift_m"]["final"] == pytest.approx(comp.outcome["object"]["final_lift_m"], abs=2e-3)
    for s in ("4", "5"):
        normal_log = hover["ams"][s]["contact_normal_n"]["final"]
        assert normal_log == pytest.approx(comp.outcome["ams"][s]["hover_mean_normal_force_n"], rel=0.01)
        assert hover["ee_slip_m"][s]["max"] < 2e-3
    assert (comp.run_dir / "plots").is_dir() and any((comp.run_dir / "plots").glob("*.png"))


# -- attitude mode: the same scenarios through an emulated stock autopilot, rotors lagging ------
ATTITUDE = {"two_am_comp_attitude.toml": 0.02, "two_am_nocomp_attitude.toml": 0.02, "ten_am_attitude.toml": 0.05}


@pytest.fixture(scope="module", params=sorted(ATTITUDE))
def attitude_run(request, tmp_path_factory):
    extra = ("--no-telemetry",) if request.param.startswith("ten") else ()  # ten AMs: the lighter run (the torque twin logs)
    return request.param, am_run(request.param, tmp_path_factory.mktemp(request.param.split(".")[0]), *extra)


def test_attitude_mode_scenario_passes_its_torque_mode_twins_ground_truth_checks(attitude_run):
    """Issue 13: lift at least 0.2 m, slip under 2 mm, each AM carrying m g / N within 2 %
    (5 % for ten AMs), here with SET_ATTITUDE_TARGET to an emulated PX4 and lagging rotors."""
    name, run = attitude_run
    _check_clean(run)
    spec = load_scenario(SCENARIOS / name)
    assert spec.vehicle.flight_controller.mode == "attitude" and spec.vehicle.rotors.time_constant_s > 0
    assert run.outcome["flight_controller"] == "attitude" and run.outcome["control_every"] == spec.control_every
    assert run.outcome["steps"] == 20000
    assert all(link["other_mode"] == 0 for link in run.outcome["fc_link"].values())
    for c in run.companions.values():  # free flight converged, as in torque mode
        a = c["at"]["approach_end"]
        assert abs(a["t"] - 5.0) < 1e-3 and a["r_c_err"] < 5e-3 and a["e_R"] < 0.01
    obj = run.outcome["object"]
    assert obj["hover_min_lift_m"] >= 0.2
    assert obj["touching_in_hover"] == []
    share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
    ups = np.array([-a["hover_mean_ft_force_W_n"][2] for a in run.outcome["ams"].values()])
    assert len(ups) == len(spec.ams)
    np.testing.assert_allclose(ups, share, rtol=ATTITUDE[name])
    for a in run.outcome["ams"].values():
        assert a["slip_max_m"] < 2e-3
