"""The baseline's two options beyond the first write-up (amcore.baseline, [baseline].arm and
reaction_feedforward), on the canted hexarotor of two_am_robust: the impedance at the pad
squeezes with the mission's planned force whatever the base's pitch, the feed-forward adds
exactly the arm's last wrench to the base, and both default to the first write-up's law."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest

from amcore import baseline as bl
from amcore.attitude import desired_attitude
from amcore.config import load_scenario, read_scenario, scenario_from_dict
from amcore.control import Reference
from amcore.mission import am_mission, squeeze_plan
from amcore.model import AmState, build_model, create_data
from trials.cli import apply_overrides

from ..conftest import ROOT

ROBUST = ROOT / "configs" / "scenarios" / "two_am_robust.toml"
G = 9.81


@pytest.fixture(scope="module")
def hex_spec():
    return scenario_from_dict(apply_overrides(read_scenario(ROBUST), ['options.controller="baseline"']), ROBUST)


@pytest.fixture(scope="module")
def hex_model(hex_spec):
    return build_model(hex_spec.vehicle)


@pytest.fixture(scope="module")
def hex_mission(hex_spec, hex_model):
    return am_mission(hex_spec, hex_spec.ams[0], hex_model)


def _params(spec, model, mission, **change) -> bl.BaselineParams:
    return dataclasses.replace(bl.BaselineParams.from_vehicle(spec.vehicle, model, mission.frame), **change)


def _grasp_state(model, data, params, mission, t: float, short_m: float, tilt_acc: float):
    """The base exactly on its reference at t, pitched in the arm's plane by a horizontal
    reference acceleration tilt_acc [m/s^2] along the task x axis, at rest; the arm at the
    pose that puts the pad short_m [m] short of y_d along the task x axis (on the object's
    face: the grasp's depth), seen from there."""
    r = mission.reference(t)
    fr = mission.frame
    ref = Reference(r.r_c, np.zeros(3), fr.R_WT @ np.array([tilt_acc, 0.0, 0.0]), np.zeros(3), np.zeros(3),
                    r.psi, 0.0, 0.0, r.y, np.zeros(3), np.zeros(3))
    p_d = bl.base_reference(params, ref)[0]
    b1 = np.array([math.cos(ref.psi), math.sin(ref.psi), 0.0])
    R_d, _, _ = desired_attitude(model.mass_kg * (ref.r_c_d2 + [0, 0, G]), np.zeros(3), np.zeros(3), b1,
                                 np.zeros(3), np.zeros(3))
    y_pad = np.array(ref.y)
    y_pad[0] -= short_m
    target = bl.ik_target(params, p_d, R_d, y_pad)
    q, _ = bl.inverse_kinematics(model, data, target, np.array(model.vehicle.q_nominal_rad), 200, 1e-3,
                                 params.q_min, params.q_max)
    np.testing.assert_allclose(bl.planar_fk(model, data, q)[0], target, atol=1e-9)
    x = AmState(p_WB=p_d, R_WB=R_d, v_B=np.zeros(3), w_B=np.zeros(3), q=q, qdot=np.zeros(model.n))
    return x, ref, R_d


def _pad_wrench(model, res, x) -> np.ndarray:
    """The (x, z, pitch) wrench in {b} that the arm's torque less gravity holds at the pad:
    J^-T (tau_q - g_q), at rest."""
    g = pin.computeGeneralizedGravity(model.pin_model, create_data(model), x.pin_q())[6:]
    _, J = bl.planar_fk(model, create_data(model), x.q)
    return np.linalg.solve(J.T, np.asarray(res.command.tau_q_nm) - g)


@pytest.mark.parametrize("tilt_acc", [0.0, 4.0])
def test_cartesian_arm_squeezes_with_the_planned_force_at_the_grasp_pose(hex_spec, hex_model, hex_mission, tilt_acc):
    """With the pad held on the face and the base on its reference, the impedance at the pad
    pushes along the task frame's x axis with the squeeze sizing's force (above the fixed
    K_y,x squeeze_m), no vertical force and no moment on the pad, for a level and for a pitched
    base (where a stiffness along the body axes would push askew)."""
    model, data = hex_model, create_data(hex_model)
    plan = squeeze_plan(hex_spec, model)
    k_x = hex_spec.vehicle.gains.K_y[0]
    assert plan.force_n > k_x * hex_spec.mission.squeeze_m + 1.0  # the sizing really acts
    p = _params(hex_spec, model, hex_mission, arm="cartesian", K_y=np.array(hex_spec.vehicle.gains.K_y),
                D_y=np.array(hex_spec.vehicle.gains.D_y), reaction_feedforward=False)
    x, ref, R_d = _grasp_state(model, data, p, hex_mission, 9.0, plan.depth_m, tilt_acc)
    res = bl.step(model, data, p, x, ref, np.zeros(6), bl.BaselineMemory(), 9.0)
    np.testing.assert_allclose(res.diagnostics.R_d, R_d, atol=1e-12)
    w = _pad_wrench(model, res, x)
    f_task = bl.body_to_task_xz(hex_mission.frame, R_d) @ w[0:2]
    np.testing.assert_allclose(f_task, [plan.force_n, 0.0], atol=1e-6)
    assert abs(w[2]) < 1e-8
    if tilt_acc:
        assert abs(w[1]) > 1.0  # seen from the pitched base the push is not along its x axis


def test_cartesian_arm_on_its_reference_holds_only_gravity(hex_spec, hex_model, hex_mission):
    """Pad on y_d, arm at rest: the torque is the arm's gravity, nothing else."""
    model, data = hex_model, create_data(hex_model)
    p = _params(hex_spec, model, hex_mission, arm="cartesian", K_y=np.array([300.0, 300.0, 1.5]),
                D_y=np.array([14.0, 14.0, 0.03]))
    x, ref, _ = _grasp_state(model, data, p, hex_mission, 9.0, 0.0, 2.0)
    res = bl.step(model, data, p, x, ref, np.zeros(6), bl.BaselineMemory(), 9.0)
    np.testing.assert_allclose(_pad_wrench(model, res, x), 0.0, atol=1e-7)


def test_cartesian_damping_opposes_the_pads_velocity(hex_spec, hex_model, hex_mission):
    """On the reference, a joint velocity gives the wrench -A^T D A J qdot (translation) and
    -D_pitch (J qdot)_pitch: power J qdot . w < 0."""
    model, data = hex_model, create_data(hex_model)
    D = np.array([14.0, 20.0, 0.03])
    p = _params(hex_spec, model, hex_mission, arm="cartesian", K_y=np.array([300.0, 300.0, 1.5]), D_y=D)
    x, ref, R_d = _grasp_state(model, data, p, hex_mission, 9.0, 0.0, 3.0)
    qdot = np.array([0.4, -0.3, 0.8])
    xs = AmState(x.p_WB, x.R_WB, x.v_B, x.w_B, x.q, qdot)
    res = bl.step(model, data, p, xs, ref, np.zeros(6), bl.BaselineMemory(), 9.0)
    g = pin.computeGeneralizedGravity(model.pin_model, create_data(model), x.pin_q())[6:]
    _, J = bl.planar_fk(model, create_data(model), x.q)
    w = np.linalg.solve(J.T, np.asarray(res.command.tau_q_nm) - g)
    v = J @ qdot
    A = bl.body_to_task_xz(hex_mission.frame, R_d)
    np.testing.assert_allclose(w[0:2], -A.T @ (D[0:2] * (A @ v[0:2])), atol=1e-9)
    assert w[2] == pytest.approx(-D[2] * v[2], abs=1e-12)
    assert v @ w < 0.0


def test_reaction_feedforward_adds_the_arms_last_wrench_to_the_base(hex_spec, hex_model, hex_mission):
    """With the feed-forward, F_d is F_d without it plus R f, and the body torque is that of the
    law without it flying the same F_d plus p_BE x f + m, (f, m) the pad wrench the last step
    left in memory; the memory then holds the spring wrench this step's arm commands."""
    model, data = hex_model, create_data(hex_model)
    on = _params(hex_spec, model, hex_mission, arm="cartesian", K_y=np.array([300.0, 300.0, 1.5]),
                 D_y=np.array([14.0, 14.0, 0.03]), reaction_feedforward=True)
    off = dataclasses.replace(on, reaction_feedforward=False)
    x, ref, _ = _grasp_state(model, data, on, hex_mission, 9.0, squeeze_plan(hex_spec, model).depth_m, 3.0)
    w_last = (6.0, -2.5, 0.04)
    f_b = np.array([w_last[0], 0.0, w_last[1]])
    mem = bl.BaselineMemory(w_arm=w_last)
    r_on = bl.step(model, data, on, x, ref, np.zeros(6), mem, 9.0)
    r_off = bl.step(model, data, off, x, ref, np.zeros(6), mem, 9.0)
    np.testing.assert_allclose(r_on.diagnostics.f_d - r_off.diagnostics.f_d, x.R_WB @ f_b, atol=1e-9)
    # the law without the feed-forward asked for the same F_d (through the reference's acceleration)
    same = ref._replace(r_c_d2=ref.r_c_d2 + x.R_WB @ f_b / model.mass_kg)
    r_same = bl.step(model, data, off, x, same, np.zeros(6), mem, 9.0)
    np.testing.assert_allclose(r_same.diagnostics.f_d, r_on.diagnostics.f_d, atol=1e-9)
    np.testing.assert_allclose(r_same.diagnostics.R_d, r_on.diagnostics.R_d, atol=1e-12)
    assert r_on.command.thrust_n == pytest.approx(r_same.command.thrust_n, rel=1e-12)
    bl.planar_fk(model, data, x.q)
    pad = data.oMf[model.ee_frame_id].translation.copy()  # the pad in {b}
    wrench_at_base = pin.SE3(np.eye(3), pad).act(pin.Force(f_b, np.array([0.0, w_last[2], 0.0])))
    moment = np.asarray(r_on.command.tau_B_nm) - np.asarray(r_same.command.tau_B_nm)
    np.testing.assert_allclose(moment, wrench_at_base.angular, atol=1e-9)
    assert abs(moment[1]) > 0.1
    # memory: the spring wrench this step commands, J^-T of its spring torque
    g = pin.computeGeneralizedGravity(model.pin_model, create_data(model), x.pin_q())[6:]
    _, J = bl.planar_fk(model, create_data(model), x.q)
    spring = np.asarray(r_on.command.tau_q_nm) - g  # at rest, all of tau_q - g is the spring's
    np.testing.assert_allclose(r_on.memory.w_arm, np.linalg.solve(J.T, spring), atol=1e-9)
    assert np.linalg.norm(r_on.memory.w_arm) > 1.0
    assert r_off.memory.w_arm == w_last  # off: carried, never used


def test_defaults_are_the_first_write_ups_law(spec, model, mission):
    """The paper's quadrotor keeps the joint PD without feed-forward (its [baseline] names
    neither option)."""
    p = bl.BaselineParams.from_vehicle(load_scenario(ROOT / "configs" / "scenarios" / "two_am_baseline.toml").vehicle,
                                       model, mission.frame)
    assert p.arm == "joint" and not p.reaction_feedforward and p.K_y is None


def test_the_feed_forward_needs_the_cartesian_arm(hex_spec, hex_model, hex_mission):
    """Fed forward, the joint PD's wrench closes a loop through R_d (measured: diverged): refused."""
    p = _params(hex_spec, hex_model, hex_mission, arm="cartesian", K_y=np.ones(3), D_y=np.ones(3),
                reaction_feedforward=False)
    with pytest.raises(ValueError, match="reaction_feedforward needs arm = 'cartesian'"):
        dataclasses.replace(p, arm="joint", reaction_feedforward=True)
    with pytest.raises(ValueError, match="needs K_y and D_y"):
        dataclasses.replace(p, K_y=None)
