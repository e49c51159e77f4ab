"""The in-process runner is the SITL minus sockets: same digest as the multi-process run."""
from __future__ import annotations

import pytest

from amcore.config import load_scenario
from sitl.inprocess import run

from .runner import SCENARIOS, am_run

pytestmark = pytest.mark.sitl

# attitude mode's sampling options at the law's literal form (they default to "reported", 40 Hz and
# the discretized damping in attitude mode: amcore.config.MODE_OPTION_DEFAULTS)
LITERAL_OPTIONS = '\n[options]\noffboard_inputs = "sent"\noffboard_torque_cutoff_hz = 0.0\ndiscrete_damping = false\n'


def _attitude_scenario(tmp_path, name: str, text_edit=lambda t: t, literal: bool = False):
    """An overlay of two_am_comp_attitude.toml at tmp_path/name (its [flight_controller] restated for
    `text_edit`), edited, with the literal options appended if `literal`."""
    text = f'base = "{SCENARIOS / "two_am_comp_attitude.toml"}"\n\n[flight_controller]\nmode = "attitude"\n'
    path = tmp_path / name
    path.write_text(text_edit(text) + (LITERAL_OPTIONS if literal else ""))
    return path


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


@pytest.mark.parametrize("delay", [1, 4])
def test_an_actuation_delay_is_bit_identical_in_process_and_through_the_processes(tmp_path, delay):
    """[flight_controller].actuation_delay_steps: the UDP simulator steps physics while the
    companions compute, and their setpoints act d steps after their frames; the in-process
    runner applies them at the same steps, so the two agree bit for bit, and the run differs
    from one without the delay (the delay acts). The law at its literal form, whose failure a
    whole period late is pinned below."""
    path = _attitude_scenario(tmp_path, "delayed.toml", literal=True, text_edit=lambda t: t.replace(
        'mode = "attitude"', f'mode = "attitude"\nactuation_delay_steps = {delay}', 1))
    spec = load_scenario(path)
    assert spec.vehicle.flight_controller.actuation_delay_steps == delay
    assert spec.vehicle.options.offboard_inputs == "sent" and not spec.vehicle.options.discrete_damping
    ours = run(spec, duration_s=0.4)
    plain = run(load_scenario(_attitude_scenario(tmp_path, "plain.toml", literal=True)), duration_s=0.4)
    assert ours["state_digest"] != plain["state_digest"]
    sitl = am_run(str(path), tmp_path / "r", "--duration", "0.4", "--no-telemetry", timeout_s=300)
    # a whole period late the literal attitude-mode law's joint torques diverge (docs/flight_controller.md,
    # "Actuation delay"): refusals, failsafes and the verdict must agree as well
    assert sitl.code == (4 if ours["verdict"]["status"] == "failed" else 0), sitl.stderr
    assert (ours["verdict"]["status"] == "failed") == (delay == 4)
    assert ours["steps"] == sitl.outcome["steps"] == 400
    assert ours["state_digest"] == sitl.outcome["state_digest"]
    assert ours["verdict"] == sitl.outcome["verdict"]
    assert ours["rejected_setpoints"] == sitl.outcome["rejected_setpoints"]
    assert sitl.outcome["link"]["retransmits"] == 0


@pytest.mark.parametrize("scenario,options", [
    ("two_am_comp.toml", {}),
    ("two_am_comp_attitude.toml", {}),  # attitude mode's defaults: the reports, the 40 Hz estimate
], ids=["torque", "attitude"])
def test_a_drawn_trial_is_bit_identical_in_process_and_through_the_processes(tmp_path, scenario, options):
    """A trial of the stress randomization (sensor devices and the estimator at twice their
    levels, setpoint loss, blind misalignment, start offsets, another object moved, turned and
    planned from the motion capture) written as a scenario file: `am-run` and the
    in-process runner agree bit for bit, so a campaign's rows replay through the processes.
    In attitude mode with the arm law on the autopilot's reports, those reports (ATTITUDE_TARGET,
    AM_JOINT_STATE's measured effort) travel the wire to each companion process."""
    from amcore.config import read_scenario
    from trials.cli import build_tasks
    from trials.randomize import load_randomize

    base = SCENARIOS / scenario
    data = read_scenario(base)
    data.setdefault("options", {}).update(options)
    task = build_tasks(data, base, load_randomize(SCENARIOS.parent / "randomize" / "stress.toml"), 11, 1, tmp_path,
                       None)[0]
    spec = load_scenario(task.path)
    assert spec.devices.enabled and spec.devices.ft.force_noise_n > 0  # sensor devices and the estimator
    assert spec.link.loss > 0 and spec.am(4).misalignment_deg != 0 and spec.mission.object_pose == "mocap"
    ours = run(spec, duration_s=0.4)
    sitl = am_run(task.path, tmp_path / "r", "--duration", "0.4", "--no-telemetry", timeout_s=300)
    assert sitl.code == (4 if ours["verdict"]["status"] == "failed" else 0), sitl.stderr
    assert ours["state_digest"] == sitl.outcome["state_digest"]
    assert ours["verdict"] == sitl.outcome["verdict"]


def test_a_failed_mission_makes_am_run_say_so_and_exit_4(tmp_path):
    """A vehicle started turned 20 deg away from its heading saturates its rotors fighting
    back: the verdict names it and am-run exits 4."""
    text = (f'base = "{SCENARIOS / "two_am_short.toml"}"\n\n'  # [[am]] replaces the base's whole team
            "[[am]]\nsysid = 4\nazimuth_deg = 180.0\nstart_heading_deg = 20.0\n\n[[am]]\nsysid = 5\nazimuth_deg = 0.0\n")
    path = tmp_path / "turned.toml"
    path.write_text(text)
    r = am_run(str(path), tmp_path / "r", "--duration", "1.0", "--no-telemetry", timeout_s=300)
    assert r.code == 4, r.stderr
    assert "verdict: mission FAILED: am4's actuators saturated on" in r.stderr
    assert r.outcome["verdict"]["failure_class"] == "saturated" and r.outcome["exit_code"] == 4
    assert run(load_scenario(path), duration_s=1.0)["verdict"] == r.outcome["verdict"]


def test_baseline_flies_the_approach_through_the_same_runner():
    """two_am_baseline ([options] controller = "baseline") in the in-process SITL: through the
    approach (free flight in PyBullet, the CoM reference moves ~0.3 m) each AM's CoM tracks the
    mission's reference within 5 mm throughout and ends on it with the pad on y_d, with no
    actuator saturation."""
    spec = load_scenario(SCENARIOS / "two_am_baseline.toml")
    out = run(spec, duration_s=spec.mission.approach_end_s + 0.01)
    for sysid, c in out["companions"].items():
        a = c["at"]["approach_end"]
        assert c["phases"]["approach"]["max"]["r_c_err"] < 5e-3
        assert a["r_c_err"] < 1e-3 and a["e_R"] < 0.01
        assert max(abs(e) for e in a["y_err"]) < 5e-3
        assert out["ams"][str(sysid)]["saturated_steps"] == 0
        assert out["ams"][str(sysid)]["base_contacts"] == []
def test_baseline_squeezes_two_am_robusts_object_with_the_planned_force():
    """two_am_robust flown by the baseline (hex3dof's [baseline]: the impedance at the pad and the
    reaction feed-forward) in the in-process SITL: at the end of the grasp each pad presses the
    object with the squeeze sizing's planned force (within 2 %, PyBullet's contact), not the
    fixed K_y,x squeeze_m, and no base touches anything."""
    from amcore.config import read_scenario, scenario_from_dict
    from amcore.mission import squeeze_plan
    from amcore.model import build_model
    from trials.cli import apply_overrides

    path = SCENARIOS / "two_am_robust.toml"
    spec = scenario_from_dict(apply_overrides(read_scenario(path), ['options.controller="baseline"']), path)
    plan = squeeze_plan(spec, build_model(spec.vehicle))
    assert plan.force_n > spec.vehicle.gains.K_y[0] * spec.mission.squeeze_m + 1.0
    normal: dict[int, list[float]] = {}

    def on_truth(gt):
        if gt.time_s >= spec.mission.grasp_end_s - 1.0:
            for s, am in gt.ams.items():
                normal.setdefault(s, []).append(am.pad_object_contact.normal_force_n)

    out = run(spec, duration_s=spec.mission.grasp_end_s, on_truth=on_truth)
    assert sorted(normal) == [4, 5]
    for s, n in normal.items():
        assert sum(n) / len(n) == pytest.approx(plan.force_n, rel=0.02)
        assert out["ams"][str(s)]["base_contacts"] == []


@pytest.mark.parametrize("literal", [False, True], ids=["defaults", "literal"])
def test_attitude_mode_in_process_run_is_bit_identical_to_the_multi_process_one(tmp_path, literal):
    """Attitude mode at 250 Hz: the lockstep exchanges on control steps only, the emulated
    autopilot flies between them; SET_ATTITUDE_TARGET's float32 rounding is the same in both.
    With its default options and with the law's literal form ("sent", 0, false), which still
    flies (no refusal, no failsafe) and is another run (the options act)."""
    path = _attitude_scenario(tmp_path, "attitude.toml", literal=literal)
    spec = load_scenario(path)
    assert spec.vehicle.options.discrete_damping is not literal
    ours = run(spec, duration_s=0.4)
    sitl = am_run(str(path), tmp_path / "r", "--duration", "0.4", "--no-telemetry", timeout_s=300)
    assert sitl.code == 0, sitl.stderr
    assert ours["steps"] == sitl.outcome["steps"] == 400
    assert ours["flight_controller"] == sitl.outcome["flight_controller"] == "attitude"
    assert ours["fc_link"]["4"]["sent"] == sitl.outcome["fc_link"]["4"]["sent"] == 100  # one setpoint per 4 steps
    assert ours["state_digest"] == sitl.outcome["state_digest"]
    assert ours["rejected_setpoints"] == sitl.outcome["rejected_setpoints"] == 0 and ours["events"] == []
    other = run(load_scenario(_attitude_scenario(tmp_path, "other.toml", literal=not literal)), duration_s=0.4)
    assert other["state_digest"] != ours["state_digest"]


def test_a_world_in_physics_substeps_is_bit_identical_in_process_and_through_the_processes(tmp_path):
    """The screening campaign's world ([scenario].rate_hz = 500 in two PyBullet substeps, the
    autopilot at 500 Hz): both runners step it alike, and the substeps act (another run than
    the same world at 500 Hz in one step)."""
    path = tmp_path / "substeps.toml"
    path.write_text(f'base = "{SCENARIOS / "two_am_comp_attitude.toml"}"\n\n[scenario]\nrate_hz = 500.0\n'
                    "physics_substeps = 2\n\n[flight_controller]\nrate_hz = 500.0\n")
    spec = load_scenario(path)
    assert (spec.rate_hz, spec.physics_substeps, spec.vehicle.flight_controller.rate_hz) == (500.0, 2, 500.0)
    ours = run(spec, duration_s=0.4)
    sitl = am_run(str(path), tmp_path / "r", "--duration", "0.4", "--no-telemetry", timeout_s=300)
    assert sitl.code == 0, sitl.stderr
    assert ours["steps"] == sitl.outcome["steps"] == 200
    assert ours["state_digest"] == sitl.outcome["state_digest"]
    one_step = tmp_path / "one_step.toml"
    one_step.write_text(path.read_text().replace("physics_substeps = 2", "physics_substeps = 1", 1))
    plain = run(load_scenario(one_step), duration_s=0.4)
    assert plain["steps"] == 200 and plain["state_digest"] != ours["state_digest"]


def test_rejected_setpoints_are_answered_at_once_and_the_run_stays_deterministic(tmp_path):
    """8 ms of sensor latency makes the controllers' joint torques implausible from t = 0.16 s:
    each refusal is answered at once (the flight controller holds the last valid command), K in
    a row send the vehicle to failsafe, and no step waits for --step-timeout (5 s). Two am-run
    runs and the in-process run agree on digest, events and verdict."""
    text = f'base = "{SCENARIOS / "two_am_short.toml"}"\n'
    path = tmp_path / "late.toml"
    path.write_text(text + "\n[sensors]\nlatency_s = 0.008\n")
    ours = run(load_scenario(path), duration_s=0.6)
    assert ours["rejected_setpoints"] > 10 and ours["verdict"]["failure_class"] == "rejected setpoints"
    K = ours["failsafe_after_rejected"]
    assert [(e["event"], e["in_a_row"]) for e in ours["events"]] == [("rejected", K)] * 2
    outcomes = []
    for i in range(2):
        r = am_run(str(path), tmp_path / f"r{i}", "--duration", "0.6", "--no-telemetry", timeout_s=300)
        assert r.code == 4, r.stderr
        o = r.outcome
        assert o["link"]["peers_lost"] == 0 and o["link"]["rejected_setpoints"] == o["rejected_setpoints"]
        assert o["wall_s"] < 5.0, o["wall_s"]  # one stall for the step timeout would take 5 s
        outcomes.append(o)
    for o in outcomes:
        assert o["state_digest"] == ours["state_digest"]
        assert o["verdict"] == ours["verdict"] and o["events"] == ours["events"]
        assert o["rejected_setpoints"] == ours["rejected_setpoints"] and o["distrusted"] == ours["distrusted"] == [4, 5]


def test_a_deployment_trial_plans_from_the_same_measured_object_in_process_and_through_the_processes(tmp_path):
    """A trial of the default randomization (the deployment) on two_am_robust (the object moved and turned on its
    table, measured by motion capture, [mission].object_pose = "mocap"): the simulator sends its
    measurement in the handshake (AM_OBJECT_POSE), each companion plans from it, and `am-run`
    agrees with the in-process runner bit for bit."""
    from amcore.config import read_scenario
    from amcore.mission import config_object_pose
    from amcore.preflight import preflight
    from simulator.object_mocap import measure_object
    from trials.cli import build_tasks
    from trials.randomize import load_randomize

    base = SCENARIOS / "two_am_robust.toml"
    rand = load_randomize(SCENARIOS.parent / "randomize" / "default.toml")
    tasks = build_tasks(read_scenario(base), base, rand, 23, 6, tmp_path, None)
    task = next(t for t in tasks if preflight(load_scenario(t.path)).inside)  # a draw the team flies
    spec = load_scenario(task.path)
    measured, truth = measure_object(spec), config_object_pose(spec)
    assert spec.object.yaw_deg != 0.0 and measured != truth  # turned, and measured with an error
    ours = run(spec, duration_s=0.4)
    sitl = am_run(task.path, tmp_path / "r", "--duration", "0.4", "--no-telemetry", timeout_s=300)
    assert sitl.code == (4 if ours["verdict"]["status"] == "failed" else 0), sitl.stderr
    assert ours["state_digest"] == sitl.outcome["state_digest"]
