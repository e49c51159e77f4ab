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
