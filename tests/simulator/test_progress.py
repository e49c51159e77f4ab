"""The shared progress bar of a run's simulated time (simulator.progress)."""
from __future__ import annotations

from simulator.progress import SimBar


def test_into_a_log_the_bar_writes_a_line_per_tenth_of_the_run(capsys):
    bar = SimBar(2.0)
    for k in range(2001):  # as a 2 s run at 1 kHz would call it
        bar.show(k * 1e-3, 0.8)
    bar.close()
    lines = [x for x in capsys.readouterr().err.replace("\r", "\n").splitlines() if x.strip()]
    assert 10 <= len(lines) <= 13  # tenths, the start and the close
    assert "2.00/2.0 s sim" in lines[-1] and "0.80x real time" in lines[-1]


def test_a_disabled_bar_writes_nothing(capsys):
    bar = SimBar(1.0, disabled=True)
    bar.show(0.5, 1.0)
    bar.close()
    assert capsys.readouterr().err == ""
