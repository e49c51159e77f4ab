"""Value types validate shapes and ranges and are immutable."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from amlink.types import (
    AttitudeTarget,
    ScenarioInfo,
    SensorFrame,
    SetpointFlag,
    StepFlag,
    TorqueSetpoint,
    attitude_target_from_wire,
    frame_values,
    sensor_frame_from_wire,
    sensor_frame_of_array,
    torque_setpoint_from_wire,
)


def frame(**kw):
    args = dict(step=3, time_s=0.003, p_WB=[0, 0, 1], quat_WB_wxyz=[1, 0, 0, 0], v_B=[0, 0, 0], w_B=[0, 0, 0],
                q=[0.1, 0.2, 0.3], qdot=[0, 0, 0], wrench_E=np.zeros(6))  # fmt: skip
    args.update(kw)
    return SensorFrame(**args)


def test_sensor_frame_copies_to_read_only_float64():
    src = np.array([0.1, 0.2, 0.3])
    f = frame(q=src)
    src[0] = 99.0
    assert f.q[0] == 0.1 and f.q.dtype == np.float64
    with pytest.raises(ValueError):
        f.q[0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        f.step = 4
    assert f.n_joints == 3 and not f.shutdown
    assert frame(flags=StepFlag.SHUTDOWN | StepFlag.FAILSAFE).shutdown


@pytest.mark.parametrize(
    "kw",
    [
        dict(p_WB=[0, 0]),
        dict(quat_WB_wxyz=[1, 0, 0]),
        dict(wrench_E=np.zeros(5)),
        dict(q=np.zeros(9), qdot=np.zeros(9)),  # more joints than the wire carries
        dict(qdot=[0, 0]),  # qdot must match q
        dict(q=np.zeros((3, 1))),
        dict(step=-1),
        dict(step=2**64),
        dict(flags=256),
    ],
)
def test_sensor_frame_rejects_bad_shapes_and_ranges(kw):
    with pytest.raises(ValueError):
        frame(**kw)


def test_setpoint_and_attitude_validate():
    sp = TorqueSetpoint(1, 9.81, [0, 0, 0], [], SetpointFlag.SATURATED)
    assert sp.n_joints == 0 and sp.flags == SetpointFlag.SATURATED
    with pytest.raises(ValueError):
        TorqueSetpoint(1, 9.81, [0, 0], [])
    with pytest.raises(ValueError):
        AttitudeTarget(1, [1, 0, 0], [0, 0, 0], 0.5)


@pytest.mark.parametrize(
    "kw",
    [dict(name="x" * 33), dict(name="é"), dict(name="a\x00b"), dict(rate_hz=0.0), dict(rate_hz=float("nan")),
     dict(n_am=256), dict(seed=-1)],  # fmt: skip
)
def test_scenario_info_rejects_what_the_wire_cannot_carry(kw):
    args = dict(scenario_id=1, n_am=2, name="two_am", seed=0, rate_hz=1000.0)
    args.update(kw)
    with pytest.raises(ValueError):
        ScenarioInfo(**args)


def _same(a, b):
    assert type(a) is type(b) and vars(a).keys() == vars(b).keys()
    for name, x in vars(a).items():
        y = getattr(b, name)
        if isinstance(x, np.ndarray):
            assert x.dtype == y.dtype == np.float64 and x.shape == y.shape and x.tobytes() == y.tobytes()
            assert not x.flags.writeable and not y.flags.writeable
        else:
            assert (x, type(x)) == (y, type(y))


@pytest.mark.parametrize("n", [0, 1, 3, 8])
def test_wire_constructors_build_what_the_validating_constructors_build(n):
    rng = np.random.default_rng(n)
    v = rng.normal(size=19 + 2 * n).tolist()
    j = 13 + n
    _same(sensor_frame_from_wire(2**64 - 1, 1.5, v, n, 3),
          SensorFrame(2**64 - 1, 1.5, v[0:3], v[3:7], v[7:10], v[10:13], v[13:j], v[j : j + n], v[j + n :], 3))
    _same(torque_setpoint_from_wire(7, 2.5, v[: 3 + n], n, 2), TorqueSetpoint(7, 2.5, v[:3], v[3 : 3 + n], 2))
    _same(attitude_target_from_wire(7, v[:8]), AttitudeTarget(7, v[:4], v[4:7], v[7]))


@pytest.mark.parametrize("n", [0, 3, 8])
def test_frame_values_are_the_decoders_array_or_the_fields_joined(n):
    v = np.random.default_rng(n).normal(size=19 + 2 * n)
    f = sensor_frame_from_wire(5, 0.005, v.tolist(), n, 0)
    a = frame_values(f)
    assert a.tobytes() == v.tobytes() and a is f.p_WB.base and not a.flags.writeable
    j = 13 + n
    g = SensorFrame(5, 0.005, v[0:3], v[3:7], v[7:10], v[10:13], v[13:j], v[j : j + n], v[j + n :])
    assert frame_values(g).tobytes() == v.tobytes()


def test_sensor_frame_of_array_takes_the_array_over():
    n = 2
    v = np.arange(19.0 + 2 * n)
    f = sensor_frame_of_array(1, 0.001, v, n, 0)
    _same(f, sensor_frame_from_wire(1, 0.001, v.tolist(), n, 0))
    assert f.p_WB.base is v and not v.flags.writeable
