"""The grasp mission's references for any task the paper covers (amcore.mission.am_mission):
y_d has one entry per [task].components, in their order; "x" approaches and squeezes, "z"
carries the start height and the lift, every other component holds the nominal pose's value;
the CoM path does not depend on the components. Checked over 2-, 3-, 4-, 5- and 6-component
tasks in every order."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amcore.config import grasped_face, load_scenario
from amcore.mission import am_mission, nominal_geometry, squeeze_plan
from amcore.model import build_model
from amcore.task import angle_of

ROOT = Path(__file__).resolve().parents[2]
OTHERS = ("y", "roll", "pitch", "yaw")


@pytest.fixture(scope="module")
def paper():
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    return spec, build_model(spec.vehicle)


def _with_task(spec, components):
    """The scenario with [task].components replaced; each component's K_y, D_y as the paper's for
    its kind (position: x's, angle: pitch's), so that the squeeze (K_y,x) is the paper's."""
    g = spec.vehicle.gains
    k = {c: (g.K_y[0], g.D_y[0]) if c in ("x", "y", "z") else (g.K_y[2], g.D_y[2]) for c in components}
    gains = dataclasses.replace(g, K_y=tuple(k[c][0] for c in components), D_y=tuple(k[c][1] for c in components))
    v = dataclasses.replace(spec.vehicle, task=dataclasses.replace(spec.vehicle.task, components=tuple(components)),
                            gains=gains)
    return dataclasses.replace(spec, vehicle=v)


tasks = st.lists(st.sampled_from(OTHERS), unique=True, max_size=4).flatmap(
    lambda extra: st.permutations(["x", "z", *extra]))


@settings(max_examples=30, deadline=None)
@given(components=tasks)
def test_references_follow_the_components(paper, components):
    spec, model = paper
    n = len(components)
    assert 2 <= n <= 6
    s = _with_task(spec, components)
    ms = s.mission
    geo = nominal_geometry(model)
    ref3 = am_mission(_with_task(spec, ("x", "z", "pitch")), s.ams[0], model)
    for am in s.ams:
        m = am_mission(s, am, model)
        _, half = grasped_face(s, am)
        depth = squeeze_plan(s, model).depth_m
        ix, iz = components.index("x"), components.index("z")
        expect = {  # (t, x, z) at the start and at the end of each phase
            0.0: (-(half + ms.standoff_m), ms.start_height_m),
            ms.approach_end_s: (-(half + ms.pre_gap_m), 0.0),
            ms.grasp_end_s: (-(half - depth), 0.0),
            ms.hover_end_s: (-(half - depth), ms.lift_m),
        }
        nominal = {"y": geo.p_BE[1] - geo.r_BC[1], **{c: angle_of(geo.R_BE, c) for c in ("roll", "pitch", "yaw")}}
        r3 = am_mission(_with_task(spec, ("x", "z", "pitch")), am, model)
        for t, (x, z) in expect.items():
            r = m.reference(t)
            assert r.y.shape == (n,) and r.y_d1.shape == (n,) and r.y_d2.shape == (n,)
            assert r.y[ix] == pytest.approx(x, abs=1e-12) and r.y[iz] == pytest.approx(z, abs=1e-12)
            np.testing.assert_allclose(r.y_d1, 0.0, atol=1e-12)  # at rest at every phase's end
            for i, c in enumerate(components):
                if c not in ("x", "z"):
                    assert r.y[i] == pytest.approx(nominal[c], abs=1e-12), c
            np.testing.assert_allclose(r.r_c, r3.reference(t).r_c, atol=1e-12)  # the CoM path is the task's own
        for t in np.linspace(0.0, ms.hover_end_s, 23):  # in between: x and z as the paper's task, the rest still
            r, p = m.reference(t), r3.reference(t)
            assert r.y[ix] == pytest.approx(p.y[0], abs=1e-12) and r.y[iz] == pytest.approx(p.y[1], abs=1e-12)
            for i, c in enumerate(components):
                if c not in ("x", "z"):
                    assert r.y[i] == pytest.approx(nominal[c], abs=1e-12) and r.y_d1[i] == 0.0
    assert ref3.reference(0.0).y[2] == pytest.approx(geo.pitch_rad)


@pytest.mark.parametrize("components", [("x", "z"), ("x", "z", "pitch"), ("x", "z", "pitch", "roll"),
                                        ("x", "y", "z", "roll", "pitch", "yaw")], ids="-".join)
def test_two_three_four_and_six_components(paper, components):
    """The sizes the issue names, each once without hypothesis (same properties, the first AM):
    the pad comes to the face, squeezes and lifts; the rest holds."""
    spec, model = paper
    s = _with_task(spec, components)
    m = am_mission(s, s.ams[0], model)
    a, g, h = m.phase_ends_s
    y = np.array([m.reference(t).y for t in (0.0, a, g, h)])
    ix, iz = components.index("x"), components.index("z")
    assert y[0, ix] < y[1, ix] < y[2, ix] == y[3, ix]  # towards the object, then into it
    assert y[0, iz] > y[1, iz] == y[2, iz] < y[3, iz]  # down to the grasp height, then the lift
    rest = [i for i, c in enumerate(components) if c not in ("x", "z")]
    assert np.ptp(y[:, rest], axis=0).max(initial=0.0) == 0.0
