"""telemetry.capture: the binary samples built in two steps say exactly what the JSON samples
say, byte for byte the literal path's, for real controller steps and ground truth, any number
of joints, arrays of other types and non-finite numbers."""
from __future__ import annotations

import json
import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from amcore.so3 import R_to_quat_wxyz_shepperd
from telemetry import binary, capture, schema
from telemetry.capture import finished
from telemetry.schema import PHASES, Channel, Keys

KEYS = Keys()
DIAGNOSTICS = ("r_c", "r_c_d", "r_c_err", "e_R", "e_w", "R_WB", "R_d", "y", "y_d", "y_err", "F_y", "F_rc",
               "wrench_W_filtered", "wrench_E_filtered", "sigma_min_J3", "damping", "com_err_saturated",
               "y_err_saturated")  # the public fields the builders read


def _received_json(payload: dict) -> dict:
    """What a recorder of JSON samples gets: the payload through the JSON encoder and back."""
    return json.loads(schema.encode(payload)[0])


@pytest.mark.parametrize("phase", PHASES)
def test_controller_sample_decodes_to_the_json_payload_exactly(step_result, phase):
    d, c = step_result.diagnostics, step_result.command
    data = finished(capture.controller(0.7, phase, d, c, sysid=4))
    payload = schema.controller_sample(0.7, phase, d, c, sysid=4)
    back = binary.to_dict(Channel.CONTROLLER, data)
    assert back == payload == _received_json(payload)  # float64 for float64: == on every number
    assert list(back) == list(payload)  # and in the same order
    assert data == binary.from_dict(Channel.CONTROLLER, payload)  # the fast builder, byte for byte the literal path
    assert binary.header(data) == (0.7, 0)


def test_ground_truth_samples_decode_to_the_json_payloads_exactly(ground_truth):
    fast = [(k, finished(p)) for k, p in capture.ground_truth(ground_truth, KEYS)]
    slow = list(schema.ground_truth_samples(ground_truth, KEYS))
    assert [k for k, _ in fast] == [k for k, _ in slow]
    assert any(len(p.get("p_W_joints", ())) for _, p in slow)  # the arm is in it
    assert any(p.get("n_points", 0) for _, p in slow) and any(p.get("touching") for _, p in slow)
    for (key, data), (_, payload) in zip(fast, slow):
        ch = KEYS.parse(key).channel
        assert binary.to_dict(ch, data) == payload == _received_json(payload), key
        assert data == binary.from_dict(ch, payload), key


def _diag(rng, n_y: int, n_q: int, **over):
    """Diagnostics and Command as their public fields (what the builders read), n_y task variables, n_q joints."""
    v = lambda k: rng.normal(size=k)  # noqa: E731
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R *= np.linalg.det(R)  # a rotation
    diag = NS(r_c=v(3), r_c_d=v(3), r_c_err=v(3), e_R=v(3), e_w=v(3), R_WB=R, R_d=R.T.copy(), y=v(n_y), y_d=v(n_y),
              y_err=v(n_y), F_y=v(n_y), F_rc=v(3), wrench_W_filtered=v(6), wrench_E_filtered=v(6),
              sigma_min_J3=float(rng.uniform()), damping=float(rng.uniform()), com_err_saturated=True,
              y_err_saturated=False)
    cmd = NS(thrust_n=float(rng.uniform(10, 30)), tau_B_nm=v(3), tau_q_nm=v(n_q))
    for k, val in over.items():
        setattr(cmd if hasattr(cmd, k) else diag, k, val)
    return diag, cmd


@pytest.mark.parametrize("n", [0, 1, 2, 3, 5, 7])
def test_any_number_of_joints_and_task_variables(n):
    rng = np.random.default_rng(n)
    for n_y in (n, 6):
        diag, cmd = _diag(rng, n_y, n)
        data = finished(capture.controller(1.25, "hover", diag, cmd, sysid=11))
        assert binary.to_dict(Channel.CONTROLLER, data) == schema.controller_sample(1.25, "hover", diag, cmd, sysid=11)
    joints = tuple(rng.normal(size=3) for _ in range(n))
    am = NS(p_WB=rng.normal(size=3), R_WB=np.eye(3), p_WE=rng.normal(size=3), R_WE=np.eye(3), p_W_joints=joints,
            rotor_saturated_steps=3, joint_saturated_steps=2**40)
    got = binary.to_dict(Channel.AM_TRUTH, finished(capture.am_truth(0.5, 4, am)))
    assert got == schema.am_truth_sample(0.5, 4, am)
    assert len(got.get("p_W_joints", ())) == n  # absent when there are none, as in JSON


def test_the_caller_copies_and_the_sender_finishes(step_result):
    """The caller's part is a copy: changing the arrays afterwards changes nothing."""
    d, c = step_result.diagnostics, step_result.command
    expected = schema.controller_sample(0.7, "grasp", d, c, sysid=4)
    diag = NS(**{k: (v.copy() if isinstance(v, np.ndarray) else v) for k in DIAGNOSTICS for v in [getattr(d, k)]})
    pending = capture.controller(0.7, "grasp", diag, c, sysid=4)
    assert type(pending) is tuple  # (finish, pre-sample): the quaternions are left to the sender
    diag.R_WB[:] = 0.0
    diag.r_c[:] = -1.0
    assert binary.to_dict(Channel.CONTROLLER, finished(pending)) == expected


@pytest.mark.parametrize("change", [
    dict(y_d=np.zeros(4)),  # longer than y
    dict(tau_B_nm=[0.1, 0.2, 0.3]),  # a list
    dict(e_R=np.zeros(3, dtype=np.float32)),  # another dtype
    dict(r_c=np.arange(6.0)[::2]),  # not contiguous
    dict(R_WB=np.asfortranarray(np.diag([1.0, -1.0, -1.0]))),  # column-major: C-contiguous it is not
])
def test_unexpected_shapes_and_types_take_the_literal_path(change):
    rng = np.random.default_rng(5)
    diag, cmd = _diag(rng, 3, 3, **change)
    pending = capture.controller(0.5, "grasp", diag, cmd, sysid=4)
    assert type(pending) is bytes  # the literal path, all on the caller
    assert binary.to_dict(Channel.CONTROLLER, pending) == schema.controller_sample(0.5, "grasp", diag, cmd, sysid=4)
    am = NS(p_WB=(1.0, 2.0, 3.0), R_WB=np.eye(3), p_WE=[0.0, 0.0, 1.0], R_WE=np.eye(3))  # no counters, tuples
    got = binary.to_dict(Channel.AM_TRUTH, finished(capture.am_truth(0.5, 4, am)))
    assert got == schema.am_truth_sample(0.5, 4, am)
    with pytest.raises(TypeError):  # a missing array is an error on both paths
        finished(capture.controller(0.5, "grasp", *_diag(rng, 3, 3, wrench_W_filtered=None)))


def test_non_finite_numbers_travel_as_they_are():
    """Binary samples carry NaN and infinity as IEEE 754 values; JSON sends null instead."""
    rng = np.random.default_rng(9)
    e_R = np.array([math.nan, math.inf, -math.inf])
    diag, cmd = _diag(rng, 3, 3, e_R=e_R, damping=math.nan)
    back = binary.to_dict(Channel.CONTROLLER, finished(capture.controller(0.5, "grasp", diag, cmd, sysid=4)))
    assert math.isnan(back["e_R"][0]) and back["e_R"][1:] == [math.inf, -math.inf] and math.isnan(back["damping"])
    data, replaced = schema.encode(schema.controller_sample(0.5, "grasp", diag, cmd, sysid=4))
    assert replaced and json.loads(data)["e_R"] == [None, None, None] and json.loads(data)["damping"] is None

# ----------------------------------------------------------------------------- the law's packed array
def test_a_step_of_the_compiled_law_is_copied_from_its_packed_array(step_result):
    """The packed path (one copy of the array's prefix) gives the bytes of the field-by-field
    path and of the literal path, and reading fields first changes nothing."""
    d, c = step_result.diagnostics, step_result.command
    pending = capture.controller(0.7, "grasp", d, c, sysid=4)
    assert pending[0] is capture._packed_layouts[(d._packed.size, len(d.y_d), len(c.tau_q_nm), "grasp")].finisher
    literal = binary.from_dict(Channel.CONTROLLER, schema.controller_sample(0.7, "grasp", d, c, sysid=4))
    fields = NS(**{k: getattr(d, k) for k in DIAGNOSTICS})
    assert finished(pending) == finished(capture.controller(0.7, "grasp", fields, c, sysid=4)) == literal
    assert finished(capture.controller(0.7, "grasp", d, c, sysid=4)) == literal  # all fields now read (cached views)


def test_a_reassigned_field_is_sent_as_reassigned(spec, model):
    from amcore.control import ControllerMemory, ControllerParams, step
    from amcore.mission import am_mission
    from amcore.model import create_data

    m = am_mission(spec, spec.ams[0], model)
    res = step(model, create_data(model), ControllerParams.from_vehicle(spec.vehicle, m.frame), m.initial_state(),
               m.reference(0.3), np.zeros(6), ControllerMemory(), 0.3)
    d, c = res.diagnostics, res.command
    d.e_R = np.array([1.0, 2.0, 3.0])  # another array: no longer the packed array's
    d.damping = 0.25
    d.R_d = np.eye(3)
    back = binary.to_dict(Channel.CONTROLLER, finished(capture.controller(0.3, "hover", d, c, sysid=4)))
    assert back["e_R"] == [1.0, 2.0, 3.0] and back["damping"] == 0.25 and back["q_WB_d"] == [1.0, 0.0, 0.0, 0.0]
    d.y_err[:] = 7.0  # written into the array's own view: the packed path sends it too
    pending = capture.controller(0.3, "hover", d, c, sysid=4)
    assert binary.to_dict(Channel.CONTROLLER, finished(pending))["y_err"] == [7.0] * len(d.y_err)


def test_real_runs_samples_in_one_batch_are_the_literal_paths_bytes(spec, model):
    """Every controller and truth sample of a short two-AM run, finished as the sender does
    (one call per layout for the whole batch), is byte for byte the literal path's."""
    from tests.ground_station import simrun

    steps, truths = [], []
    simrun.run(simrun.short_spec(spec, 0.3), model, 0.3, lambda k, p: None, KEYS,
               on_step=lambda s, t, phase, res: steps.append((s, t, phase, res)), on_truth=truths.append)
    pending = [(capture.controller(t, phase, res.diagnostics, res.command, sysid=s),
                binary.from_dict(Channel.CONTROLLER, schema.controller_sample(t, phase, res.diagnostics,
                                                                              res.command, sysid=s)))
               for s, t, phase, res in steps]
    for gt in truths:
        for (key, p), (_, payload) in zip(capture.ground_truth(gt, KEYS), schema.ground_truth_samples(gt, KEYS)):
            if type(p) is tuple:
                pending.append((p, binary.from_dict(KEYS.parse(key).channel, payload)))
    by_layout: dict = {}
    for (f, pre), literal in pending:
        by_layout.setdefault(f, []).append((pre, literal))
    assert len(pending) > 1000 and len(by_layout) >= 2  # controller (its phases) and truth layouts
    for f, group in by_layout.items():
        assert f.many([pre for pre, _ in group]) == [literal for _, literal in group]


def test_the_laws_q_d_is_the_same_rotation_not_the_same_bits(step_result):
    """q_WB_d is computed from R_d as the literal path does (amcore.so3.R_to_quat_wxyz_shepperd), not taken from
    the law's q_d: both are (w, x, y, z) with w >= 0 of the same matrix, but Eigen's
    arithmetic (law.quaternion_xyzw) rounds differently in the last bits."""
    d = step_result.diagnostics
    q = np.array(R_to_quat_wxyz_shepperd(d.R_d))
    assert d.q_d[0] >= 0.0 and q[0] >= 0.0
    assert np.allclose(d.q_d, q, rtol=0.0, atol=4 * np.finfo(float).eps)
    sent = binary.to_dict(Channel.CONTROLLER, finished(capture.controller(0.7, "grasp", d, step_result.command)))
    assert sent["q_WB_d"] == q.tolist()


def test_the_reported_base_state_rides_beside_the_truth():
    rng = np.random.default_rng(9)
    est = tuple(rng.normal(size=13).tolist())
    am = NS(p_WB=rng.normal(size=3), R_WB=np.eye(3), p_WE=rng.normal(size=3), R_WE=np.eye(3), p_W_joints=(),
            rotor_saturated_steps=0, joint_saturated_steps=0, estimate=est)
    pending = capture.am_truth(0.5, 4, am)
    assert type(pending) is tuple  # the fast path
    got = binary.to_dict(Channel.AM_TRUTH, finished(pending))
    assert got == schema.am_truth_sample(0.5, 4, am)
    assert got["p_WB_est"] + got["q_WB_est"] + got["v_B_est"] + got["w_B_est"] == list(est)
    none = binary.to_dict(Channel.AM_TRUTH, finished(capture.am_truth(0.5, 4, NS(**{**vars(am), "estimate": ()}))))
    assert none["q_WB_est"] == [0.0] * 4  # nothing reported yet
