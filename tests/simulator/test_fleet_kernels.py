"""One compiled call over every AM (simulator.fleet_kernels) against each AM stepped alone: the
devices and estimators of AMs that share `DeviceArrays`, and the autopilots that share
`AutopilotArrays`, give, bit for bit, what a `DeviceSuite` and a `FlightController` of their
own give on the same inputs (the same kernels run, in the same order, for each row); an AM's
row moves only when that AM steps; the fused step between control steps (`hold`) is the
devices' step, then the autopilots' on the estimates just made."""
from __future__ import annotations

import dataclasses

import numpy as np

from amlink.types import AttitudeTarget
from simulator import fleet_kernels
from simulator.devices import DeviceArrays, DeviceSuite
from simulator.flight_controller import AutopilotArrays, FlightController

from .test_device_kernels import DT, FULL, G, moving_values

SYSIDS = (3, 4, 7)


def fleet_and_alone(spec=FULL, seed=11):
    """The same three AMs twice: in one `DeviceArrays`, and each in a suite of its own."""
    starts = [moving_values(np.random.default_rng(s), 1)[0] for s in SYSIDS]
    arrays = DeviceArrays(len(SYSIDS), 3, spec.estimator.history_steps, DT, G)
    fleet = [DeviceSuite(spec, 3, DT, G, seed, s, v, arrays, i) for i, (s, v) in enumerate(zip(SYSIDS, starts))]
    alone = [DeviceSuite(spec, 3, DT, G, seed, s, v) for s, v in zip(SYSIDS, starts)]
    return arrays, fleet, alone


def test_the_devices_of_a_fleet_step_as_each_alone():
    arrays, fleet, alone = fleet_and_alone()
    values = [moving_values(np.random.default_rng(100 + s), 1200) for s in SYSIDS]
    for k in range(1200):  # past the F/T tare (0.5 s) and several blocks of draws (256 steps)
        t = k * DT
        got = []
        for i, suite in enumerate(alone):
            v = values[i][k] if k % 4 == 0 or suite.needs_reading(t) else values[i][k][:13]
            got.append(suite.step(v, t))
            arrays.load(v, i)
        arrays.step(t)
        for i, suite in enumerate(fleet):
            assert arrays.frames[i, :len(got[i])].tolist() == got[i], f"AM {i}, step {k}"
            assert np.array_equal(suite.autopilot_rate, alone[i].autopilot_rate)
        assert [s.mocap.captured for s in fleet] == [s.mocap.captured for s in alone]


def test_an_am_that_does_not_step_keeps_its_row():
    arrays, fleet, _ = fleet_and_alone()
    values = [moving_values(np.random.default_rng(s), 3) for s in SYSIDS]
    for i in range(3):
        arrays.load(values[i][0], i)
    arrays.step(0.0)
    before = (arrays.frames.copy(), arrays.state.copy(), arrays.est_x.copy())
    arrays.load(values[1][1], 1)
    arrays.step(DT, np.array([1], np.int64))
    for a, b in zip(before, (arrays.frames, arrays.state, arrays.est_x)):
        assert np.array_equal(a[[0, 2]], b[[0, 2]])
        assert not np.array_equal(a[1], b[1])


def targets(rng, k):
    rv = 0.3 * rng.normal(size=3)
    angle = np.linalg.norm(rv)
    q = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * rv / angle])
    return AttitudeTarget(k, quat_wxyz=q, rates_rad_s=0.5 * rng.normal(size=3),
                          thrust_normalized=float(rng.uniform(0.2, 1.05)))


def test_the_autopilots_of_a_fleet_step_as_each_alone(spec):
    fc = dataclasses.replace(spec.vehicle.flight_controller, rate_hz=500.0)  # a loop every 2 steps: held between
    rotors = spec.vehicle.rotors
    arrays = AutopilotArrays(3, rotors)
    fleet = [FlightController(fc, rotors, DT, arrays, i) for i in range(3)]
    alone = [FlightController(fc, rotors, DT) for _ in range(3)]
    rng = np.random.default_rng(5)
    held = [None] * 3
    saturated = 0
    for k in range(600):
        flown = [i for i in range(3) if (k + i) % 5]  # each AM sits some steps out
        for i in flown:
            if k % 37 == i or held[i] is None:
                held[i] = targets(rng, k)
                arrays.set_target(i, held[i])
            q, w = targets(rng, k).quat_wxyz, 2.0 * rng.normal(size=3)
            arrays.attitude[i], arrays.rate[i] = q, w
            expect = alone[i].step(tuple(q), tuple(w), held[i])
            saturated += expect.allocation.saturated
        arrays.step(np.array(flown, np.int64))
        for i in flown:
            got = fleet[i].output
            assert got == alone[i].output, f"AM {i}, step {k}"
        for i in range(3):
            assert fleet[i].rate_int == alone[i].rate_int
    assert saturated > 0  # the comparison covers desaturated allocations too


def test_reset_starts_the_loops_afresh(spec):
    fc, rotors = spec.vehicle.flight_controller, spec.vehicle.rotors
    arrays = AutopilotArrays(2, rotors)
    used, fresh = FlightController(fc, rotors, DT, arrays, 0), FlightController(fc, rotors, DT)
    rng = np.random.default_rng(1)
    for k in range(50):
        used.step(tuple(targets(rng, k).quat_wxyz), (0.1, 0.0, 0.0), targets(rng, k))
    used.reset()
    assert used.output is None
    target = targets(rng, 0)
    assert used.step((1.0, 0.0, 0.0, 0.0), (0.0, 0.2, 0.0), target) == \
        fresh.step((1.0, 0.0, 0.0, 0.0), (0.0, 0.2, 0.0), target)


def test_the_fused_step_is_the_devices_then_the_autopilots_on_their_estimates(spec):
    fc, rotors = spec.vehicle.flight_controller, spec.vehicle.rotors
    devices, fleet, alone = fleet_and_alone()
    autopilots = AutopilotArrays(3, rotors)
    fcs = [FlightController(fc, rotors, DT, autopilots, i) for i in range(3)]
    fcs_alone = [FlightController(fc, rotors, DT) for _ in range(3)]
    values = [moving_values(np.random.default_rng(200 + s), 300) for s in SYSIDS]
    target = targets(np.random.default_rng(2), 0)
    every = np.arange(3, dtype=np.int64)
    for i in range(3):
        autopilots.set_target(i, target)
    for k in range(300):
        t = k * DT
        for i in range(3):
            odo = alone[i].step(values[i][k], t)
            fcs_alone[i].step(odo[3:7], alone[i].autopilot_rate.tolist(), target)
            devices.load(values[i][k], i)
        fleet_kernels.hold(every, t, *devices.sense_arrays(), every, *autopilots.fly_arrays())
        for i in range(3):
            assert fcs[i].output == fcs_alone[i].output, f"AM {i}, step {k}"
