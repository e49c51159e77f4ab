"""Draws outside the team's envelope (amcore.preflight) are refused before flight and counted
as their own class: not flown, not failures of flight; the summary gives success over the
flown trials and over all, each with its Wilson interval."""
from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from amcore.config import read_scenario
from trials import cli
from trials.report import read_csv, summarize, summary_line, wilson_interval
from trials.runner import TrialTask, run_trial

ROOT = Path(__file__).resolve().parents[2]
ROBUST = ROOT / "configs" / "scenarios" / "two_am_robust.toml"


def _row(verdict: str, cls: str = "") -> dict:
    return {"verdict": verdict, "failure_class": cls}


def test_the_summary_counts_refused_trials_apart_from_flown_ones():
    rows = [_row("success")] * 6 + [_row("failed", "slipped")] * 2 + [_row("refused")] * 4
    s = summarize(rows)
    assert (s["trials"], s["flown"], s["refused"], s["successes"]) == (12, 8, 4, 6)
    assert s["success_rate"] == 0.5 and s["success_rate_flown"] == 0.75
    assert s["wilson95"] == pytest.approx(list(wilson_interval(6, 12)))
    assert s["wilson95_flown"] == pytest.approx(list(wilson_interval(6, 8)))
    assert sum(s["failure_classes"].values()) == 2  # a refusal is no failure of flight
    line = summary_line(s)
    assert line.startswith("4 of 12 refused before flight") and "of the 8 flown, 6/8 succeeded" in line
    assert "failures: slipped 2" in line and "over all trials 6/12 succeeded" in line
    assert summary_line(summarize([_row("success"), _row("failed", "dropped")])).startswith("1/2 succeeded")


def test_incomplete_trials_are_counted_in_the_line_and_the_comparison():
    """A campaign cut short (--set scenario.duration_s below the hover window's end) has trials
    that neither succeeded nor failed: the line and the table say how many, so their rows add up."""
    from trials.report import comparison_table

    s = summarize([_row("incomplete")] * 2 + [_row("failed", "dropped")])
    line = summary_line(s)
    assert line.startswith("0/3 succeeded") and "failures: dropped 1" in line
    assert "incomplete 2 (the run ended before the hover window did)" in line
    head, _, row = comparison_table([{**s, "controller": "baseline"}]).splitlines()
    cells = dict(zip((c.strip() for c in head.strip("|").split("|")), (c.strip() for c in row.strip("|").split("|"))))
    assert cells["trials"] == "3" and cells["incomplete"] == "2" and cells["dropped"] == "1"


def test_a_refused_trial_does_not_fly_and_says_why(tmp_path):
    data = read_scenario(ROBUST)
    data["object"]["mass_kg"] = 2.5
    t0 = time.perf_counter()
    row = run_trial(TrialTask(0, data, str(ROBUST), {"object_mass_kg": 2.5}))
    assert time.perf_counter() - t0 < 10.0  # no 20 s flight
    assert row["verdict"] == "refused" and row["failure_class"] == "" and "state_digest" not in row
    assert "outside the team's envelope" in row["reason"] and "use " in row["reason"]


def test_a_campaign_of_draws_outside_the_envelope_refuses_them_all(tmp_path):
    rand = tmp_path / "heavy.toml"
    rand.write_text("[randomize]\nobject_mass_kg = [2.5, 3.0]\npad_friction = [0.5, 0.6]\n")
    out = tmp_path / "c"
    assert cli.main([str(ROBUST), "--trials", "3", "--seed", "5", "--out", str(out), "--workers", "1",
                     "--randomize", str(rand), "--no-progress"]) == 0
    rows = read_csv(out / "trials.csv")
    assert [r["verdict"] for r in rows] == ["refused"] * 3
    s = json.loads((out / "summary.json").read_text())
    assert (s["refused"], s["flown"], s["successes"], s["success_rate_flown"]) == (3, 0, 0, None)
