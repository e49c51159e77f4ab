"""SitlCore: per-AM link impairment from the scenario reaches that AM's flight controller only."""
from __future__ import annotations

import dataclasses

import pytest

from amcore.config import load_scenario
from simulator.core import TRUTH_PERIOD_S, truth_every
from sitl.inprocess import run

from ..conftest import SCENARIO


def test_per_am_link_override(tmp_path):
    text = SCENARIO.read_text().replace('vehicle = "../vehicles/am3dof.toml"',
                                        f'vehicle = "{SCENARIO.parent.parent / "vehicles" / "am3dof.toml"}"')
    # 2 ms: within what the grasp tolerates even with the arm's torques on the link
    text = text.replace("sysid = 4\n", "sysid = 4\nlink = { delay_s = 0.002, loss = 0.3 }\n")
    p = tmp_path / "s.toml"
    p.write_text(text + "\n[link]\njitter_s = 0.0\n")
    spec = load_scenario(p)
    a4, a5 = spec.am(4), spec.am(5)
    assert a4.link is not None and a4.link.delay_s == 0.002 and a4.link.loss == 0.3
    assert a5.link is None and spec.link.delay_s == 0.0
    o = run(spec, duration_s=0.2)
    s4, s5 = o["fc_link"]["4"], o["fc_link"]["5"]
    assert s4["sent"] == s5["sent"] == 200 and o["rejected_setpoints"] == 0
    assert 30 < s4["lost"] < 90 and s4["delayed"] == s4["sent"] - s4["lost"]
    assert s5["lost"] == 0 and s5["delayed"] == 0


def test_setpoints_applied_on_arrival_give_the_run_of_setpoints_applied_after_the_exchange():
    """The UDP simulator applies each setpoint as it arrives (on_setpoint), the in-process
    runner after all arrived (actuate): same physics, same digest, with one AM lost a while."""
    import numpy as np

    from amlink.types import TorqueSetpoint
    from simulator.core import SitlCore

    spec = load_scenario(SCENARIO)
    digests = []
    for on_arrival in (False, True):
        core = SitlCore(spec)
        core.connect()
        try:
            m = core.model
            for k in range(300):
                lost = {5} if 100 <= k < 150 else set()
                thrust = m.mass_kg * m.gravity_mps2 * (1.0 + 0.1 * np.sin(0.05 * k))
                sps = {s: TorqueSetpoint(step=k, thrust_n=thrust, tau_B_nm=[0.0, 0.01 * np.cos(0.1 * k + s), 0.0],
                                         tau_q_nm=[0.2, 0.1, 0.01 * s]) for s in core.sysids if s not in lost}
                if on_arrival:
                    for s, _ in core.iter_frames(k):
                        pass
                    for s in reversed(core.sysids):  # arrival order differs from sysid order
                        if s in sps:
                            core.on_setpoint(s, sps[s])
                else:
                    core.frames(k)
                core.actuate(k, sps, lost)
                core.step()
            out = core.finish()
        finally:
            core.close()
        digests.append(out["state_digest"])
        assert [e["event"] for e in out["events"]] == ["lost", "rejoined"]
    assert digests[0] == digests[1]


def _attitude_spec(spec, control_rate_hz=250.0):
    import dataclasses

    v = spec.vehicle
    return dataclasses.replace(spec, control_rate_hz=control_rate_hz, vehicle=dataclasses.replace(
        v, flight_controller=dataclasses.replace(v.flight_controller, mode="attitude")))


def test_attitude_mode_flies_the_target_between_control_steps_and_ignores_torque_setpoints():
    """Attitude mode at 250 Hz: the emulated autopilot holds a level hover from one
    SET_ATTITUDE_TARGET per 4 physics steps; ground truth is still sampled at 100 Hz; a torque
    setpoint (what no stock autopilot takes) is ignored and counted."""
    import numpy as np

    from amcore.model import generalized_gravity
    from amlink.types import AttitudeSetpoint, AttitudeTarget, TorqueSetpoint
    from simulator.core import SitlCore

    spec = _attitude_spec(load_scenario(SCENARIO))
    truths = []
    core = SitlCore(spec, on_truth=truths.append)
    core.connect()
    try:
        z0 = {s: core.world.state(s).p_WB[2] for s in core.sysids}
        q0 = {s: core.world.attitude_and_rate(s)[0] for s in core.sysids}  # level, each at its own heading
        m = core.model
        hover = m.mass_kg * m.gravity_mps2 / (spec.vehicle.rotors.count * spec.vehicle.rotors.thrust_max_n)
        frames_sent = 0
        for k in range(600):
            if core.is_control_step(k):
                frames = core.frames(k)
                frames_sent += 1
                sps = {}
                for s in core.sysids:
                    g = generalized_gravity(m, m.pin_model.createData(), core.world.state(s))
                    att = AttitudeTarget(k, q0[s], [0.0, 0.0, 0.0], hover)
                    sps[s] = AttitudeSetpoint(k, att, g[6:])  # the arm holds itself up
                if k == 300:
                    sps[5] = TorqueSetpoint(k, m.mass_kg * m.gravity_mps2, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
                core.actuate(k, sps)
            else:
                core.hold(k)
            core.step()
        out = core.finish()
        for s in core.sysids:
            x = core.world.state(s)
            assert abs(x.p_WB[2] - z0[s]) < 0.05 and np.linalg.norm(x.w_B) < 0.05  # hovering, level
            assert abs(x.R_WB[2, 0]) < 0.02 and abs(x.R_WB[2, 1]) < 0.02
            assert np.allclose(core.world.attitude_and_rate(s)[0], q0[s], atol=0.02)
    finally:
        core.close()
    assert frames_sent == 150 and out["control_every"] == 4 and out["flight_controller"] == "attitude"
    assert len(truths) == 60  # every 10 physics steps, control step or not
    assert out["fc_link"]["5"]["other_mode"] == 1 and out["fc_link"]["4"]["other_mode"] == 0


def _hover(core, k):
    import numpy as np

    from amlink.types import TorqueSetpoint

    m = core.model
    return TorqueSetpoint(step=k, thrust_n=m.mass_kg * m.gravity_mps2, tau_B_nm=np.zeros(3),
                          tau_q_nm=[0.2, 0.1, 0.01])


def test_a_rejected_setpoint_holds_the_last_command_and_k_in_a_row_send_the_vehicle_to_failsafe_for_good():
    """The rejection policy of every runner (simulator.core): a refusal holds the last valid
    command (the same physics as a missed setpoint, not a failsafe); K - 1 refusals in a row
    and a valid setpoint keep the vehicle flying; the K-th in a row engages the failsafe,
    which later valid setpoints do not end."""
    from simulator.core import SitlCore

    spec = load_scenario(SCENARIO)
    K = 4
    core = SitlCore(spec, failsafe_after_rejected=K)
    core.connect()
    try:
        refuse = {5: set(range(10, 10 + K - 1)) | set(range(20, 20 + K))}  # K-1 in a row, then K in a row
        for k in range(40):
            core.frames(k)
            sps = {s: _hover(core, k) for s in core.sysids}
            for s, steps in refuse.items():
                if k in steps:
                    core.note_rejected(s, "test")
                    del sps[s]
            core.actuate(k, sps)
            if k == 10 + K - 1:
                assert not core.failsafes, "K - 1 refusals in a row must not engage the failsafe"
            if k == 20 + K - 2:
                assert 5 not in core.failsafes
            core.step()
        assert core.failsafes.keys() == {5} and core.distrusted == {5}  # still, 16 valid steps later
        out = core.finish()
    finally:
        core.close()
    assert out["rejected_setpoints"] == 2 * K - 1 and out["failsafe_after_rejected"] == K
    assert [(e["sysid"], e["event"], e["t"]) for e in out["events"]] == [(5, "rejected", 0.001 * (20 + K - 1))]
    assert out["verdict"]["failure_class"] == "rejected setpoints"


def test_failsafe_after_rejected_is_taken_from_the_scenario_and_checked():
    import pytest

    from simulator.core import SitlCore

    spec = load_scenario(SCENARIO)
    assert SitlCore(spec).failsafe_after_rejected == spec.vehicle.flight_controller.failsafe_after_rejected == 10
    for bad in (0, -1, 2.5):
        with pytest.raises(ValueError, match="failsafe_after_rejected"):
            SitlCore(spec, failsafe_after_rejected=bad)


def _attitude_hover_setpoints(core, k, q0, hover):
    from amcore.model import generalized_gravity
    from amlink.types import AttitudeSetpoint, AttitudeTarget

    m = core.model
    out = {}
    for s in core.sysids:
        g = generalized_gravity(m, m.pin_model.createData(), core.world.state(s))
        out[s] = AttitudeSetpoint(k, AttitudeTarget(k, q0[s], [0.0, 0.0, 0.0], hover + 1e-4 * k), g[6:])
    return out


def _attitude_core(COM_OF_LOSS_T=1.0):
    import dataclasses

    from simulator.core import SitlCore

    spec = _attitude_spec(load_scenario(SCENARIO))
    v = spec.vehicle
    spec = dataclasses.replace(spec, vehicle=dataclasses.replace(v, flight_controller=dataclasses.replace(
        v.flight_controller, COM_OF_LOSS_T=COM_OF_LOSS_T)))
    core = SitlCore(spec)
    core.connect()
    m = core.model
    hover = m.mass_kg * m.gravity_mps2 / (spec.vehicle.rotors.count * spec.vehicle.rotors.thrust_max_n)
    return core, {s: core.world.attitude_and_rate(s)[0] for s in core.sysids}, hover


def test_offboard_loss_fails_over_exactly_after_com_of_loss_t():
    """PX4's offboard loss: AM 5's setpoints stop reaching its flight controller after the
    control step at k = 40; the vehicle holds the last one while the silence lasts
    COM_OF_LOSS_T = 0.1 s (100 physics steps) and fails over at the first step beyond it
    (k = 141), for the rest of the run, while AM 4 keeps flying offboard."""
    core, q0, hover = _attitude_core(COM_OF_LOSS_T=0.1)
    lost_at = None
    try:
        for k in range(200):
            if core.is_control_step(k):
                core.frames(k)
                sps = _attitude_hover_setpoints(core, k, q0, hover)
                if k > 40:
                    del sps[5]
                core.actuate(k, sps)
            else:
                core.hold(k)
            if lost_at is None and 5 in core.failsafes:
                lost_at = k
            core.step()
        assert core.offboard_lost == {5} and 4 not in core.failsafes
        out = core.finish()
    finally:
        core.close()
    assert lost_at == 141
    ev = [e for e in out["events"] if e["event"] == "offboard lost"]
    assert len(ev) == 1 and ev[0]["sysid"] == 5 and abs(ev[0]["silent_s"] - 0.101) < 1e-9
    assert out["offboard_lost"] == [5]


def test_a_lossy_link_below_com_of_loss_t_never_fails_over():
    """Setpoints lost one period in two for 0.4 s: held, never failed over (COM_OF_LOSS_T = 1 s)."""
    core, q0, hover = _attitude_core()
    try:
        for k in range(400):
            if core.is_control_step(k):
                core.frames(k)
                sps = _attitude_hover_setpoints(core, k, q0, hover)
                if (k // 4) % 2:
                    del sps[5]
                core.actuate(k, sps)
            else:
                core.hold(k)
            core.step()
        assert not core.failsafes and not core.offboard_lost
    finally:
        core.close()


def test_attitude_frames_report_the_flown_target_and_the_measured_joint_torques():
    """In attitude mode every frame carries what the flight controller flies: after a setpoint
    lost on the link, the target of the one before (not the companion's latest), and the joint
    torques acting (exact without [devices]); torque-mode frames carry neither."""
    import numpy as np

    core, q0, hover = _attitude_core()
    try:
        sent = {}
        for k in range(0, 60, 4):
            frames = core.frames(k)
            if k >= 8:
                f = frames[5]
                flown = sent[k - 4] if k - 4 != 24 else sent[k - 8]  # the setpoint of k = 24 never arrived
                assert f.attitude_target.step == flown.step
                assert f.attitude_target.thrust_normalized == flown.attitude.thrust_normalized
                np.testing.assert_array_equal(f.joint_effort_nm, core.world.joint_torques(5))
                np.testing.assert_allclose(f.joint_effort_nm, flown.tau_q_nm, atol=1e-12)
            sps = _attitude_hover_setpoints(core, k, q0, hover)
            sent[k] = sps[5]
            if k == 24:  # computed, lost on the link: the flight controller keeps flying the last one
                del sps[5]
            core.actuate(k, sps)
            for j in range(4):
                if j:
                    core.hold(k + j)
                core.step()
    finally:
        core.close()
    from simulator.core import SitlCore

    torque = SitlCore(load_scenario(SCENARIO))
    torque.connect()
    try:
        f = torque.frames(0)[4]
        assert f.attitude_target is None and f.joint_effort_nm is None
    finally:
        torque.close()


def test_an_actuation_delay_makes_the_answers_act_d_steps_after_their_frames():
    """[flight_controller].actuation_delay_steps = d: the answers to control step k's frames act
    at step k + d (`due`), except step 0's, which act at once; d = 0: on arrival, never `due`."""
    import dataclasses

    from simulator.core import SitlCore

    spec = load_scenario(SCENARIO.parent / "two_am_comp_attitude.toml")
    assert spec.control_every == 4
    for d, due in ((0, []), (1, [5, 9, 13]), (3, [7, 11, 15]), (4, [8, 12, 16])):
        fc = dataclasses.replace(spec.vehicle.flight_controller, actuation_delay_steps=d)
        core = SitlCore(dataclasses.replace(spec, vehicle=dataclasses.replace(spec.vehicle, flight_controller=fc)))
        assert core.actuation_delay == d
        assert [k for k in range(17) if core.due(k)] == due


def test_with_an_actuation_delay_a_lost_companion_is_noticed_when_its_answer_is_due():
    """A companion silent from t = 0.1 to 0.3 s: its flight controller goes to failsafe and
    back as without the delay, each d physics steps later, when the answer it did not send
    would have acted."""
    import dataclasses

    spec = load_scenario(SCENARIO.parent / "two_am_comp_attitude.toml")

    def events(d: int) -> list[tuple[int, str, float]]:
        fc = dataclasses.replace(spec.vehicle.flight_controller, actuation_delay_steps=d)
        sp = dataclasses.replace(spec, vehicle=dataclasses.replace(spec.vehicle, flight_controller=fc))
        o = run(sp, duration_s=0.5, lost=lambda t: {5} if 0.1 <= t < 0.3 else set())
        return [(e["sysid"], e["event"], e["t"]) for e in o["events"]]

    plain, late = events(0), events(1)
    assert [e[:2] for e in plain] == [e[:2] for e in late] == [(5, "lost"), (5, "rejoined")]
    for (_, _, t0), (_, _, t1) in zip(plain, late):
        assert t1 - t0 == pytest.approx(spec.dt_s)


@pytest.mark.parametrize("rate_hz, substeps", [(1000.0, 1), (500.0, 1), (500.0, 2)])
def test_ground_truth_is_sampled_every_10_ms_of_simulated_time_at_any_rate(rate_hz, substeps):
    """The outcome's and telemetry's ground truth comes every TRUTH_PERIOD_S of simulated
    time, not every so many steps: a world at 500 Hz (in substeps or not) is judged on
    samples as dense as one at 1 kHz."""
    base = load_scenario(SCENARIO)
    fc = dataclasses.replace(base.vehicle.flight_controller, rate_hz=min(base.vehicle.flight_controller.rate_hz, rate_hz))
    spec = dataclasses.replace(base, rate_hz=rate_hz, physics_substeps=substeps,
                               vehicle=dataclasses.replace(base.vehicle, flight_controller=fc))
    truths = []
    run(spec, 0.2, on_truth=truths.append)
    times = [gt.time_s for gt in truths]
    assert truth_every(rate_hz) == round(TRUTH_PERIOD_S * rate_hz)
    assert len(times) == 20 and times[0] == 0.0
    assert all(b - a == pytest.approx(TRUTH_PERIOD_S) for a, b in zip(times, times[1:]))


@pytest.mark.parametrize("joints", ["servo_bus", "link"])
def test_the_link_s_delay_reaches_the_joint_torques_only_when_they_travel_on_the_link(joints):
    """[link].joints: on the companion's servo bus (the default) the arm's torques act at the
    step they were computed, while the flight controller flies the setpoint of 10 ms before;
    on the link they come as late as the rest of their setpoint."""
    import numpy as np

    from amlink.types import TorqueSetpoint
    from simulator.core import SitlCore

    base = load_scenario(SCENARIO)
    assert base.link.joints == "servo_bus"
    spec = dataclasses.replace(base, link=dataclasses.replace(base.link, delay_s=0.010, joints=joints))
    assert spec.control_every == 1 and spec.rate_hz == 1000.0
    core = SitlCore(spec)
    core.connect()
    applied = []  # (k, thrust, tau_q[2]) of AM 4
    real_apply = core.world.apply

    def recording_apply(s, thrust_n, tau_B_nm, tau_q_nm, *a, **kw):
        if s == 4:
            applied.append((k, thrust_n, float(np.asarray(tau_q_nm)[2])))
        return real_apply(s, thrust_n, tau_B_nm, tau_q_nm, *a, **kw)

    core.world.apply = recording_apply
    try:
        m = core.model
        for k in range(40):
            core.frames(k)
            sps = {s: TorqueSetpoint(step=k, thrust_n=m.mass_kg * m.gravity_mps2 + 1e-3 * k, tau_B_nm=[0.0, 0.0, 0.0],
                                     tau_q_nm=[0.0, 0.0, 1e-4 * k]) for s in core.sysids}
            core.actuate(k, sps)
            core.step()
    finally:
        core.close()
    assert [a[0] for a in applied] == list(range(10, 40))  # nothing reaches the flight controller for 10 ms
    for k, thrust, tau_q in applied:
        assert thrust == pytest.approx(m.mass_kg * m.gravity_mps2 + 1e-3 * (k - 10))
        assert tau_q == pytest.approx(1e-4 * (k if joints == "servo_bus" else k - 10))
