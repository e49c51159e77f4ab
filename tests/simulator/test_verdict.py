"""The mission verdict from ground truth (simulator.verdict), on synthetic samples: each
criterion fails when, and only when, it should, names the time, and the most fundamental
failure comes first."""
from __future__ import annotations

from types import SimpleNamespace as NS

import numpy as np
import pytest

from amcore.config import SuccessCriteria
from simulator.outcome import RunOutcome
from simulator.verdict import FAILURE_CLASSES, judge

Z_REST = 0.6
C = SuccessCriteria()


def _gt(t, lift, touching=(), base_contacts=None, slip=0.0, p_WB=(1.0, 0.0, 1.0)):
    pad = NS(normal_force_n=5.0, tangential_force_W=np.zeros(3))
    ams = {}
    for s, side in ((4, -1.0), (5, 1.0)):
        p_WE = np.array([side * 0.1, slip if s == 4 else 0.0, Z_REST + lift])
        ams[s] = NS(p_WB=np.array(p_WB) * [side, 1, 1], R_WB=np.eye(3), p_WE=p_WE, R_WE=np.eye(3),
                    pad_object_contact=pad, base_contacts=tuple((base_contacts or {}).get(s, ())))
    obj = NS(p_WO=np.array([0.0, 0.0, Z_REST + lift]), quat_WO_wxyz=np.array([1.0, 0, 0, 0]), touching=tuple(touching))
    return NS(time_s=t, ams=ams, object=obj)


def _outcome(lift_of_t, duration=20.0, **kw_of_t):
    o = RunOutcome([4, 5], hover_window=(15.0, 20.0), slip_from_s=10.0)
    for t in np.arange(0.0, duration + 1e-9, 0.01):
        kw = {k: f(t) for k, f in kw_of_t.items()}
        o.add(_gt(float(t), lift_of_t(t), **kw), {4: np.zeros(6), 5: np.zeros(6)})
    return o


def _lift_profile(t):  # on the table until 10 s, up 0.3 m by 14 s
    return 0.0 if t < 10 else min(0.3, 0.3 * (t - 10) / 4)


def _touch_until_lifted(t):
    return ("table",) if t < 10 else ()


def test_a_clean_run_is_a_success():
    v = judge(_outcome(_lift_profile, touching=_touch_until_lifted), C, n_steps=20000)
    assert v.success and v.status == "success" and v.failure_class is None and v.text == "mission success"


def test_never_lifted_names_the_lift_in_the_hover_window():
    v = judge(_outcome(lambda t: 0.0, touching=lambda t: ("table",)), C, n_steps=20000)
    assert v.failure_class == "never lifted"
    assert "object never lifted to 20 cm (max 0.0 cm; 0.0 cm at t = 15-20 s)" in v.text


def test_an_object_that_came_down_was_dropped_at_that_time():
    lift = lambda t: _lift_profile(t) if t < 12.4 else 0.0  # noqa: E731
    v = judge(_outcome(lift, touching=lambda t: ("table",) if t < 10 or t >= 12.4 else ()), C, n_steps=20000)
    # 20 cm is first reached at 12.67 s > 12.4: it never got up, so it was never dropped
    assert v.failures[0].kind == "never lifted"
    lift = lambda t: _lift_profile(t) if t < 14.5 else 0.0  # noqa: E731
    v = judge(_outcome(lift, touching=lambda t: ("table",) if t < 10 or t >= 14.5 else ()), C, n_steps=20000)
    assert v.failure_class == "dropped" and "dropped at t = 14.50 s" in v.text


def test_up_but_never_off_the_table_is_never_lifted():
    v = judge(_outcome(_lift_profile, touching=lambda t: ("table",)), C, n_steps=20000)
    assert v.failure_class == "never lifted" and "never up and off the table" in v.text


def test_slip_beyond_the_limit_is_named_with_its_size_and_time():
    slip = lambda t: 0.0 if t < 12.0 else 0.054  # noqa: E731
    v = judge(_outcome(_lift_profile, touching=_touch_until_lifted, slip=slip), C, n_steps=20000)
    assert v.failure_class == "slipped"
    assert "slip 54 mm > 2 mm (am4's pad, beyond the limit from t = 12.00 s)" in v.text
    v = judge(_outcome(_lift_profile, touching=_touch_until_lifted, slip=lambda t: 0.0019 * (t > 12)), C, 20000)
    assert v.success  # under the limit


def test_base_contact_comes_before_what_it_causes():
    bc = lambda t: {5: ("table",)} if t >= 3.21 else {}  # noqa: E731
    v = judge(_outcome(lambda t: 0.0, touching=lambda t: ("table",), base_contacts=bc), C, n_steps=20000)
    assert [f.kind for f in v.failures] == ["base contact", "never lifted"]
    assert "base of am5 touched table at t = 3.21 s" in v.text


def test_a_base_far_away_or_a_nan_state_is_divergence():
    far = lambda t: (1.0, 0.0, 1.0) if t < 5 else (4.0, 0.0, 1.0)  # noqa: E731
    v = judge(_outcome(_lift_profile, touching=_touch_until_lifted, p_WB=far), C, n_steps=20000)
    assert v.failure_class == "diverged" and "diverged at t = 5.00 s" in v.text and "> 3 m" in v.text
    nan = lambda t: (1.0, 0.0, 1.0) if t < 5 else (np.nan, 0.0, 1.0)  # noqa: E731
    v = judge(_outcome(_lift_profile, touching=_touch_until_lifted, p_WB=nan), C, n_steps=20000)
    assert v.failure_class == "diverged" and "non-finite" in v.text
    v = judge(_outcome(_lift_profile, touching=_touch_until_lifted), C, 20000,
              controller_errors=[(7.5, 4, "LinAlgError: singular")])
    assert v.failure_class == "diverged" and "am4's controller failed at t = 7.50 s" in v.text


def test_failsafe_rejections_and_saturation_are_failures_of_their_own():
    o = _outcome(_lift_profile, touching=_touch_until_lifted)
    assert judge(o, C, 20000, failsafe_at_end=[5]).failure_class == "failsafe"
    v = judge(o, C, 20000, rejected=[(11.0, 4, "|thrust_n| = 200 > 96")] * 3)
    assert v.failure_class == "rejected setpoints" and "3 setpoint(s) rejected" in v.text
    o.ams[4].saturated_steps, o.ams[4].first_saturation_s = 1001, 10.3  # 5.005 % of 20000
    v = judge(o, C, 20000)
    assert v.failure_class == "saturated" and "5.0 % of the steps > 5 %" in v.text and "t = 10.30 s" in v.text
    o.ams[4].saturated_steps = 1000  # exactly 5 %: allowed
    assert judge(o, C, 20000).success


def test_a_run_cut_short_is_incomplete_unless_something_already_failed():
    o = _outcome(_lift_profile, duration=12.0, touching=_touch_until_lifted)
    v = judge(o, C, 12000)
    assert v.status == "incomplete" and not v.success and v.failure_class is None
    assert "ended at t = 12.00 s" in v.text
    bc = lambda t: {4: ("ground",)} if t >= 1.0 else {}  # noqa: E731
    o = _outcome(lambda t: 0.0, duration=3.0, base_contacts=bc)
    assert judge(o, C, 3000).status == "failed"


def test_failure_classes_come_in_the_documented_order():
    assert FAILURE_CLASSES == ("commanded", "failover", "diverged", "base contact", "never lifted", "dropped", "slipped",
                               "rejected setpoints", "failsafe", "saturated")


@pytest.mark.parametrize("criteria,expect", [
    (SuccessCriteria(min_lift_m=0.35), "never lifted"),
    (SuccessCriteria(max_slip_m=0.0), None),  # no slip at all: 0 is not > 0
    (SuccessCriteria(max_distance_m=0.5), "diverged"),
])
def test_criteria_come_from_the_scenario(criteria, expect):
    v = judge(_outcome(_lift_profile, touching=_touch_until_lifted), criteria, n_steps=20000)
    assert v.failure_class == expect


def test_a_failover_is_named_first_after_a_command_with_its_return():
    """Free-running: a vehicle taken out of OFFBOARD (a PX4 failsafe, a mode another client asked
    for) fails a mission that otherwise met every criterion; the first one is named, with the
    time a companion engaged it again, and how many there were."""
    ok = judge(_outcome(_lift_profile, touching=_touch_until_lifted), C, n_steps=20000)
    assert ok.success
    v = judge(_outcome(_lift_profile, touching=_touch_until_lifted), C, n_steps=20000,
              failovers=[(3.5, 5, "failsafe: offboard signal lost", 6.25), (-1.0, 4, "HOLD asked for", None)])
    assert v.status == "failed" and v.failure_class == "failover"
    assert v.failures[0].t_s == -1.0 and "am4 left OFFBOARD at t = -1.00 s (HOLD asked for) (2 in all)" in v.text
    back = judge(_outcome(_lift_profile, touching=_touch_until_lifted), C, n_steps=20000,
                 failovers=[(3.5, 5, "failsafe: offboard signal lost", 6.25)])
    assert "engaged again at t = 6.25 s" in back.text
