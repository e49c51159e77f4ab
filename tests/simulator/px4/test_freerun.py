"""simulator.freerun: drift-free pacing, the ground start, and one vehicle flown through its
commander in-process (no MAVLink client: the commander is fed as the port feeds it)."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from amcore.config import load_scenario
from amcore.mission import TAKEOFF_S
from amcore.model import build_model
from amlink.endpoint import parse_endpoint
from simulator import scene
from simulator.bullet import pb
from simulator.core import initial_state
from simulator.freerun import FreeRun, HoldJoints, Pacer, ground_start_states
from simulator.px4 import commander as cm
from simulator.px4.setpoint import from_set_attitude_target
from tests.sitl.runner import SCENARIOS

H = math.sqrt(0.5)


@pytest.fixture(scope="module")
def spec():
    return load_scenario(SCENARIOS / "two_am_comp_attitude.toml")


def test_pacer_deadlines_do_not_drift_and_misses_are_counted():
    """deadline_k = t0 + k period exactly, however late the steps start; a miss is a start
    more than one period late."""
    now = [1_000_000]
    waits = []

    def serve(timeout_s):  # a wait that oversleeps by 0.3 ms
        waits.append(timeout_s)
        now[0] += int(timeout_s * 1e9) + 300_000

    p = Pacer(lambda: now[0], 1e6 / 3.0, serve)  # 3 kHz: a period that is not a whole number of ns
    p.start()
    for k in range(3000):
        p.wait(k)
    assert p.deadline(3000) == 1_000_000 + 1_000_000_000  # exactly 1 s later: no drift
    assert p.misses == 0 and p.worst_ns <= 300_001 and p.steps == 3000
    now[0] += 5_000_000  # one step takes 5 ms: the next ones start late, back to back
    lates = [p.wait(k) for k in range(3000, 3020)]
    assert lates[0] > 4_000_000 and p.misses >= 14
    assert all(b < a for a, b in zip(lates[:15], lates[1:15]))  # catching up, one period a step


def test_ground_start_rests_the_lowest_shape_on_the_ground(spec):
    model = build_model(spec.vehicle)
    starts = ground_start_states(spec, model)
    c = pb.connect(pb.DIRECT)
    try:
        body = scene.load_am(c, spec.vehicle, friction=1.0)
        for am in spec.ams:
            x0, x = initial_state(spec, am, model), starts[am.sysid]
            assert np.allclose(x.p_WB[:2], x0.p_WB[:2]) and x.p_WB[2] < x0.p_WB[2]
            assert np.allclose(x.q, x0.q) and np.allclose(x.R_WB, x0.R_WB)
            scene.reset_am(c, body, x)
            z = min(pb.getAABB(body.body_id, link, physicsClientId=c)[0][2]
                    for link in range(-1, pb.getNumJoints(body.body_id, physicsClientId=c))
                    if pb.getCollisionShapeData(body.body_id, link, physicsClientId=c))
            assert z == pytest.approx(0.0, abs=1e-9)
    finally:
        pb.disconnect(physicsClientId=c)


def test_hold_joints_is_a_limited_pd():
    arm = HoldJoints([1.0, -2.0, 1.0], [6.0, 4.0, 2.0], (1.0, 0.4, 0.1))
    assert np.allclose(arm.joint_torques_nm([1.0, -2.0, 1.0], [0.0, 0.0, 0.0]), 0.0)
    tau = arm.joint_torques_nm([0.9, -2.0, 2.0], [0.0, 1.0, 0.0])
    assert np.allclose(tau, [20.0 * 0.1, -0.4, -2.0])  # the last one at its 2 N m limit


def test_a_vehicle_takes_off_hovers_and_fails_over(spec):
    """Vehicle 0 armed in OFFBOARD on the ground climbs on SET_ATTITUDE_TARGET-like setpoints
    (its own altitude loop on the truth, 50 Hz), the mission clock starts TAKEOFF_S after the
    engage, and when the setpoints stop the commander holds after COM_OF_LOSS_T; vehicle 1
    stays disarmed on the ground with its motors off. The clock jumps 2 ms a call: every step
    starts late (misses counted), physics as fast as it computes."""
    run = FreeRun(spec, [parse_endpoint("udpin:127.0.0.1:0")] * 2, clock=itertools.count(0, 2_000_000).__next__)
    s0, s1 = run.sysids
    c = run.vehicles[s0].commander
    hover = run.model.mass_kg * spec.vehicle.gravity_mps2 / run.thrust_scale_n
    seen = {}
    q_yaw = (H, 0.0, 0.0, H)  # NED <- FRD nose east: vehicle 0 faces +x

    def pilot() -> bool:
        w = run.core.world
        t = w.time_s
        if w.step_index % 20 == 1 and t < 5.0:
            x = w.state(s0)
            v_z = (x.R_WB @ x.v_B)[2]
            thrust = hover + 0.15 * (1.0 - x.p_WB[2]) - 0.12 * v_z
            c.offboard_setpoint(t, from_set_attitude_target(7, q_yaw, (0.0, 0.0, 0.0), thrust, (0.0, 0.0, 0.0), t))
        if w.step_index == 1:
            assert c.handle_command(t, cm.CMD_DO_SET_MODE, (1.0, 6.0, 0.0, 0, 0, 0, 0)) == cm.ACCEPTED
            assert c.handle_command(t, cm.CMD_COMPONENT_ARM_DISARM, (1.0, 0, 0, 0, 0, 0, 0)) == cm.ACCEPTED
        if abs(t - 4.9) < 1e-9:
            seen["z_hover"] = w.state(s0).p_WB[2]
            seen["nav_hover"] = c.nav_state
        if abs(t - 6.2) < 1e-9:
            seen["nav_lost"] = c.nav_state
            seen["z_lost"] = w.state(s0).p_WB[2]
        return False

    run.open()
    try:
        z1 = run.vehicles[s1].start.p_WB[2]
        result = run.run(duration_s=7.0, should_stop=pilot)
        x1 = run.core.world.state(s1)  # at rest on the ground (tipped back onto the base's edge), motors off
        assert 0.0 < x1.p_WB[2] <= z1 + 1e-6 and np.linalg.norm(x1.v_B) < 1e-3
    finally:
        run.close()
    assert seen["nav_hover"] == cm.NavState.OFFBOARD and seen["z_hover"] == pytest.approx(1.0, abs=0.1)
    assert seen["nav_lost"] == cm.NavState.AUTO_LOITER and seen["z_lost"] == pytest.approx(1.0, abs=0.15)
    v = result["vehicles"][str(s0)]
    assert v["offboard_engaged_s"] == pytest.approx(0.001)
    assert result["mission_t0_s"] == pytest.approx(0.001 + TAKEOFF_S)
    assert result["t_last_s"] == pytest.approx(7.0 - 0.001 - TAKEOFF_S, abs=0.002)  # mission time
    assert [e["event"] for e in v["events"]][:4] == ["mode request", "mode", "armed", "offboard engaged"]
    assert any(e["event"] == "failsafe" for e in v["events"])
    assert result["vehicles"][str(s1)]["armed_at_end"] is False
    assert result["timing"]["steps"] == 7000 and result["timing"]["deadline_misses"] > 0
    assert result["verdict"]["status"] in ("failed", "incomplete")


def test_flight_values_are_sensor_values_without_the_wrench(spec, make_world):
    """World.flight_values (the free-running per-step read) = sensor_values less the F/T."""
    model = build_model(spec.vehicle)
    w = make_world({am.sysid: initial_state(spec, am, model) for am in spec.ams}, spec)
    for _ in range(3):
        w.step()
    n = spec.vehicle.n_joints
    for s in w.sysids:
        assert w.flight_values(s) == w.sensor_values(s)[:13 + 2 * n]


def test_the_rate_integral_can_be_kept(spec):
    """FlightController.rate_int's setter (the free-running autopilot keeps it while landed)."""
    from amlink.types import AttitudeTarget
    from simulator.flight_controller import FlightController
    fc = FlightController(spec.vehicle.flight_controller, spec.vehicle.rotors, spec.dt_s)
    target = AttitudeTarget(0, quat_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), rates_rad_s=np.zeros(3),
                            thrust_normalized=0.4)
    for _ in range(50):
        fc.step((math.cos(0.1), 0.0, math.sin(0.1), 0.0), (0.0, 0.0, 0.0), target)  # pitched: MC_PITCHRATE_I > 0
    kept = list(fc.rate_int)
    assert any(abs(x) > 0 for x in kept)
    fc.rate_int = [0.0, 0.0, 0.0]
    assert fc.rate_int == [0.0, 0.0, 0.0]
    fc.rate_int = kept
    assert fc.rate_int == kept


def test_pacer_catches_up_at_most_max_behind_periods_then_moves_its_schedule():
    """A start later than max_behind_periods moves every later deadline by its lateness (the
    simulation runs slower, as Gazebo's does); within that bound it catches up back to back."""
    now = [0]

    def serve(timeout_s):  # an exact wait
        now[0] += max(1, int(math.ceil(timeout_s * 1e9)))

    period = 1_000_000
    p = Pacer(lambda: now[0], period, serve, max_behind_periods=10)
    p.start()
    for k in range(10):
        p.wait(k)
    now[0] += 5 * period  # a 5-period stall: caught up (the deadlines stay where they were)
    assert p.wait(10) == 4 * period and p.shifts == 0
    assert p.deadline(20) == 20 * period
    for k in range(11, 30):
        p.wait(k)
    now[0] += 50 * period  # a 50-period stall: too far to catch up; the schedule moves by it
    late = p.wait(30)
    assert late == 49 * period and p.shifts == 1 and p.shift_ns == late
    assert p.wait(31) == 0  # the next start is on its (moved) deadline, not back to back
    assert p.deadline(32) == 32 * period + late
    assert p.to_dict()["schedule_shifts"] == 1
    with pytest.raises(ValueError, match="max_behind_periods"):
        Pacer(lambda: 0, period, serve, max_behind_periods=-1)


def test_each_onboard_port_carries_its_vehicle_s_link_impairment_and_the_arm_stays_off_it(spec):
    """[link] (with an [[am]]'s own on top) impairs what reaches each autopilot; the arm's
    torques go on its own bus free-running, so joints = "link" with an impairment is refused."""
    import dataclasses

    link = dataclasses.replace(spec.link, delay_s=0.010, jitter_s=0.002)
    am1 = dataclasses.replace(spec.ams[1], link=dataclasses.replace(link, loss=0.1))
    run = FreeRun(dataclasses.replace(spec, link=link, ams=(spec.ams[0], am1)),
                  [parse_endpoint("udpin:127.0.0.1:0")] * 2)
    p0, p1 = run.ports
    assert (p0.impaired.impairment.delay_steps, p0.impaired.impairment.jitter_steps, p0.impaired.impairment.loss) == (10, 2, 0.0)
    assert p1.impaired.impairment.loss == 0.1
    assert FreeRun(spec, [parse_endpoint("udpin:127.0.0.1:0")] * 2).ports[0].impaired is None
    with pytest.raises(ValueError, match=r'joints = "link" \(sysid 4\).*own servo bus'):
        FreeRun(dataclasses.replace(spec, link=dataclasses.replace(link, joints="link")),
                [parse_endpoint("udpin:127.0.0.1:0")] * 2)
