"""Heading and lateral admittance (amcore.adapt) and squeeze sizing (amcore.mission.squeeze_plan)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from amcore.adapt import (Trim, adapted, trim_reference, trim_update, HeadingAdmittance, HeadingState, LateralAdmittance,
                          LateralState, heading_update, lateral_update, misalignment)

from . import reference_adapt
from .reference_adapt import shift_reference, turn_frame, turn_reference
from amcore.config import load_scenario
from amcore.control import Reference
from amcore.mission import am_mission, squeeze_plan
from amcore.model import build_model
from amcore.so3 import Rz
from amcore.task import TaskFrame

from ..conftest import SCENARIO

ADM = HeadingAdmittance(omega_rad_s=2.0 * math.pi * 0.3, zeta=1.0, crown_radius_m=0.05)


def _crown_wrench(delta, normal=9.0, friction_y=0.0):
    """The wrench a flat face exerts on a crowned pad turned by delta, on {e}."""
    R = ADM.crown_radius_m
    y_c, x_c = R * math.sin(delta), -R * (1.0 - math.cos(delta))
    f = np.array([-normal, friction_y, 2.0])
    m = np.cross([x_c, y_c, 0.0], f)
    return np.concatenate([f, m])


@pytest.mark.parametrize("delta_deg", [-5.0, -0.1, 0.0, 2.0, 5.0])
def test_the_crown_shows_the_misalignment(delta_deg):
    d = math.radians(delta_deg)
    assert misalignment(ADM, _crown_wrench(d)) == pytest.approx(d, abs=1e-12)
    # lateral friction moves the estimate by R (1 - cos delta) f_y / N only
    assert misalignment(ADM, _crown_wrench(d, friction_y=2.0)) == pytest.approx(d, abs=1e-3)  # 0.06 deg


def test_out_of_contact_nothing_is_measured_and_the_heading_only_settles():
    assert misalignment(ADM, _crown_wrench(0.05, normal=1.0)) is None
    s = heading_update(ADM, HeadingState(0.1, 0.2), np.zeros(6), 0.001)
    assert s.dpsi_d2 == pytest.approx(-2.0 * ADM.omega_rad_s * 0.2)


def test_in_closed_loop_the_heading_settles_on_the_face_critically_damped():
    delta, dt = math.radians(4.0), 0.001
    s, trace = HeadingState(), []
    for _ in range(int(6.0 / dt)):
        s = heading_update(ADM, s, _crown_wrench(delta - s.dpsi), dt)  # turning reduces what the crown shows
        trace.append(s.dpsi)
    assert s.dpsi == pytest.approx(delta, rel=1e-3)
    assert max(trace) <= delta * (1 + 1e-6)  # critically damped: no overshoot


def test_turning_keeps_the_contact_point_and_turns_frame_and_heading_together():
    pivot = np.array([-0.1, 0.02, 0.6])
    frame = TaskFrame(R_WT=Rz(0.3), p_WT=np.array([0.0, 0.0, 0.6]))
    s = HeadingState(dpsi=0.05, dpsi_d1=0.01, dpsi_d2=-0.02)
    turned = turn_frame(frame, s, pivot)
    assert turned.R_WT == pytest.approx(Rz(0.35))
    # the pivot has the same coordinates in both frames' horizontal plane
    in_old = frame.R_WT.T @ (pivot - frame.p_WT)
    in_new = turned.R_WT.T @ (pivot - turned.p_WT)
    assert in_new == pytest.approx(in_old)
    z = np.zeros(3)
    ref = Reference(np.array([-0.4, 0.0, 0.7]), np.array([0.1, 0, 0]), z, z, z, 0.3, 0.0, 0.0, z, z, z)
    r = turn_reference(ref, s, pivot)
    assert r.psi == pytest.approx(0.35) and r.psi_d1 == 0.01 and r.psi_d2 == -0.02
    assert np.linalg.norm(r.r_c - pivot) == pytest.approx(np.linalg.norm(ref.r_c - pivot))
    assert r.r_c_d1 == pytest.approx(Rz(0.05) @ ref.r_c_d1)


LAT = LateralAdmittance(omega_rad_s=2.0 * math.pi * 0.3, zeta=1.0, stiffness_n_per_m=80.0)


def _pad_wrench(push_y, normal=11.0):
    """The wrench on a pad that squeezes with `normal` and pushes the object along {e}'s y
    with push_y (the object pushes back: -push_y on the pad)."""
    return np.array([-normal, -push_y, 0.0, 0.0, 0.0, 0.0])


def test_lateral_admittance_nulls_an_internal_push_without_overshoot():
    """A pad stuck to the object: the AM pushes along the face with K (e + dy) for its share e
    of the disagreement; the reference shift settles on -e and the push on zero."""
    e, dt = 0.004, 0.001
    s, trace = LateralState(), []
    for _ in range(int(6.0 / dt)):
        s = lateral_update(LAT, s, _pad_wrench(LAT.stiffness_n_per_m * (e + s.dy)), dt)
        trace.append(s.dy)
    assert s.dy == pytest.approx(-e, rel=1e-3)
    assert s.push_n == pytest.approx(0.0, abs=1e-3 * LAT.stiffness_n_per_m * e)
    assert min(trace) >= -e * (1 + 1e-6)  # critically damped: no overshoot


def test_lateral_admittance_moves_only_in_contact_and_stays_within_its_bound():
    s = lateral_update(LAT, LateralState(0.01, 0.002), _pad_wrench(5.0, normal=1.0), 0.001)
    assert s.dy_d2 == pytest.approx(-2.0 * LAT.omega_rad_s * 0.002)  # out of contact: damping only
    s = LateralState()
    for _ in range(20000):  # a push no shift can relieve (the object is held elsewhere)
        s = lateral_update(LAT, s, _pad_wrench(30.0), 0.001)
    assert abs(s.dy) == LAT.max_shift_m and s.dy_d1 == 0.0


def test_the_shift_moves_the_com_path_along_the_axis_and_nothing_else():
    axis = np.array([0.0, 1.0, 0.0])
    ref = Reference(np.array([0.1, 0.2, 0.9]), np.ones(3), np.ones(3), np.ones(3), np.ones(3), 0.3, 0.1, 0.0,
                    np.zeros(3), np.zeros(3), np.zeros(3))
    out = shift_reference(ref, LateralState(0.003, 0.001, -0.002), axis)
    np.testing.assert_allclose(out.r_c - ref.r_c, 0.003 * axis)
    np.testing.assert_allclose(out.r_c_d1 - ref.r_c_d1, 0.001 * axis)
    np.testing.assert_allclose(out.r_c_d2 - ref.r_c_d2, -0.002 * axis)
    assert out.r_c_d3 is ref.r_c_d3 and out.psi == ref.psi and out.y is ref.y
    assert shift_reference(ref, LateralState(), axis) is ref


def test_squeeze_sizing_holds_the_share_with_the_margin_within_the_thrust():
    spec = load_scenario(SCENARIO)
    model = build_model(spec.vehicle)
    k_x = spec.vehicle.gains.K_y[0]
    off = squeeze_plan(spec, model)
    assert off.force_n == pytest.approx(k_x * spec.mission.squeeze_m) and off.depth_m == spec.mission.squeeze_m
    on = dataclasses.replace(spec, mission=dataclasses.replace(spec.mission, squeeze_sizing=True))
    g = spec.vehicle.gravity_mps2
    p = squeeze_plan(on, model)
    assert p.required_n == pytest.approx(1.5 * 1.0 * g / 2 / 0.5)
    assert p.force_n == pytest.approx(p.required_n) and p.depth_m == pytest.approx(p.required_n / k_x)
    heavy = dataclasses.replace(on, object=dataclasses.replace(on.object, mass_kg=2.0))
    h = squeeze_plan(heavy, model)
    thrust = 0.8 * 4 * spec.vehicle.rotors.thrust_max_n
    assert h.force_n == pytest.approx(h.feasible_n) and h.feasible_n < h.required_n
    assert math.hypot(h.force_n, model.mass_kg * g + 2.0 * g / 2) == pytest.approx(thrust)
    light = dataclasses.replace(on, object=dataclasses.replace(on.object, mass_kg=0.3))
    assert squeeze_plan(light, model).force_n == pytest.approx(k_x * spec.mission.squeeze_m)  # never below fixed
    mission = am_mission(on, on.am(4), model)
    assert mission.reference(on.mission.grasp_end_s).y[0] == pytest.approx(-(0.1 - p.depth_m))


def test_squeeze_sizing_stops_at_the_missions_cap_but_never_below_the_fixed_squeeze():
    spec = load_scenario(SCENARIO)
    model = build_model(spec.vehicle)
    k_x = spec.vehicle.gains.K_y[0]
    on = dataclasses.replace(spec, mission=dataclasses.replace(spec.mission, squeeze_sizing=True, squeeze_max_n=12.0))
    p = squeeze_plan(on, model)
    assert p.required_n > 12.0 and p.force_n == pytest.approx(12.0) and p.depth_m == pytest.approx(12.0 / k_x)
    low = dataclasses.replace(on, mission=dataclasses.replace(on.mission, squeeze_max_n=1.0))
    assert squeeze_plan(low, model).force_n == pytest.approx(k_x * spec.mission.squeeze_m)


def test_touch_align_squeeze_presses_the_touch_force_holds_it_then_squeezes():
    spec = load_scenario(SCENARIO)
    model = build_model(spec.vehicle)
    ms = dataclasses.replace(spec.mission, touch_force_n=2.0, touch_hold_s=1.0, grasp_move_s=1.5)
    touch = dataclasses.replace(spec, mission=ms)
    k_x = spec.vehicle.gains.K_y[0]
    plain = am_mission(dataclasses.replace(spec, mission=dataclasses.replace(ms, touch_force_n=0.0, touch_hold_s=0.0)),
                       spec.am(4), model)
    m = am_mission(touch, touch.am(4), model)
    t_a = ms.approach_end_s
    squeezed = plain.reference(t_a + ms.grasp_move_s).y[0]  # one move to the squeeze
    face = squeezed - squeeze_plan(spec, model).depth_m  # the face's x in {t}
    for t in (t_a + ms.grasp_move_s, t_a + ms.grasp_move_s + ms.touch_hold_s):  # touching, held
        assert m.reference(t).y[0] == pytest.approx(face + 2.0 / k_x)  # 2 N through K_y,x
        assert np.allclose(m.reference(t).y_d1, 0.0)
    end = t_a + 2 * ms.grasp_move_s + ms.touch_hold_s
    assert m.reference(end).y[0] == pytest.approx(squeezed)  # then the full squeeze
    assert m.reference(t_a + 0.5 * ms.grasp_move_s).r_c == pytest.approx(plain.reference(t_a + 0.5 * ms.grasp_move_s).r_c)


@pytest.mark.parametrize("mission,words", [
    ({"touch_force_n": 2.0}, "touch_force_n and touch_hold_s go together"),
    ({"touch_force_n": -1.0, "touch_hold_s": 1.0}, "touch_force_n: must be >= 0"),
    ({"touch_force_n": 2.0, "touch_hold_s": 2.0}, "must fit in the grasp phase"),
])
def test_touch_options_are_checked_naming_the_key(tmp_path, mission, words):
    from amcore.config import ConfigError, read_scenario, scenario_from_dict

    data = read_scenario(SCENARIO)
    data["mission"].update(mission)
    with pytest.raises(ConfigError, match=words):
        scenario_from_dict(data, SCENARIO)


def _hover_with_trim(F, trim, K=60.0, D=25.0, m=2.5, dt=0.004, T=6.0, speed=0.0):
    """A CoM held by the law's PD (stiffness K, damping D) against a steady force F, the trim
    moving its reference: (shift, error against the planned reference) over time."""
    x, v, dr = np.zeros(3), np.zeros(3), np.zeros(3)
    out = []
    for _ in range(int(T / dt)):
        err = x - dr  # the law's error against the moved reference (planned reference: 0)
        v = v + dt * (-K * err - D * v + F) / m
        x = x + dt * v
        dr = trim_update(trim, dr, x - dr, speed, dt)
        out.append((dr.copy(), x.copy()))
    return out


def test_the_trim_cancels_a_steady_horizontal_force_and_leaves_the_vertical_alone():
    """A tilted thrust's 0.27 N sideways (a 9 mrad roll bias at 30 N) and 0.5 N up: the trim
    settles on -F / K horizontally, so the CoM comes back onto the planned reference there;
    the vertical is not its business."""
    F, K = np.array([0.0, 0.27, 0.5]), 60.0
    run = _hover_with_trim(F, Trim(2.0 * math.pi * 0.3), K=K)
    dr, x = run[-1]
    np.testing.assert_allclose(dr[:2], -F[:2] / K, atol=2e-5)
    assert abs(x[1]) < 2e-5  # horizontally on the planned reference (4.5 mm off without the trim)
    assert dr[2] == 0.0 and x[2] == pytest.approx(F[2] / K, rel=1e-3)


def test_the_trim_holds_while_the_reference_moves_and_stays_within_its_bound():
    F = np.array([3.0, 0.0, 0.0])
    moving = _hover_with_trim(F, Trim(2.0 * math.pi * 0.3), speed=0.05, T=1.0)
    assert not any(dr.any() for dr, _ in moving)
    bounded = _hover_with_trim(F, Trim(2.0 * math.pi * 0.3, max_shift_m=0.01))
    assert max(np.linalg.norm(dr) for dr, _ in bounded) <= 0.01 + 1e-12


def test_the_trim_moves_the_com_path_and_nothing_else():
    ref = Reference(*(np.full(3, float(k)) for k in range(len(Reference._fields))))
    moved = trim_reference(ref, np.array([0.001, -0.002, 0.0]))
    np.testing.assert_allclose(moved.r_c, ref.r_c + [0.001, -0.002, 0.0])
    for name in Reference._fields[1:]:
        assert np.array_equal(getattr(moved, name), getattr(ref, name))
    assert trim_reference(ref, np.zeros(3)) is ref


# ----------------------------------------------------------------- the three together, compiled
def _random_case(rng, heading_on, lateral_on, trim_on, at_rest):
    """A mission reference and frame, and option states drawn at random (at_rest: the
    admittances' states zero, as before the first contact)."""
    rows = rng.normal(size=(5, 3))
    y = rng.normal(size=(3, 3))
    ref = Reference(*rows, *rng.normal(size=3), *y)
    psi = rng.uniform(-math.pi, math.pi)
    frame = TaskFrame(R_WT=Rz(psi), p_WT=rng.normal(size=3))
    dr = np.array([*rng.normal(scale=0.01, size=2), 0.0]) if trim_on else np.zeros(3)
    h = HeadingState() if at_rest else HeadingState(*rng.normal(scale=0.1, size=3), 0.0)
    s = LateralState() if at_rest else LateralState(*rng.normal(scale=0.005, size=3), 0.0)
    return ref, frame, dr, (h if heading_on else None), rng.normal(size=3), (s if lateral_on else None)


@pytest.mark.parametrize("heading_on", [False, True])
@pytest.mark.parametrize("lateral_on", [False, True])
@pytest.mark.parametrize("trim_on", [False, True])
def test_the_compiled_shaping_gives_its_references_numbers_to_rounding(heading_on, lateral_on, trim_on):
    """amcore.adapt.adapted (amcore.law.adapted_reference) against its reference
    (tests/amcore/reference_adapt.py: trim_reference, turn_reference, turn_frame and
    shift_reference applied in turn): every reference field and the task frame (with its H_TW
    and e_y_W) within 1e-15 of the path's scale, on 40 random cases each."""
    rng = np.random.default_rng(2831)
    for k in range(40):
        case = _random_case(rng, heading_on, lateral_on, trim_on, at_rest=False)
        fast, fast_frame = adapted(*case)
        slow, slow_frame = reference_adapt.adapted(*case)
        for a, b in zip(fast, slow):
            np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-15 * 10)
        if not heading_on:
            assert fast_frame is None and slow_frame is None
            continue
        np.testing.assert_allclose(fast_frame.R_WT, slow_frame.R_WT, rtol=0.0, atol=1e-15)
        np.testing.assert_allclose(fast_frame.p_WT, slow_frame.p_WT, rtol=0.0, atol=1e-14)
        fresh = TaskFrame(R_WT=fast_frame.R_WT, p_WT=fast_frame.p_WT)  # its properties computed anew
        np.testing.assert_array_equal(fast_frame.e_y_W, fresh.e_y_W)
        np.testing.assert_allclose(fast_frame.H_TW, fresh.H_TW, rtol=0.0, atol=1e-14)


def test_the_compiled_shaping_leaves_what_the_functions_leave_bit_for_bit():
    """With the admittances at rest and no trim, the reference comes back unchanged and the task
    frame is the mission's own (its cached H_TW reused); a trim alone adds exactly dr."""
    rng = np.random.default_rng(2832)
    ref, frame, dr, h, pivot, s = _random_case(rng, True, True, False, at_rest=True)
    out, task_frame = adapted(ref, frame, dr, h, pivot, s)
    assert task_frame is frame
    for a, b in zip(out, ref):
        np.testing.assert_array_equal(a, b)
    dr = np.array([0.01, -0.02, 0.0])
    out, _ = adapted(ref, frame, dr, h, pivot, s)
    np.testing.assert_array_equal(out.r_c, ref.r_c + dr)
    # a heading turned by zero with a rate: the path turns (by the identity), the frame stays
    out, task_frame = adapted(ref, frame, np.zeros(3), HeadingState(0.0, 0.01), pivot, None)
    assert task_frame is frame and out.psi_d1 == ref.psi_d1 + 0.01
