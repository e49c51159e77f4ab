"""The companion's per-phase error summary."""
from __future__ import annotations

import numpy as np
import pytest

from companion.outcome import Outcome


class _D:  # the Diagnostics fields the summary reads
    def __init__(self, r, eR, y, F):
        self.r_c_err, self.e_R, self.y_err, self.F_rc, self.sigma_min_J3 = (np.array(r), np.array(eR), np.array(y),
                                                                             np.array(F), 0.5)


def test_final_and_max_per_phase_and_hover_force_mean():
    o = Outcome(4, ("approach", "grasp", "hover"), hover_window=(2.0, 3.0))
    o.add(0.0, "approach", _D([0.3, 0, 0.4], [0, 0, 0], [0.1, -0.2, 0], [0, 0, 0]))
    o.add(1.0, "approach", _D([0.03, 0, 0.04], [0, 0.1, 0], [0.0, 0.05, 0], [0, 0, 0]))
    o.add(2.0, "hover", _D([0, 0, 0], [0, 0, 0], [0, 0, 0], [1, 0, -4]))
    o.add(3.0, "hover", _D([0, 0, 0], [0, 0, 0], [0, 0, 0], [3, 0, -6]))
    d = o.to_dict()
    ap = d["phases"]["approach"]
    assert ap["steps"] == 2
    assert ap["max"]["r_c_err"] == pytest.approx(0.5)
    assert ap["final"]["r_c_err"] == pytest.approx(0.05)
    assert ap["max"]["y_err"] == pytest.approx([0.1, 0.2, 0.0])
    assert ap["final"]["y_err"] == pytest.approx([0.0, 0.05, 0.0])  # signed final value
    assert d["phases"]["grasp"]["steps"] == 0
    assert d["hover_mean_F_W_n"] == pytest.approx([2.0, 0.0, -5.0])


def test_phase_stats_keep_final_values_and_largest_magnitudes_by_name():
    from companion.outcome import PhaseStats

    s = PhaseStats()
    s.add(0.0, {"a": -0.5, "v": np.array([1.0, -3.0]), "b": float("nan"), "w": [float("nan")]})
    s.add(0.1, {"a": 0.25, "v": [-2.0, 1.0], "b": 2.0, "w": [1.0]})
    d = s.to_dict()
    assert (d["steps"], d["t_first"], d["t_last"]) == (2, 0.0, 0.1)
    assert d["final"] == {"a": 0.25, "v": [-2.0, 1.0], "b": 2.0, "w": [1.0]}
    # a float's largest magnitude starts from 0 (a NaN there is passed over); a vector's from its first value
    assert d["max"]["a"] == 0.5 and d["max"]["v"] == [2.0, 3.0] and d["max"]["b"] == 2.0
    assert np.isnan(d["max"]["w"][0])
    with pytest.raises(ValueError):
        s.add(0.2, {"a": 1.0})
