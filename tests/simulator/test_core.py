"""SitlCore: per-AM link impairment from the scenario reaches that AM's flight controller only."""
from __future__ import annotations

from amcore.config import load_scenario
from simulator.inprocess import run

from ..conftest import SCENARIO


def test_per_am_link_override(tmp_path):
    text = SCENARIO.read_text().replace('vehicle = "../vehicles/am3dof.toml"',
                                        f'vehicle = "{SCENARIO.parent.parent / "vehicles" / "am3dof.toml"}"')
    text = text.replace("sysid = 4\n", "sysid = 4\nlink = { delay_s = 0.01, loss = 0.3 }\n")
    p = tmp_path / "s.toml"
    p.write_text(text + "\n[link]\njitter_s = 0.0\n")
    spec = load_scenario(p)
    a4, a5 = spec.am(4), spec.am(5)
    assert a4.link is not None and a4.link.delay_s == 0.01 and a4.link.loss == 0.3
    assert a5.link is None and spec.link.delay_s == 0.0
    o = run(spec, duration_s=0.2)
    s4, s5 = o["fc_link"]["4"], o["fc_link"]["5"]
    assert s4["sent"] == s5["sent"] == 200
    assert 30 < s4["lost"] < 90 and s4["delayed"] == s4["sent"] - s4["lost"]
    assert s5["lost"] == 0 and s5["delayed"] == 0
