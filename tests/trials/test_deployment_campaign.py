"""A short campaign of the default randomization (the deployment) on two_am_robust, as a regression check with
a loose bound: the draws outside the team's envelope are refused before flight, and of the
flown ones (the object moved and turned, measured by motion capture, every device at its
default level) at least half succeed. Two 20 s missions on two workers: 77 s measured on two
cores shared with other work."""
from __future__ import annotations

import json
from pathlib import Path


from trials import cli
from trials.report import read_csv

ROOT = Path(__file__).resolve().parents[2]


def test_a_short_deployment_campaign_refuses_what_it_cannot_hold_and_holds_the_rest(tmp_path, capsys):
    out = tmp_path / "c"
    assert cli.main([str(ROOT / "configs" / "scenarios" / "two_am_robust.toml"), "--trials", "3", "--seed", "31",
                     "--out", str(out), "--workers", "2", "--no-progress", "--no-plots"]) == 0
    rows = read_csv(out / "trials.csv")
    s = json.loads((out / "summary.json").read_text())
    refused = [r for r in rows if r["verdict"] == "refused"]
    assert s["refused"] == len(refused) >= 1 and s["flown"] == len(rows) - len(refused) >= 2
    assert all("outside the team's envelope" in r["reason"] and " AMs" in r["reason"] for r in refused)
    assert all(r["verdict"] in ("success", "failed") for r in rows if r not in refused)
    assert s["successes"] >= 0.5 * s["flown"], [r["reason"] for r in rows]
    # the rate of trials counts the refused ones, which cost the pre-flight check alone; the flights' apart
    assert f"trials/min ({s['flown_per_minute']:.1f} flown/min)" in capsys.readouterr().err
    assert s["flown_per_minute"] < s["trials_per_minute"]
