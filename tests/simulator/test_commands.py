"""GCS commands on the flight controllers (in-process: SitlCore and the companions' Pilots)."""
from __future__ import annotations

import pytest

from amlink.codec import mav
from companion.pilot import Pilot
from simulator import commands
from simulator.core import SitlCore
from simulator.fcstate import FcMode
from simulator.gcs_link import GcsCommand
from sitl.inprocess import as_on_the_wire


class Fleet:
    """Two AMs flown by their pilots in-process; `run(seconds)` steps the lockstep."""

    def __init__(self, spec) -> None:
        self.core = SitlCore(spec)
        self.pilots = {s: Pilot(spec, s, model=self.core.model) for s in self.core.sysids}
        self.k = 0
        self.core.connect()

    def run(self, seconds: float) -> None:
        for _ in range(int(round(seconds * self.core.spec.rate_hz))):
            frames = self.core.frames(self.k)
            sps = {s: self.pilots[s].step(as_on_the_wire(f))[0] for s, f in frames.items()}
            self.core.actuate(self.k, sps)
            self.core.step()
            self.k += 1

    def do(self, command: int, target: int, *params: float):
        p = (tuple(params) + (0.0,) * 7)[:7]
        return commands.execute(self.core, GcsCommand(command, target, 1, p, 255, 190))

    def z(self, s: int) -> float:
        return float(self.core.world.state(s).p_WB[2])

    def vz(self, s: int) -> float:
        st = self.core.world.state(s)
        return float((st.R_WB @ st.v_B)[2])


@pytest.fixture
def fleet(spec):
    f = Fleet(spec)
    f.run(0.2)
    yield f
    f.core.close()


def _results(answers):
    return {a.sysid: a.result for a in answers}


def test_nav_land_lands_that_vehicle_and_ignores_its_companion(fleet):
    z0 = {s: fleet.z(s) for s in (4, 5)}
    answers, news = fleet.do(mav.MAV_CMD_NAV_LAND, 5)
    assert _results(answers) == {5: mav.MAV_RESULT_ACCEPTED} and news == ""
    fleet.run(0.6)
    assert fleet.core.fc_mode(5) == FcMode.LAND and fleet.core.fc_mode(4) == FcMode.OFFBOARD
    assert fleet.z(5) < z0[5] - 0.05  # coming down at the failsafe's 0.3 m/s
    assert abs(fleet.z(4) - z0[4]) < 0.01  # the other one flies its mission
    assert [e["event"] for e in fleet.core.events] == ["land"]
    snap = fleet.core.snapshot({4: True, 5: True})
    assert snap.vehicle(5).mode == FcMode.LAND and not snap.vehicle(5).failsafe and snap.phase == "approach"


def test_disarm_in_the_air_is_denied_unless_forced(fleet):
    answers, _ = fleet.do(mav.MAV_CMD_COMPONENT_ARM_DISARM, 4, 0.0)
    assert _results(answers) == {4: mav.MAV_RESULT_DENIED} and "force" in answers[0].text
    fleet.run(0.1)
    assert abs(fleet.vz(4)) < 0.05
    answers, _ = fleet.do(mav.MAV_CMD_COMPONENT_ARM_DISARM, 4, 0.0, commands.FORCE_DISARM_MAGIC)
    assert _results(answers) == {4: mav.MAV_RESULT_ACCEPTED}
    fleet.run(0.3)
    assert fleet.vz(4) < -2.0  # motors off: falling (g t = 2.9 m/s)
    assert not fleet.core.snapshot({4: True, 5: True}).vehicle(4).armed
    answers, _ = fleet.do(mav.MAV_CMD_COMPONENT_ARM_DISARM, 4, 1.0)
    assert _results(answers) == {4: mav.MAV_RESULT_ACCEPTED} and 4 not in fleet.core.disarmed
    assert [e["event"] for e in fleet.core.events] == ["disarmed", "armed"]


def test_mission_abort_lands_the_whole_team_whoever_it_is_sent_to(fleet):
    answers, news = fleet.do(mav.MAV_CMD_AM_ABORT_MISSION, 4)
    assert _results(answers) == {4: mav.MAV_RESULT_ACCEPTED} and "aborted" in news
    fleet.run(0.3)
    assert {fleet.core.fc_mode(s) for s in (4, 5)} == {FcMode.LAND}
    assert all(fleet.vz(s) < -0.1 for s in (4, 5))


def test_broadcast_commands_are_answered_by_every_vehicle_and_others_are_unsupported(fleet):
    answers, _ = fleet.do(mav.MAV_CMD_DO_SET_MODE, 0, 1.0)
    assert _results(answers) == {4: mav.MAV_RESULT_UNSUPPORTED, 5: mav.MAV_RESULT_UNSUPPORTED}
    answers, _ = fleet.do(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0)
    assert _results(answers) == {4: mav.MAV_RESULT_ACCEPTED, 5: mav.MAV_RESULT_ACCEPTED}
    assert fleet.do(mav.MAV_CMD_NAV_LAND, 9)[0] == []  # not one of ours: no answer
    assert fleet.core.events == []


def test_setpoints_after_a_commanded_landing_are_ignored_not_rejected(fleet):
    """A companion that keeps flying its mission after NAV_LAND sends setpoints its landing
    vehicle does not take; even one the simulator would refuse as implausible is ignored and
    counted, never a rejection (no failsafe, no "rejected setpoints" verdict)."""
    fleet.core.note_rejected(4, "before: |tau_q_nm| > 12")  # a refusal before any command counts
    fleet.do(mav.MAV_CMD_NAV_LAND, 5)
    for _ in range(2 * fleet.core.failsafe_after_rejected):
        fleet.core.note_rejected(5, "|tau_q_nm| > 12")
    fleet.run(0.5)
    core = fleet.core
    assert [(s, why) for _, s, why in core.rejected] == [(4, "before: |tau_q_nm| > 12")]
    assert 5 not in core.distrusted and core.fc_mode(5) == FcMode.LAND
    assert core.ignored_setpoints[5] == 2 * core.failsafe_after_rejected + 500  # and every step's setpoint
    assert core.ignored_setpoints[4] == 0


def test_the_verdict_names_a_commanded_landing_and_not_the_touchdown(fleet):
    """NAV_LAND on one vehicle: the run's cause is the command, with its time; its base then
    reaching the ground is the landing, not a base-contact failure."""
    fleet.do(mav.MAV_CMD_NAV_LAND, 5)
    fleet.run(4.0)
    assert fleet.core.fc_mode(5) == FcMode.LANDED  # down on the ground (or the table), motors off
    v = fleet.core.finish()["verdict"]
    assert v["status"] == "failed" and v["failure_class"] == "commanded", v["text"]
    assert v["failures"][0]["reason"] == "am5 landed by the GCS at t = 0.20 s"
    assert "base contact" not in [f["class"] for f in v["failures"]], v["text"]


def test_the_verdict_names_the_mission_abort(fleet):
    fleet.do(mav.MAV_CMD_AM_ABORT_MISSION, 5)
    fleet.run(0.3)
    v = fleet.core.finish()["verdict"]
    assert v["failure_class"] == "commanded" and v["text"].startswith("mission FAILED: aborted by the GCS at t = 0.20 s")
    assert [f["class"] for f in v["failures"]].count("commanded") == 1


def test_a_forced_disarm_in_flight_is_named_but_a_disarm_after_landing_is_not(fleet):
    fleet.do(mav.MAV_CMD_COMPONENT_ARM_DISARM, 4, 0.0, commands.FORCE_DISARM_MAGIC)
    fleet.run(0.1)
    assert fleet.core.commanded == [(pytest.approx(0.2), 4, "disarm")]
    v = fleet.core.finish()["verdict"]
    assert v["failures"][0]["reason"] == "am4 disarmed in flight by the GCS at t = 0.20 s"
