"""A companion restarted while its pad holds the object ([mission].resume_contact_force):
it resumes the push its wrist sensor reads, and the object stays up; starting from zero
squeeze, it lets the object fall. In-process, two_am_short: at t = 6 s, in the hover,
companion 5 is replaced by a fresh Pilot, as when a killed companion is restarted within
the step timeout (the lockstep waits for it, so no simulated time passes)."""
from __future__ import annotations

import copy
from pathlib import Path

import pytest

from amcore.config import read_scenario, scenario_from_dict
from companion.pilot import Pilot
from simulator.core import SitlCore
from sitl.inprocess import as_on_the_wire

SHORT = Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_short.toml"


def _restart_run(resume: bool) -> dict:
    data = copy.deepcopy(read_scenario(SHORT))
    data["mission"]["resume_contact_force"] = resume  # the default is true
    spec = scenario_from_dict(data, SHORT)
    core = SitlCore(spec)
    pilots = {s: Pilot(spec, s, model=core.model) for s in core.sysids}
    core.connect()
    try:
        for k in range(int(spec.duration_s * spec.rate_hz)):
            if k == 6000:  # t = 6 s: the restarted process
                pilots[5] = Pilot(spec, 5, model=core.model)
            frames = core.frames(k)
            core.actuate(k, {s: pilots[s].step(as_on_the_wire(f))[0] for s, f in frames.items()})
            core.step()
        return core.finish()
    finally:
        core.close()


@pytest.mark.parametrize("resume,expect", [(True, "success"), (False, "failed")])
def test_a_restart_in_contact_resumes_the_measured_push(resume, expect):
    out = _restart_run(resume)
    assert out["verdict"]["status"] == expect, out["verdict"]["text"]
    if not resume:
        assert out["verdict"]["failure_class"] in ("dropped", "slipped")
