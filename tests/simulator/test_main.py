"""The simulator process main's own wording (in-process: nothing is started)."""
from __future__ import annotations

import pytest

from amlink.udp import STATUSTEXT_MAX
from simulator.main import _told


@pytest.mark.parametrize("reason,told", [
    ("aborted by the GCS at t = 12.74 s", "mission failed: aborted by the GCS at t = 12.74 s"),
    ("am5 landed by the GCS at t = 15.70 s", "mission failed: am5 landed (GCS) at t = 15.70 s"),
    ("am4 disarmed in flight by the GCS at t = 3.00 s", "mission failed: ended by a GCS command"),
])
def test_the_last_statustext_names_a_gcs_command_within_one_statustext(reason, told):
    assert _told({"class": "commanded", "reason": reason}) == told
    assert len(told.encode()) <= STATUSTEXT_MAX


def test_other_failures_are_named_by_their_class():
    assert _told({"class": "dropped", "reason": "dropped at t = 12.40 s"}) == "mission failed: dropped"
