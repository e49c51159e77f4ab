"""Task variable y, ydot = J_y V = J xi, and the drift Jdot xi against finite differences."""
from __future__ import annotations

import numpy as np
import pytest

from amcore.model import AmState, create_data, decoupled_terms
from amcore.so3 import exp_so3
from amcore.task import TaskFrame, angle_of, task_terms

from .conftest import flow, states

H = 1e-5


def _tk(model, st, frame, comps, full=False):
    d = create_data(model)
    tm = decoupled_terms(model, d, st, full=full)
    return tm, task_terms(model, d, tm, frame, comps, full=full)


@pytest.mark.parametrize("comps", [("x", "z", "pitch"), ("y", "roll", "yaw")])
def test_jacobians_and_drift_against_finite_differences(model, mission, comps):
    frame = mission.frame
    for st in states(model, seed=7):
        tm, tk = _tk(model, st, frame, comps, full=True)
        _, tp = _tk(model, flow(model, st, H), frame, comps)
        _, tn = _tk(model, flow(model, st, -H), frame, comps)
        ydot_fd = (tp.y - tn.y) / (2 * H)
        assert np.abs(tk.J_y @ tm.V - ydot_fd).max() < 1e-7
        assert np.abs(tk.J @ tm.xi - ydot_fd).max() < 1e-7
        Jdot_fd = (tp.J - tn.J) / (2 * H)
        assert np.abs(tk.Jdot - Jdot_fd).max() < 1e-7 * (1 + np.abs(Jdot_fd).max())
        ref = Jdot_fd @ tm.xi
        assert np.abs(tk.Jdot_xi - ref).max() < 1e-8 * (1 + np.abs(ref).max())
        Jydot_fd = (tp.J_y - tn.J_y) / (2 * H)
        ref = Jydot_fd @ tm.V
        assert np.abs(tk.Jdot_y_V - ref).max() < 1e-8 * (1 + np.abs(ref).max())


def test_drift_needs_the_T_inverse_Tdot_term(model, mission):
    """Dropping -J_y T^-1 Tdot V from Jdot xi gives a measurably wrong drift."""
    st = states(model, seed=11)[0]
    tm, tk = _tk(model, st, mission.frame, ("x", "z", "pitch"))
    assert np.abs(tk.J @ tm.Tdot_V).max() > 1e-2
    assert np.abs(tk.Jdot_y_V - tk.Jdot_xi).max() > 1e-2


def test_classical_not_spatial_acceleration(model, mission):
    """With Vdot = 0 the end-effector point's acceleration is J_y_dot V (classical)."""
    for st in states(model, count=4, seed=2):
        _, tk = _tk(model, st, mission.frame, ("x", "y", "z"))
        _, tp = _tk(model, flow(model, st, H), mission.frame, ("x", "y", "z"))
        _, tn = _tk(model, flow(model, st, -H), mission.frame, ("x", "y", "z"))
        acc_fd = (tp.y - 2 * tk.y + tn.y) / H**2
        assert np.abs(tk.Jdot_y_V - acc_fd).max() < 1e-3


def test_planar_angle_is_the_joint_sum_when_level(model, mission):
    q = np.array([0.9, -0.5, 0.2])
    st = AmState(np.zeros(3), mission.frame.R_WT, np.zeros(3), np.zeros(3), q, np.zeros(3))
    _, tk = _tk(model, st, mission.frame, ("x", "z", "pitch"))
    # positive joint angles turn the links down (about +y): pitch = sum(q)
    assert tk.y[2] == pytest.approx(q.sum(), abs=1e-12)
    assert angle_of(exp_so3(np.array([0, 0.3, 0])), "pitch") == pytest.approx(0.3)
    assert angle_of(exp_so3(np.array([0, 0, -0.4])), "yaw") == pytest.approx(-0.4)


def test_task_frame_turns_with_heading(model, mission):
    """Rotating the whole AM and its task frame about z leaves y unchanged."""
    st = states(model, count=1, seed=5)[0]
    _, tk = _tk(model, st, mission.frame, ("x", "z", "pitch"))
    Rz = exp_so3(np.array([0, 0, 1.1]))
    st2 = AmState(Rz @ st.p_WB, Rz @ st.R_WB, st.v_B, st.w_B, st.q, st.qdot)
    f2 = TaskFrame(Rz @ mission.frame.R_WT, Rz @ mission.frame.p_WT)
    _, tk2 = _tk(model, st2, f2, ("x", "z", "pitch"))
    assert np.abs(tk.y - tk2.y).max() < 1e-12


def test_model_pass_fills_the_kinematics_task_terms_reads(model, mission):
    """decoupled_terms leaves in `data` the frame placements, Jacobians and their time
    variation that pinocchio's dedicated passes compute (it relies on computeCoriolisMatrix)."""
    import pinocchio as pin

    pm, fid = model.pin_model, model.ee_frame_id
    for st in states(model, count=6, seed=3):
        d = create_data(model)
        decoupled_terms(model, d, st)
        ref = create_data(model)
        pin.computeJointJacobiansTimeVariation(pm, ref, st.pin_q(), st.pin_v())
        pin.updateFramePlacements(pm, ref)
        for f in (fid, model.ft_frame_id):
            assert np.abs(d.oMf[f].homogeneous - ref.oMf[f].homogeneous).max() < 1e-14
            for rf in (pin.LOCAL, pin.WORLD, pin.LOCAL_WORLD_ALIGNED):
                assert np.abs(pin.getFrameJacobian(pm, d, f, rf) - pin.getFrameJacobian(pm, ref, f, rf)).max() < 1e-14
                assert np.abs(pin.getFrameJacobianTimeVariation(pm, d, f, rf)
                              - pin.getFrameJacobianTimeVariation(pm, ref, f, rf)).max() < 1e-14


def test_mission_reference_is_the_task_frame_path_in_world(mission):
    """mission.reference evaluates the CoM path taken to {w} once; it equals p_WT + R_WT c(t)."""
    R, p = mission.frame.R_WT, mission.frame.p_WT
    for t in np.linspace(-0.5, 25.0, 203):
        ref = mission.reference(t)
        c = mission.com_path_t.eval_array(t, 4)
        y = mission.y_path.eval_array(t, 2)
        got = [ref.r_c, ref.r_c_d1, ref.r_c_d2, ref.r_c_d3, ref.r_c_d4]
        want = [p + R @ c[0]] + [R @ c[k] for k in range(1, 5)]
        for g, w in zip(got, want):
            assert np.abs(g - w).max() < 1e-14 * (1 + np.abs(w).max())
        assert np.array_equal(ref.y, y[0]) and np.array_equal(ref.y_d1, y[1]) and np.array_equal(ref.y_d2, y[2])
        assert ref.psi == mission.psi and ref.psi_d1 == 0.0 and ref.psi_d2 == 0.0
