"""Wire <-> controller conversions of the companion."""
from __future__ import annotations

import numpy as np

from amcore.control import ControllerMemory, ControllerParams, step
from amcore.mission import am_mission
from amcore.model import create_data
from amcore.so3 import R_to_quat_wxyz, exp_so3, quat_wxyz_to_R
from amlink.types import SensorFrame
from companion.pilot import setpoint_from_result, state_from_frame


def test_state_from_frame_keeps_frames_and_renormalizes_the_quaternion():
    R = exp_so3(np.array([0.1, -0.2, 0.3]))
    q = R_to_quat_wxyz(R) * 1.0001  # float32 on the wire: not exactly unit
    f = SensorFrame(step=3, time_s=0.003, p_WB=[1, 2, 3], quat_WB_wxyz=q, v_B=[0.1, 0, 0], w_B=[0, 0.2, 0],
                    q=[0.1, 0.2, 0.3], qdot=[0, 0, 1], wrench_E=np.zeros(6))
    s = state_from_frame(f)
    np.testing.assert_allclose(s.R_WB, R, atol=1e-12)
    np.testing.assert_allclose(s.R_WB @ s.R_WB.T, np.eye(3), atol=1e-12)
    np.testing.assert_array_equal(s.v_B, [0.1, 0, 0])
    np.testing.assert_array_equal(s.qdot, [0, 0, 1])


def test_setpoint_carries_the_command_and_the_attitude_target(spec, model):
    am = spec.ams[0]
    m = am_mission(spec, am, model)
    params = ControllerParams.from_vehicle(spec.vehicle, m.frame)
    x = m.initial_state()
    res = step(model, create_data(model), params, x, m.reference(0.3), np.zeros(6), ControllerMemory(), 0.3)
    sp, att = setpoint_from_result(300, res, thrust_max_n=48.0)
    assert sp.step == att.step == 300
    assert sp.thrust_n == res.command.thrust_n
    np.testing.assert_array_equal(sp.tau_q_nm, res.command.tau_q_nm)
    np.testing.assert_allclose(quat_wxyz_to_R(att.quat_wxyz), res.diagnostics.R_d, atol=1e-12)
    assert att.thrust_normalized == np.clip(res.command.thrust_n / 48.0, 0, 1)


def test_setpoint_matches_the_validating_constructors(spec, model):
    """setpoint_from_result builds its setpoint and attitude target with amlink's decoder
    constructors; they equal what the validating ones build."""
    from amlink.types import AttitudeTarget, TorqueSetpoint

    m = am_mission(spec, spec.ams[1], model)
    params = ControllerParams.from_vehicle(spec.vehicle, m.frame)
    x = m.initial_state()
    res = step(model, create_data(model), params, x, m.reference(2.0), np.ones(6), ControllerMemory(), 2.0)
    for thrust_max in (48.0, 1.0, 1e6):
        sp, att = setpoint_from_result(2**64 - 1, res, thrust_max_n=thrust_max)
        c, d = res.command, res.diagnostics
        sp2 = TorqueSetpoint(step=2**64 - 1, thrust_n=c.thrust_n, tau_B_nm=c.tau_B_nm, tau_q_nm=c.tau_q_nm)
        att2 = AttitudeTarget(step=2**64 - 1, quat_wxyz=R_to_quat_wxyz(d.R_d), rates_rad_s=d.w_bd,
                              thrust_normalized=float(np.clip(c.thrust_n / thrust_max, 0.0, 1.0)))
        for a, b in ((sp, sp2), (att, att2)):
            assert type(a) is type(b) and a.__dict__.keys() == b.__dict__.keys()
            for k in a.__dict__:
                va, vb = getattr(a, k), getattr(b, k)
                assert type(va) is type(vb)
                if isinstance(va, np.ndarray):
                    assert np.array_equal(va, vb) and va.dtype == vb.dtype and not va.flags.writeable
                else:
                    assert va == vb


def test_state_from_frame_carries_the_quaternion():
    R = exp_so3(np.array([0.3, 2.9, -0.4]))
    q = R_to_quat_wxyz(R).astype(np.float32)
    f = SensorFrame(step=0, time_s=0.0, p_WB=[0, 0, 1], quat_WB_wxyz=q, v_B=np.zeros(3), w_B=np.zeros(3),
                    q=[0.1, 0.2, 0.3], qdot=np.zeros(3), wrench_E=np.zeros(6))
    s = state_from_frame(f)
    w, x, y, z = q.astype(float) / np.linalg.norm(q.astype(float))
    np.testing.assert_allclose(s.quat_xyzw, [x, y, z, w], atol=1e-15)
    np.testing.assert_allclose(s.R_WB, quat_wxyz_to_R(q), atol=1e-15)
    np.testing.assert_allclose(s.pin_q()[3:7], [x, y, z, w], atol=1e-15)


def test_state_from_frame_copies_a_decoded_frame_once():
    from amlink.types import sensor_frame_from_wire

    v = [0.1, 0.2, 1.0, 0.9, 0.1, 0.0, 0.1, 1.0, 2.0, 3.0, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, *range(6)]
    f = sensor_frame_from_wire(1, 0.001, v, 2, 0)
    s = state_from_frame(f)
    for name, x in (("p_WB", s.p_WB), ("v_B", s.v_B), ("w_B", s.w_B), ("q", s.q), ("qdot", s.qdot)):
        assert np.array_equal(x, getattr(f, name)) and x.flags.writeable and x.flags.c_contiguous
        assert not np.shares_memory(x, f.p_WB.base)
    s.p_WB[0] = 5.0  # the state's own copy
    assert f.p_WB[0] == 0.1 and s.v_B.tolist() == [1.0, 2.0, 3.0]
