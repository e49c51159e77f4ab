"""The wall-clock companion flying the free-running simulator, through the real processes: the
PX4 offboard handshake, the take-off from the ground, the mission's start on the autopilot
clock; a mode switched away by another client (the companion yields and does not fight back);
a companion killed in flight (its vehicle fails over after COM_OF_LOSS_T, the other flies on)."""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from amlink import px4
from amlink.wire import Encoder, mav

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "configs" / "scenarios" / "two_am_comp_attitude.toml"
BIN = Path(sys.executable).parent

pytestmark = pytest.mark.sitl
INSTANCE = 30  # PX4 SITL instances 30, 31: ports apart from a run on the defaults


def _env():
    return dict(os.environ, PYTHONUNBUFFERED="1")


def test_am_run_realtime_takes_off_and_flies_the_approach(tmp_path):
    """am-run --realtime: both AMs engage OFFBOARD, take off from the ground and are on their
    mission's approach at its start; the loops report their period and misses."""
    run = tmp_path / "run"
    r = subprocess.run([str(BIN / "am-run"), str(SCENARIO), "--realtime", "--duration", "3", "--run-dir", str(run),
                        "--no-progress", "--instance", "20"], capture_output=True, text=True, env=_env(), timeout=240, cwd=ROOT)
    assert r.returncode in (0, 4), r.stderr[-3000:]
    o = json.loads((run / "outcome.json").read_text())
    loops = _loop_timing_events(run / "run.mcap")
    a, b = loops["/sim/event"][-2:]
    rtf_end = (b["steps"] - a["steps"]) / o["rate_hz"] / (b["elapsed_s"] - a["elapsed_s"])
    assert o["mode"] == "free-running" and o["speed"] == 0.5 and o["mission_t0_given"]
    assert "pacing:" in r.stderr and "deadline" in r.stderr
    for sysid in ("4", "5"):
        v = o["vehicles"][sysid]
        assert v["offboard_engaged_s"] is not None and v["offboard_engaged_s"] < o["mission_t0_s"] - 3.0
        assert any(e["event"] == "takeoff" for e in v["events"]), v["events"]
        assert v["armed_at_end"] and v["mode_at_end"] == "OFFBOARD"
        c = json.loads((run / f"am{sysid}.json").read_text())
        assert c["clock"] == "wall" and c["error"] is None, c.get("ended")
        loop = c["loop"]
        # 250 Hz of the autopilot's clock: 4 ms of it, at the speed the simulator flew (0.5x asked;
        # a loaded simulator runs slower than asked, and the companion's period follows its clock)
        rtf = o["real_time_factor"]
        assert 0.0 < rtf <= 0.51  # never faster than asked (how much slower is the machine's load: benchmarks)
        # the period follows the autopilot clock's rate of the last seconds (the physics loop's rate
        # between its last two timing reports in the log): within 15 %, where a loop on its own wall
        # clock would be off by the factor itself
        assert loop["period_target_ms"] == pytest.approx(4.0 / rtf_end, rel=0.15), (rtf, rtf_end)
        assert {"odometry", "joints", "wrench"} <= set(loop["sample_age_ms"])
        # the take-off ended at the mission's start: the CoM on its reference within centimetres,
        # and the 3 s of approach flown after it track it
        approach = c["phases"]["approach"]
        assert approach["steps"] > 500
        assert approach["final"]["r_c_err"] < 0.05, approach
    ams = o["ams"]
    assert all(not a["base_contacts"] for a in ams.values()), ams
    # PX4 SITL's GCS instances, signed with the run's gcs.key
    assert "GCS ports (signed)" in r.stderr and (run / "keys" / "gcs.key").is_file()
    assert [g.split(" -> ")[0] for g in o["gcs_ports"]] == ["udp 127.0.0.1:18590", "udp 127.0.0.1:18591"]
    # the log: the mission's ground truth, each controller's state, and the loops' timing (the
    # companions' period, misses and sample ages; the physics loop's deadline misses)
    assert {"/am/4/event", "/am/5/event", "/sim/event"} <= set(loops), loops.keys()
    for sysid in ("4", "5"):
        last = loops[f"/am/{sysid}/event"][-1]
        assert last["period_ms"]["p50"] > 0 and "deadline_misses" in last and "odometry" in last["sample_age_ms"]
    assert "deadline_misses" in loops["/sim/event"][-1]


def _loop_timing_events(path: Path) -> dict[str, list[dict]]:
    """Each topic's "loop timing" events in an MCAP log (their data), in order; asserts that the
    log holds the mission's ground truth and both controllers' states."""
    from mcap.reader import make_reader
    out: dict[str, list[dict]] = {}
    topics = set()
    with open(path, "rb") as f:
        for _, ch, msg in make_reader(f).iter_messages():
            topics.add(ch.topic)
            if ch.topic.endswith("/event"):
                for line in msg.data.split(b"\n"):
                    d = json.loads(line)
                    if d.get("text") == "loop timing":
                        out.setdefault(ch.topic, []).append(d["data"])
    assert {"/am/4/controller", "/am/5/controller", "/sim/am/4/truth", "/sim/object/pose"} <= topics, topics
    return out


def _start_sim(run: Path, duration: float, mission_start: float):
    return subprocess.Popen([str(BIN / "simulator"), "--realtime", "--speed", "0.5", "--config", str(SCENARIO),
                             "--run-dir", str(run), "--duration", str(duration), "--mission-start", str(mission_start),
                             "--instance", str(INSTANCE), "--no-telemetry"],
                            stdout=subprocess.DEVNULL, stderr=open(run / "simulator.log", "w"), env=_env(), cwd=ROOT)


def _start_companion(run: Path, sysid: int, mission_start: float, name: str | None = None):
    name = name or str(sysid)
    return subprocess.Popen([str(BIN / "companion"), "--sysid", str(sysid), "--clock", "wall", "--config",
                             str(SCENARIO), "--no-telemetry", "--mission-start", str(mission_start), "--outcome",
                             str(run / f"am{name}.json"), "--frame-timeout", "3", "--instance", str(INSTANCE)],
                            stdout=subprocess.DEVNULL, stderr=open(run / f"companion-{name}.log", "w"), env=_env(),
                            cwd=ROOT)


def test_a_mode_switched_away_is_yielded_to_a_stalled_companion_fails_over_and_a_restarted_one_rejoins(tmp_path):
    """Vehicle 0: another client switches it to HOLD in the take-off; its companion yields and
    never asks for OFFBOARD again. Vehicle 1: once the mission is under way (the vehicle in the
    air at the mission's start), its companion stalls (SIGSTOP) for 2 s of the autopilot's clock;
    PX4's COM_OF_LOSS_T failover takes the vehicle to HOLD, and the companion, resumed, yields
    without sending again (the stall is over COM_OF_LOSS_T), or on the HOLD it reads. A new
    companion started for vehicle 1 engages OFFBOARD again and joins the mission in progress
    (the team's --mission-start), flying it to the run's end. (A killed companion is a stall
    that never resumes: the same failover.) The instants are set in the autopilot's time, from
    the engage time the companion logs, so that a slow machine shifts none of them."""
    run = tmp_path / "run"
    run.mkdir()
    start, speed, stall_at = 8.0, 0.5, 8.5  # the mission's start, the stall [s, autopilot time]
    sim = _start_sim(run, duration=start + 9.0, mission_start=start)
    deadline = time.monotonic() + 120.0  # its ports and devices open (its kernels may compile first)
    while "devices:" not in (run / "simulator.log").read_text():
        assert sim.poll() is None and time.monotonic() < deadline, (run / "simulator.log").read_text()
        time.sleep(0.2)
    c4, c5 = _start_companion(run, 4, start), _start_companion(run, 5, start)
    c5b = None
    gcs = None
    try:
        # another client on vehicle 0's onboard port: PX4 executes its commands (its answers go to the
        # first partner, the companion); once both fly, it switches vehicle 0 to HOLD
        deadline = time.monotonic() + 90.0
        seen = ""
        while time.monotonic() < deadline and "starts at" not in seen:
            time.sleep(0.05)
            seen = (run / "companion-5.log").read_text()
            assert c4.poll() is None and c5.poll() is None, seen
        # the wall-clock instant of an autopilot time, from companion 5's engage (logged within a
        # step of it)
        engaged = float(re.search(r"OFFBOARD engaged at autopilot time ([0-9.]+) s", seen).group(1))
        wall0 = time.monotonic()

        def until_fc(t_fc: float) -> None:
            time.sleep(max(0.0, wall0 + (t_fc - engaged) / speed - time.monotonic()))

        while "starts at" not in (run / "companion-4.log").read_text():
            assert c4.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        until_fc(engaged + 1.5)  # into the take-off
        port = re.search(r"sysid 4: udp 127\.0\.0\.1:(\d+) ->", (run / "simulator.log").read_text()).group(1)
        gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        enc = Encoder(250, 190)  # MAVLink 2 (pymavlink's mavutil sends MAVLink 1 unless MAVLINK20 is set)
        hold = mav.MAVLink_command_long_message(4, 1, mav.MAV_CMD_DO_SET_MODE, 0, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                                float(px4.MAIN_AUTO), float(px4.SUB_AUTO_LOITER), 0, 0, 0, 0)
        gcs.sendto(enc.pack([hold]), ("127.0.0.1", int(port)))
        c4.wait(timeout=20)  # the companion sees HOLD in the next HEARTBEATs and yields
        until_fc(stall_at)
        c5.send_signal(signal.SIGSTOP)  # companion 5 stalls: 2 s of the autopilot's clock
        time.sleep(2.0 / speed)
        c5.send_signal(signal.SIGCONT)
        c5.wait(timeout=20)
        c5b = _start_companion(run, 5, start, name="5b")  # a new companion for vehicle 1
        sim.wait(timeout=150)
        c5b.send_signal(signal.SIGTERM)  # (as am-run ends the companions when the simulator ends)
        c5b.wait(timeout=20)
    finally:
        for p in (c4, c5, c5b, sim):
            if p is not None and p.poll() is None:
                p.kill()
                p.wait()
        if gcs is not None:
            gcs.close()
    log4 = (run / "companion-4.log").read_text()
    assert c4.returncode == 0, log4
    a4 = json.loads((run / "am4.json").read_text())
    assert a4["ended"].startswith("yielded") and "HOLD" in a4["ended"], a4["ended"]
    o = json.loads((run / "outcome.json").read_text())
    ev4 = o["vehicles"]["4"]["events"]
    # vehicle 0 went to HOLD on the request and stayed there: the companion did not ask for OFFBOARD again
    holds = [i for i, e in enumerate(ev4) if e.get("event") == "mode" and e.get("to") == "HOLD" and e.get("armed")]
    assert holds, ev4
    assert not any(e.get("event") == "mode request" and e.get("mode") == "OFFBOARD" for e in ev4[holds[0]:]), ev4
    # vehicle 1: the stall's failover, after COM_OF_LOSS_T of the autopilot's clock without a setpoint
    ev5 = o["vehicles"]["5"]["events"]
    fs = [e for e in ev5 if e.get("event") == "failsafe" and "offboard" in e.get("cause", "")]
    assert fs and fs[0]["t_s"] - fs[0]["last_setpoint_s"] == pytest.approx(1.0, abs=0.0011), ev5
    assert fs[0]["last_setpoint_s"] > start  # the stall came in the mission, as it was set to
    a5 = json.loads((run / "am5.json").read_text())
    assert c5.returncode == 0 and a5["ended"].startswith("yielded"), a5["ended"]
    # the restarted companion engaged again and flew the mission from where it joined, to the end
    log5b = (run / "companion-5b.log").read_text()
    a5b = json.loads((run / "am5b.json").read_text())
    # it flew to the run's end: stopped by the SIGTERM, or (the simulator's exit slower than its
    # frame timeout, on a loaded machine) ended by the autopilot's silence once the run was over: its
    # samples stale, then its hand-back (which the run's end, OFFBOARD below, shows came after it)
    assert (a5b["ended"] == "stopped by SIGTERM" or a5b["ended"].startswith("the autopilot has been silent")
            or a5b["ended"].startswith("handed back to the autopilot (HOLD): stale odometry")), log5b[-2000:]
    assert "joining the mission" in log5b and a5b["engaged_fc_s"] > fs[0]["t_s"]
    # (the first engage comes before arming; a resumed companion's stray setpoint may add one in between)
    engages = [e for e in ev5 if e.get("event") == "mode" and e.get("to") == "OFFBOARD"]
    assert len(engages) >= 2 and engages[-1]["t_s"] > fs[0]["t_s"] and engages[-1]["armed"], ev5
    assert o["vehicles"]["5"]["mode_at_end"] == "OFFBOARD" and o["vehicles"]["5"]["armed_at_end"]
    # the verdict names the first failover (vehicle 0's HOLD) and counts the others
    v = o["verdict"]
    assert v["failure_class"] == "failover" and "am4 left OFFBOARD" in v["text"] and "HOLD asked for" in v["text"], v
