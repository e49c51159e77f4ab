"""The autopilot's loops (simulator.fc_kernels, through `FlightController`) against their
readable reference (tests/simulator/reference_flight_controller.py), step after step,
saturated or not.

Tolerance: 1e-12 on every rate setpoint, normalized torque and thrust, and per newton of a
rotor's most thrust; the saturation flags exactly. Both sides take the same steps on IEEE
doubles, so what may differ is the order numba's compiler gives a sum (ulps); a wrong gain,
filter or anti-windup rule moves these by 1e-4 or more within a few steps."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from amlink.types import AttitudeTarget
from simulator import fc_kernels as fk
from simulator.flight_controller import FlightController

from . import reference_flight_controller as ref


def random_quat(rng) -> tuple[float, ...]:
    q = rng.normal(size=4)
    return tuple((q / np.linalg.norm(q) * rng.uniform(0.98, 1.02)).tolist())  # not quite unit, as estimates


def test_min_max_keep_pythons_order_on_ties_and_nan():
    for a, b in ((1.0, 2.0), (2.0, 1.0), (0.0, -0.0), (-0.0, 0.0), (math.nan, 1.0), (1.0, math.nan)):
        for fast, slow in ((fk.pymin, min), (fk.pymax, max)):
            r, e = fast(a, b), slow(a, b)
            assert (math.isnan(r) and math.isnan(e)) or (r == e and math.copysign(1, r) == math.copysign(1, e))


def test_attitude_error_is_its_reference():
    rng = np.random.default_rng(7)
    cases = [(random_quat(rng), random_quat(rng)) for _ in range(3000)]
    q = random_quat(rng)
    cases += [(q, q), (q, tuple(-x for x in q)),  # no error; the same attitude
              ((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0))]  # thrust axes opposite
    for q, q_d in cases:
        q, q_d = ref.quat_normalized(q), ref.quat_normalized(q_d)
        for w in (0.4, 1.0, 0.0):
            assert np.allclose(fk.attitude_error(q, q_d, w), ref.attitude_error(q, q_d, w), rtol=0.0, atol=1e-12)


TOL = 1e-12


def _close(a, b) -> bool:
    return len(a) == len(b) and all(abs(x - y) <= TOL for x, y in zip(a, b))


@pytest.mark.parametrize("scale", [0.05, 3.0])  # gentle; far off, the allocation and the integral saturate
def test_the_flight_controller_flies_as_its_reference(spec, scale):
    v = spec.vehicle
    for params in (v.flight_controller,
                   dataclasses.replace(v.flight_controller, IMU_GYRO_CUTOFF=0.0, body_rate_feedforward=False)):
        fast = FlightController(params, v.rotors, spec.dt_s)
        slow = ref.ReferenceFlightController(FlightController(params, v.rotors, spec.dt_s))
        rng = np.random.default_rng(11)
        q, w = random_quat(rng), (0.0, 0.0, 0.0)
        steered = 0  # updates whose integral the last allocation's saturation held back
        for k in range(600):
            if k % 4 == 0:  # a new target at the control rate
                target = AttitudeTarget(k, quat_wxyz=np.array(random_quat(rng)),
                                        rates_rad_s=scale * rng.normal(size=3), thrust_normalized=rng.uniform(0.0, 1.1))
            q = ref.quat_normalized(tuple(np.add(q, scale * 0.02 * rng.normal(size=4)).tolist()))
            w = tuple((np.array(w) + scale * rng.normal(size=3)).tolist())
            a, b = fast.step(q, w, target), slow.step(q, w, target)
            assert _close(a.rates_sp, b.rates_sp) and _close(a.torque_sp, b.torque_sp), f"step {k}"
            assert abs(a.thrust_sp - b.thrust_sp) <= TOL, f"step {k}"
            assert _close(a.allocation.outputs, b.allocation.outputs), f"step {k}"
            assert a.allocation.saturated_axes == b.allocation.saturated_axes, f"step {k}"
            f_max = v.rotors.thrust_max()
            assert all(abs(x - y) <= TOL * m for x, y, m in zip(a.rotor_thrusts_n, b.rotor_thrusts_n, f_max))
            assert _close(fast.rate_int, slow.rate_int), f"step {k}"
            steered += bool(np.any(fast._s[0]["sat_pos"]) or np.any(fast._s[0]["sat_neg"]))
        assert (any(fast.output.allocation.saturated_axes) and steered > 50) or scale < 1.0


def test_a_wrong_gain_is_seen(spec):
    """The comparison can fail: the reference with a rate P gain 1 % off leaves the tolerance
    within a few updates."""
    v = spec.vehicle
    fast = FlightController(v.flight_controller, v.rotors, spec.dt_s)
    off = FlightController(v.flight_controller, v.rotors, spec.dt_s)
    off.gain_p = tuple(1.01 * g for g in off.gain_p)
    slow = ref.ReferenceFlightController(off)
    rng = np.random.default_rng(4)
    target = AttitudeTarget(0, quat_wxyz=np.array(random_quat(rng)), rates_rad_s=np.zeros(3), thrust_normalized=0.5)
    q = random_quat(rng)
    worst = 0.0
    for _ in range(40):
        a, b = fast.step(q, (0.1, -0.2, 0.05), target), slow.step(q, (0.1, -0.2, 0.05), target)
        worst = max(worst, max(abs(x - y) for x, y in zip(a.torque_sp, b.torque_sp)))
    assert worst > 1e-4


def test_allocator_status_is_the_python_loops_saturation():
    """The compiled loops take the last allocation's saturation as the Python loops keep it
    (`_sat_pos`, `_sat_neg`): per axis, the allocation fell short and its unallocated command
    is above (below) +-1.2e-7; NaN on neither side."""
    s = fk.new_state()[0]
    values = [0.0, -0.0, 1.2e-7, -1.2e-7, np.nextafter(1.2e-7, 1.0), np.nextafter(-1.2e-7, -1.0), 0.3, -2.0, math.nan]
    rng = np.random.default_rng(5)
    for _ in range(400):
        unallocated = tuple(float(rng.choice(values)) for _ in range(4))
        for saturated in (False, True):
            fk.allocator_status(s, unallocated, saturated)
            pos = tuple(saturated and u > 1.2e-7 for u in unallocated[:3])
            neg = tuple(saturated and u < -1.2e-7 for u in unallocated[:3])
            assert tuple((s["sat_pos"] != 0.0).tolist()) == pos
            assert tuple((s["sat_neg"] != 0.0).tolist()) == neg


@pytest.mark.parametrize("name", ["two_am_comp_attitude", "two_am_comp"])
def test_the_warm_up_compiles_what_a_run_calls(name):
    """SitlCore.connect warms the simulator's kernels: a run afterwards adds no specialization
    (none is compiled at a lockstep's first steps), with [devices] on and in either mode."""
    from pathlib import Path

    from amcore import allocation_kernels
    from amcore.config import load_scenario
    from amcore.jit import kernels
    from simulator import device_kernels, fleet_kernels
    from simulator.core import warm_up_kernels
    from sitl.inprocess import run

    spec = load_scenario(Path(__file__).resolve().parents[2] / "configs" / "scenarios" / f"{name}.toml")
    spec = dataclasses.replace(spec, devices=dataclasses.replace(spec.devices, enabled=True))
    warm_up_kernels(spec)
    ks = [k for m in (fk, device_kernels, allocation_kernels, fleet_kernels) for k in kernels(m)]
    before = {k.py_func.__name__: len(k.signatures) for k in ks}
    run(spec, 0.2)
    assert {k.py_func.__name__: len(k.signatures) for k in ks} == before
