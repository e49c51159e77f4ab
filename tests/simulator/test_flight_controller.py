"""The emulated autopilot (simulator.flight_controller): PX4's attitude law, allocation and
rate loop, each against its defining property, and the whole against a rigid quadrotor."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from amcore.so3 import R_to_quat_wxyz, exp_so3, quat_wxyz_to_R
from amlink.types import AttitudeTarget
from amcore.allocation import Allocation
from simulator.fc_kernels import attitude_error
from simulator.flight_controller import FlightController, lowpass2p

from .reference_flight_controller import LowPass2p
from simulator.actuators import RotorLag


@pytest.fixture(scope="module")
def fc_params(spec):
    return spec.vehicle.flight_controller


@pytest.fixture(scope="module")
def alloc(spec):
    return Allocation(spec.vehicle.rotors)


def q_of(rotvec) -> tuple:
    return tuple(R_to_quat_wxyz(exp_so3(np.asarray(rotvec, dtype=float))).tolist())


# ----------------------------------------------------------------------------- attitude law
def test_attitude_error_is_the_rotation_to_the_target_and_yaw_is_weighted():
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = q_of(rng.normal(size=3))
        tilt = np.array([*rng.uniform(-0.3, 0.3, 2), 0.0])
        q_d = tuple(R_to_quat_wxyz(quat_wxyz_to_R(q) @ exp_so3(tilt)).tolist())  # a pure body tilt away
        e = np.array(attitude_error(q, q_d, 0.4))
        # with the thrust axes apart by a body tilt and no yaw: 2 sin(angle / 2) about the axis
        np.testing.assert_allclose(e, 2.0 * math.sin(np.linalg.norm(tilt) / 2.0) * tilt / np.linalg.norm(tilt),
                                   atol=1e-9)
        yaw = rng.uniform(-1.0, 1.0)
        q_y = tuple(R_to_quat_wxyz(quat_wxyz_to_R(q) @ exp_so3([0.0, 0.0, yaw])).tolist())
        for w in (0.4, 1.0):  # the yaw about the shared thrust axis, scaled by the weight
            np.testing.assert_allclose(attitude_error(q, q_y, w), [0.0, 0.0, 2.0 * math.sin(w * yaw / 2.0)], atol=1e-9)
        assert np.abs(attitude_error(q, tuple(-x for x in q), 0.4)).max() < 1e-9  # -q is the same attitude


# ----------------------------------------------------------------------------- allocation
def test_allocation_is_normalized_as_px4_and_scales_to_this_vehicle(alloc, spec):
    r = spec.vehicle.rotors
    arm_length_m = math.hypot(*r.rotor[0].position_m)  # the quad X: every rotor at the same radius
    k = r.rotor[0].moment_ratio_m
    assert alloc.torque_scale_nm[0] == pytest.approx(2.0 * arm_length_m * r.thrust_max_n)
    assert alloc.torque_scale_nm[1] == pytest.approx(2.0 * arm_length_m * r.thrust_max_n)
    assert alloc.torque_scale_nm[2] == pytest.approx(4.0 * k * r.thrust_max_n)
    assert alloc.thrust_scale_n == pytest.approx(4.0 * r.thrust_max_n)
    np.testing.assert_allclose(np.abs(alloc.mix[:, 0:2]), math.sqrt(0.5), atol=1e-12)  # quad X: +-0.707
    np.testing.assert_allclose(np.abs(alloc.mix[:, 2:4]), 1.0, atol=1e-12)
    # physically: the rotors' wrench is the normalized command times the scales
    a = alloc.allocate(0.05, -0.03, 0.2, 0.45)
    assert not a.saturated
    (_, _, T), tau = alloc.wrench([r.thrust_max_n * x for x in a.outputs])
    np.testing.assert_allclose(tau, np.array([0.05, -0.03, 0.2]) * alloc.torque_scale_nm, atol=1e-12)
    assert T == pytest.approx(0.45 * alloc.thrust_scale_n)


def test_desaturation_keeps_roll_and_pitch_and_never_raises_thrust(alloc):
    rng = np.random.default_rng(2)
    for _ in range(300):
        roll, pitch, yaw = rng.uniform(-0.6, 0.6, 3)
        thrust = rng.uniform(0.05, 1.0)
        a = alloc.allocate(roll, pitch, yaw, thrust)
        assert all(0.0 <= x <= 1.0 for x in a.outputs)
        assert a.allocated[3] <= thrust + 1e-12  # airmode off: thrust only ever goes down
        if a.saturated and abs(a.unallocated[2]) > 1e-9 and max(map(abs, a.unallocated[:2])) < 1e-9:
            assert abs(a.allocated[2]) < abs(yaw)  # yaw gave way, roll and pitch were kept
    a = alloc.allocate(0.3, 0.0, 0.5, 0.5)  # roll fits; yaw on top does not (0.354 + 0.5 + 0.5 > 1)
    assert a.saturated and a.allocated[0] == pytest.approx(0.3) and 0.0 < a.allocated[2] < 0.5
    a = alloc.allocate(0.4, 0.0, 0.0, 0.95)  # full thrust and roll: thrust is cut, roll kept
    assert a.allocated[0] == pytest.approx(0.4) and a.allocated[3] < 0.95 and max(a.outputs) == pytest.approx(1.0)


# ----------------------------------------------------------------------------- rate loop, filters
def test_low_pass_has_unit_dc_gain_and_minus_3_db_at_its_cutoff():
    f = LowPass2p(lowpass2p(1000.0, 40.0))
    assert all(f.apply(2.5) == pytest.approx(2.5) for _ in range(100))
    f = LowPass2p(lowpass2p(1000.0, 40.0))
    y = [f.apply(math.sin(2.0 * math.pi * 40.0 * k / 1000.0)) for k in range(4000)]
    assert max(y[2000:]) == pytest.approx(math.sqrt(0.5), abs=0.01)
    assert LowPass2p(lowpass2p(1000.0, 0.0)).apply(3.0) == 3.0


def test_integral_stops_growing_into_a_saturated_axis_and_stays_within_its_limit(fc_params, spec):
    """A roll rate error the rotors cannot meet at full thrust: the roll integral stops in the
    saturated direction; unsaturated, it is clamped at MC_RR_INT_LIM."""
    p = dataclasses.replace(fc_params, IMU_GYRO_CUTOFF=0.0, IMU_DGYRO_CUTOFF=0.0, MC_ROLLRATE_I=5.0)
    target = AttitudeTarget(0, [1.0, 0.0, 0.0, 0.0], [3.0, 0.0, 0.0], 1.0)  # roll rate feed-forward, full thrust
    fc = FlightController(p, spec.vehicle.rotors, 1e-3)
    outs = [fc.step((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), target) for _ in range(200)]
    assert all(o.allocation.saturated for o in outs[1:])
    assert fc.rate_int[0] < 0.05  # one step's worth at most: saturated positive ever after
    fc = FlightController(p, spec.vehicle.rotors, 1e-3)
    target = AttitudeTarget(0, [1.0, 0.0, 0.0, 0.0], [0.5, 0.0, 0.0], 0.4)
    for _ in range(2000):
        fc.step((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), target)
    assert fc.rate_int[0] == pytest.approx(p.MC_RR_INT_LIM)


def test_loop_runs_at_its_own_rate_and_holds_between(fc_params, spec):
    fc = FlightController(dataclasses.replace(fc_params, rate_hz=250.0), spec.vehicle.rotors, 1e-3)
    target = AttitudeTarget(0, q_of([0.1, 0.0, 0.0]), [0.0, 0.0, 0.0], 0.4)
    outs = [fc.step((1.0, 0.0, 0.0, 0.0), (0.02 * k, 0.0, 0.0), target) for k in range(12)]
    assert fc.every == 4 and fc.dt_s == pytest.approx(4e-3)
    assert [outs[k] is outs[k - 1] for k in range(1, 12)] == [k % 4 != 0 for k in range(1, 12)]
    assert FlightController(fc_params, spec.vehicle.rotors, 1e-3).step((1, 0, 0, 0), (0, 0, 0), None) is None


# ----------------------------------------------------------------------------- the whole loop
def _fly(fc, rotors, q_d, steps, disturbance_nm=(0.0, 0.0, 0.0), tau_s=0.025, dt=1e-3):
    """A rigid quadrotor (the vehicle's base and arm at its nominal inertia) with lagging rotors."""
    J = np.diag([0.04, 0.04, 0.065])
    alloc, lag = Allocation(rotors), RotorLag(tau_s, dt)
    R, w = np.eye(3), np.zeros(3)
    target = AttitudeTarget(0, q_d, [0.0, 0.0, 0.0], 0.4)
    errors = []
    for _ in range(steps):
        o = fc.step(tuple(R_to_quat_wxyz(R).tolist()), tuple(w.tolist()), target)
        _, tau = alloc.wrench(lag.step(o.rotor_thrusts_n))
        w = w + dt * np.linalg.solve(J, np.array(tau) + disturbance_nm - np.cross(w, J @ w))
        R = R @ exp_so3(w * dt)
        E = quat_wxyz_to_R(np.array(q_d)).T @ R
        errors.append(math.acos(max(-1.0, min(1.0, (np.trace(E) - 1.0) / 2.0))))  # the angle left
    return np.array(errors)


def test_the_autopilot_flies_a_rigid_quad_to_its_target_and_rejects_a_steady_moment(fc_params, spec):
    rotors = spec.vehicle.rotors
    e = _fly(FlightController(fc_params, rotors, 1e-3), rotors, q_of([0.15, -0.1, 0.3]), 3000)
    assert e[0] > 0.3 and e[1000:].max() < 0.1 * e[0] and e[2000:].max() < 2e-3  # settled, no limit cycle
    e = _fly(FlightController(fc_params, rotors, 1e-3), rotors, q_of([0.1, 0.05, 0.0]), 1000)  # a tilt: fast
    assert e[250:].max() < 0.1 * e[0]
    # a steady pitch moment (an arm's load): the integrator takes it up, no steady error
    e = _fly(FlightController(fc_params, rotors, 1e-3), rotors, (1.0, 0.0, 0.0, 0.0), 4000, (0.0, 1.5, 0.0))
    assert e.max() < 0.05 and e[-1] < 1e-3
