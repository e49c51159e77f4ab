"""Pilot: a companion started during a run joins the mission from where its vehicle is."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from amcore.config import load_scenario
from amlink.types import sensor_frame_from_wire
from companion.pilot import Pilot

from ..conftest import SCENARIO


def _frame(step: int, t: float, state, psi: float):
    quat = [math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2)]  # the state's R_WB = Rz(psi)
    values = [*state.p_WB, *quat, *state.v_B, *state.w_B, *state.q, *state.qdot, *[0.0] * 6]
    return sensor_frame_from_wire(step, t, values, len(state.q), 0)


@pytest.fixture(scope="module")
def spec():
    return load_scenario(SCENARIO)


def test_restarted_pilot_holds_its_vehicle_where_it_is_then_joins_the_mission(spec):
    """The vehicle hovers where the mission started (held there by a failsafe) while the
    mission is 3 s on: the restarted pilot's first command holds it (zero errors, thrust
    ~ m g) instead of commanding the mission's jump, and its references are the mission's
    again [mission].join_blend_s later."""
    p = Pilot(spec, 4)
    x0 = p.mission.initial_state()
    t0 = 3.0
    _, _, res = p.command(_frame(3000, t0, x0, p.mission.psi))
    d = res.diagnostics
    assert np.linalg.norm(p.mission.reference(t0).r_c - p.mission.reference(0.0).r_c) > 0.1  # far from the mission
    np.testing.assert_allclose(d.r_c_err, 0.0, atol=1e-9)
    np.testing.assert_allclose(d.y_err, 0.0, atol=1e-9)
    m_g = p.model.mass_kg * p.model.gravity_mps2
    assert abs(res.command.thrust_n - m_g) < 0.05 * m_g
    fresh = Pilot(spec, 4)  # what a pilot without the blend would command from the same state
    fresh._started = True
    _, _, jump = fresh.command(_frame(3000, t0, x0, p.mission.psi))
    assert np.linalg.norm(jump.command.tau_q_nm) > 10 * np.linalg.norm(res.command.tau_q_nm)
    t1 = t0 + spec.mission.join_blend_s
    mission = p.mission.reference(t1)
    assert p._blend.apply(mission, t1) is mission


def test_join_blend_references_are_smooth(spec):
    """C3 as eq. Rd needs: each blended derivative is the finite difference of the one below."""
    p = Pilot(spec, 4)
    x0 = p.mission.initial_state()
    p.command(_frame(1500, 1.5, x0, p.mission.psi))

    def ref(t):
        return p._blend.apply(p.mission.reference(t), t)

    h = 1e-5
    for t in (1.5 + 1e-3, 2.2, 3.9, 4.49):
        a, b, c = ref(t - h), ref(t), ref(t + h)
        for lo, hi in (("r_c", "r_c_d1"), ("r_c_d1", "r_c_d2"), ("r_c_d2", "r_c_d3"), ("r_c_d3", "r_c_d4"),
                       ("y", "y_d1"), ("y_d1", "y_d2")):
            fd = (getattr(c, lo) - getattr(a, lo)) / (2 * h)
            np.testing.assert_allclose(fd, getattr(b, hi), rtol=1e-4, atol=1e-4 * (1 + np.abs(getattr(b, hi)).max()))


def test_pilot_started_with_the_run_uses_the_mission_as_it_is(spec):
    p = Pilot(spec, 4)
    x0 = p.mission.initial_state()
    p.command(_frame(0, 0.0, x0, p.mission.psi))
    assert p._blend is None


def test_join_blend_duration_comes_from_the_scenario(spec):
    """[mission].join_blend_s sets when a restarted pilot's references are the mission's again."""
    short = dataclasses.replace(spec, mission=dataclasses.replace(spec.mission, join_blend_s=0.5))
    p = Pilot(short, 4)
    x0 = p.mission.initial_state()
    p.command(_frame(3000, 3.0, x0, p.mission.psi))
    inside = p._blend.apply(p.mission.reference(3.4), 3.4)
    assert np.linalg.norm(inside.r_c - p.mission.reference(3.4).r_c) > 1e-3  # still blending at 0.4 s
    after = p.mission.reference(3.5)
    assert p._blend.apply(after, 3.5) is after  # done at 0.5 s, where the default (3 s) would not be


def test_pilot_flies_the_law_its_scenario_names(spec):
    """[options].controller picks the law; both answer the same frame with setpoints of the same
    shapes, and the baseline's diagnostics carry what the outcome summary and telemetry read."""
    from amcore import baseline, control
    from amcore.config import load_scenario
    from companion.outcome import Outcome
    from telemetry.schema import controller_sample

    from ..conftest import ROOT

    paper = Pilot(spec, 4)
    base = Pilot(load_scenario(ROOT / "configs" / "scenarios" / "two_am_baseline.toml"), 4, model=paper.model)
    assert paper.law is control.step and isinstance(paper.params, control.ControllerParams)
    assert base.law is baseline.step and isinstance(base.params, baseline.BaselineParams)
    x0 = paper.mission.initial_state()
    frame = _frame(0, 0.0, x0, paper.mission.psi)
    (sp_p, att_p, res_p), (sp_b, att_b, res_b) = paper.command(frame), base.command(frame)
    m_g = paper.model.mass_kg * paper.model.gravity_mps2
    for sp, att in ((sp_p, att_p), (sp_b, att_b)):
        assert sp.thrust_n == pytest.approx(m_g, rel=1e-3)  # both hold the vehicle at rest on the reference
        np.testing.assert_allclose(att.quat_wxyz, att_p.quat_wxyz, atol=1e-6)
        assert sp.tau_q_nm.shape == sp_p.tau_q_nm.shape
    np.testing.assert_allclose(sp_b.tau_q_nm, sp_p.tau_q_nm, atol=1e-6)  # gravity compensation, both
    base.record(0.0, res_b)
    assert base.summary()["phases"]["approach"]["steps"] == 1
    Outcome(4, ("approach",), (0.0, 1.0)).add(0.0, "approach", res_b.diagnostics)
    sample = controller_sample(0.0, "approach", res_b.diagnostics, res_b.command)
    assert sample.keys() == controller_sample(0.0, "approach", res_p.diagnostics, res_p.command).keys()


@pytest.mark.parametrize("phase_t, moves", [(7.0, True), (12.0, False)])
def test_lateral_admittance_gives_way_to_the_pads_push_in_the_grasp_phase_only(phase_t, moves):
    """[options].lateral_admittance_hz: a pad squeezing with 11 N and pushing the object with
    1 N along {e}'s y moves the CoM reference back along the task frame's y while the pads
    squeeze the object on the table; from the lift on the same push moves nothing."""
    from ..conftest import ROOT

    base = load_scenario(ROOT / "configs" / "scenarios" / "two_am_robust.toml")
    opts = dataclasses.replace(base.vehicle.options, lateral_admittance_hz=0.3, heading_admittance_hz=0.0)
    spec = dataclasses.replace(base, vehicle=dataclasses.replace(base.vehicle, options=opts))
    p = Pilot(spec, 4)
    x0 = p.mission.initial_state()
    y_W = p.mission.frame.R_WT[:, 1]
    dt = spec.control_dt_s
    shift = []
    for k in range(1500):
        t = phase_t + k * dt
        values = [*x0.p_WB, 1.0, 0.0, 0.0, 0.0, *x0.v_B, *x0.w_B, *x0.q, *x0.qdot, -11.0, -1.0, 0.0, 0.0, 0.0, 0.0]
        _, _, res = p.command(sensor_frame_from_wire(k, t, values, len(x0.q), 0))
        shift.append(float(y_W @ (res.diagnostics.r_c_d - p.mission.reference(t).r_c)))
    if moves:
        assert shift[-1] < -1e-3  # > 1 mm back, against the push
        assert all(b <= a + 1e-12 for a, b in zip(shift, shift[1:]))  # monotonic: no overshoot
    else:
        assert max(abs(s) for s in shift) < 1e-12


@pytest.mark.parametrize("phase_t, moves", [(4.0, True), (7.0, False)])
def test_trim_moves_the_com_reference_against_a_steady_offset_in_the_approachs_hover_only(phase_t, moves):
    """[options].trim_hz: a vehicle held 5 mm off its CoM reference (along world y) in the
    approach's hover moves the reference the other way; in the grasp phase the same offset
    moves nothing (the trim is held)."""
    from ..conftest import ROOT

    base = load_scenario(ROOT / "configs" / "scenarios" / "two_am_robust.toml")
    opts = dataclasses.replace(base.vehicle.options, trim_hz=0.3, heading_admittance_hz=0.0,
                               lateral_admittance_hz=0.0)
    spec = dataclasses.replace(base, vehicle=dataclasses.replace(base.vehicle, options=opts))
    p = Pilot(spec, 4)
    x0 = p.mission.initial_state()
    dt = spec.control_dt_s
    p.command(_frame(0, 0.0, x0, p.mission.psi))  # started with the run: no join blend
    shift = []
    for k in range(1, 500):
        t = phase_t + k * dt
        r = p.mission.reference(t).r_c - p.mission.reference(0.0).r_c  # where the mission has moved the CoM
        values = [*(x0.p_WB + r + [0.0, 0.005, 0.0]), 1.0, 0.0, 0.0, 0.0, *x0.v_B, *x0.w_B, *x0.q, *x0.qdot,
                  0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        _, _, res = p.command(sensor_frame_from_wire(k, t, values, len(x0.q), 0))
        shift.append(res.diagnostics.r_c_d - p.mission.reference(t).r_c)
    if moves:
        assert shift[-1][1] < -1e-3  # > 1 mm the other way
        assert shift[-1][2] == 0.0
    else:
        assert max(np.abs(s).max() for s in shift) < 1e-12


def test_the_baseline_flies_two_am_robust_without_the_wrist_sensor_admittances():
    """The heading and lateral admittances are driven by the wrist sensor, which the baseline
    ignores: under it they are off whatever [options] says (the baseline's step takes no turned
    task frame), and the trim, which reads the CoM error both laws give, stays on."""
    from amcore import baseline
    from amcore.config import read_scenario, scenario_from_dict
    from trials.cli import apply_overrides

    from ..conftest import ROOT

    robust = ROOT / "configs" / "scenarios" / "two_am_robust.toml"
    paper = Pilot(load_scenario(robust), 4)
    assert paper.heading is not None and paper.lateral is not None and paper.trim is not None
    spec_b = scenario_from_dict(apply_overrides(read_scenario(robust), ['options.controller="baseline"']), robust)
    base = Pilot(spec_b, 4, model=paper.model)
    assert base.law is baseline.step
    assert base.heading is None and base.lateral is None and base.trim is not None
    x0 = base.mission.initial_state()
    for k, t in enumerate((0.0, 0.001, 6.0)):  # the approach and the grasp, where the admittances would act
        sp, _, res = base.command(_frame(k, t, x0, base.mission.psi))
        assert np.isfinite(sp.thrust_n) and np.all(np.isfinite(sp.tau_q_nm))
