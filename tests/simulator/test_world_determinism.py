"""Same inputs give the same run; commands persist; the world's bookkeeping."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from .sim_testing import at_rest, facing_object


def snapshot(w) -> list[np.ndarray]:
    out = []
    for s in w.sysids:
        x = w.state(s)
        out += [x.p_WB, x.R_WB, x.v_B, x.w_B, x.q, x.qdot, w.wrench_ee(s)]
        c = w.ground_truth().ams[s].pad_object_contact
        out += [np.array([c.normal_force_n]), c.tangential_force_W]
    o = w.ground_truth().object
    return out + [o.p_WO, o.quat_WO_wxyz, o.v_WO, o.w_WO]


def test_same_inputs_give_bit_identical_runs(spec, model, make_world):
    """Two worlds in one process (separate clients), stepped alternately, with pads
    touching the box and random commands around hover: every number must agree exactly."""
    initial = facing_object(spec, model, depth_m=0.003)
    a, b = make_world(initial), make_world(initial)
    rng = np.random.default_rng(spec.seed)
    T_hover = pin.computeTotalMass(model.pin_model) * spec.vehicle.gravity_mps2
    touched = False
    for _ in range(500):
        for s in spec.ams:
            T = T_hover + rng.normal(0.0, 1.0)
            tau_B = rng.normal(0.0, 0.05, 3)
            tau_q = rng.normal(0.0, 0.2, 3)
            ra = a.apply(s.sysid, T, tau_B, tau_q)
            rb = b.apply(s.sysid, T, tau_B, tau_q)
            np.testing.assert_array_equal(ra.mix.rotor_thrusts_n, rb.mix.rotor_thrusts_n)
        a.step()
        b.step()
        touched |= any(a.ground_truth().ams[s].pad_object_contact.n_points > 0 for s in a.sysids)
        for xa, xb in zip(snapshot(a), snapshot(b)):
            np.testing.assert_array_equal(xa, xb)
    assert touched
    assert a.step_index == b.step_index == 500


def test_commands_persist_until_replaced(spec, model, make_world):
    q_hang = [np.pi / 2, 0.0, 0.0]
    initial = {a.sysid: at_rest([-2.0 + 4.0 * i, 0.0, 3.0], np.eye(3), q_hang) for i, a in enumerate(spec.ams)}
    w = make_world(initial)
    held, dropped = spec.ams[0].sysid, spec.ams[1].sysid
    w.apply(held, pin.computeTotalMass(model.pin_model) * spec.vehicle.gravity_mps2, np.zeros(3), np.zeros(3))
    for _ in range(200):
        w.step()
    assert np.linalg.norm(w.state(held).v_B) < 1e-6
    assert w.state(dropped).v_B[2] == pytest.approx(-spec.vehicle.gravity_mps2 * w.time_s, abs=1e-9)


def test_saturated_commands_are_reported_and_limited(spec, model, make_world):
    initial = {a.sysid: at_rest([-2.0 + 4.0 * i, 0.0, 3.0], np.eye(3), spec.vehicle.q_nominal_rad)
               for i, a in enumerate(spec.ams)}
    w = make_world(initial)
    s = spec.ams[0].sysid
    report = w.apply(s, 1000.0, [0.0, 0.0, 50.0], [100.0, 0.0, 0.0])
    assert report.saturated and report.mix.saturated and report.joints.saturated
    assert report.joints.applied_nm[0] == spec.vehicle.joint_torque_max_nm[0]
    x0 = w.state(s)
    w.step()
    measured = (w.state(s).pin_v() - x0.pin_v()) / w.dt_s
    # the applied, not the requested, wrench moves the vehicle
    tau = np.concatenate([report.mix.force_B_n, report.mix.tau_B_nm,
                          report.joints.applied_nm])
    predicted = pin.aba(model.pin_model, model.pin_model.createData(), x0.pin_q(), x0.pin_v(), tau)
    np.testing.assert_allclose(measured, predicted, rtol=1e-3, atol=1e-3)
