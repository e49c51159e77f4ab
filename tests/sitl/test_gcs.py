"""The GCS link of a running SITL, with pymavlink's mavutil as the ground station: both AMs and
their companions seen, commands answered (signed only), a tlog stock tools read, and a run
that a GCS -- reading, never reading, or absent -- does not change by one bit."""
from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import pytest
from pymavlink import mavutil

from amcore.config import load_scenario
from amlink.codec import mav
from amlink.signing import gcs_key_from_passphrase
from sitl.inprocess import run as run_in_process
from tests.amlink.ptys import pty_pair

from .runner import SCENARIOS, Sim, am_run, companion, script

pytestmark = pytest.mark.sitl


class Gcs(threading.Thread):
    """A ground station on a free loopback UDP port, listening (the simulator's --gcs udpout:...).

    Once it has heard both vehicles it signs with the run's GCS key (``key_file``, when it
    appears), sends ``commands`` and, unsigned, ``intruder`` commands; it keeps every message."""

    def __init__(self, key_file: Path | None = None, commands=(), intruder=()) -> None:
        super().__init__(daemon=True)
        self.conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", source_system=255, source_component=190,
                                               dialect="amstack")
        self.port = self.conn.port.getsockname()[1]
        self.key_file, self.to_send, self.intruder = key_file, list(commands), list(intruder)
        self.msgs: list = []
        self.stop = threading.Event()

    def run(self) -> None:
        next_beat = 0.0
        while not self.stop.is_set():
            msg = self.conn.recv_match(blocking=True, timeout=0.05)
            if msg is not None and msg.get_type() != "BAD_DATA":
                self.msgs.append(msg)
            if time.monotonic() > next_beat and self.conn.clients:  # as MAVProxy: a GCS HEARTBEAT at 1 Hz
                self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                next_beat = time.monotonic() + 1.0
            if self.to_send and {4, 5} <= {m.get_srcSystem() for m in self.msgs} and self.key_file.is_file():
                self.conn.setup_signing(gcs_key_from_passphrase(self.key_file.read_text().strip()), sign_outgoing=True)
                for target, command, params in self.to_send:
                    self.conn.mav.command_long_send(target, 1, command, 0, *params)
                self.to_send = []
                sim_addr = next(iter(self.conn.clients))
                intruder = mavutil.mavlink_connection(f"udpout:{sim_addr[0]}:{sim_addr[1]}", source_system=254)
                for target, command, params in self.intruder:
                    intruder.mav.command_long_send(target, 1, command, 0, *params)
                intruder.close()

    def seen(self) -> Counter:
        return Counter((m.get_srcSystem(), m.get_srcComponent(), m.get_type()) for m in self.msgs)

    def texts(self, sysid: int) -> list[str]:
        return [m.text for m in self.msgs if m.get_type() == "STATUSTEXT" and m.get_srcSystem() == sysid]

    def finish(self) -> None:
        self.stop.set()
        self.join(5.0)
        self.conn.close()


def _p(*params: float) -> tuple[float, ...]:
    return (tuple(params) + (0.0,) * 7)[:7]


def _free_port(kind=socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def watched(tmp_path_factory):
    """am-run of two_am_comp (0.4 s) watched by a GCS that sends commands that change nothing
    (a disarm in the air, which is denied; an unsupported one; unsigned ones, dropped)."""
    run_dir = tmp_path_factory.mktemp("watched")
    gcs = Gcs(run_dir / "keys" / "gcs.key",
              commands=[(4, mav.MAV_CMD_COMPONENT_ARM_DISARM, _p(0.0)), (5, mav.MAV_CMD_DO_SET_MODE, _p(1.0))],
              intruder=[(4, mav.MAV_CMD_COMPONENT_ARM_DISARM, _p(0.0, 21196.0)), (5, mav.MAV_CMD_NAV_LAND, _p())])
    gcs.start()
    try:
        r = am_run("two_am_comp.toml", run_dir, "--duration", "0.4", "--no-telemetry", "--tlog-companions", "--gcs",
                   f"udpout:127.0.0.1:{gcs.port}", timeout_s=300)
        time.sleep(0.3)
    finally:
        gcs.finish()
    return r, gcs


def test_a_gcs_sees_both_vehicles_and_their_companions_at_the_rates_promised(watched):
    r, gcs = watched
    assert r.code == 0, r.stderr
    n = gcs.seen()
    for s in (4, 5):
        assert n[(s, 1, "HEARTBEAT")] >= 1 and n[(s, 1, "SYS_STATUS")] >= 1
        assert n[(s, 191, "HEARTBEAT")] >= 1  # the companion, passed on
        assert n[(s, 1, "ATTITUDE")] >= 0.4 * 10 and n[(s, 1, "LOCAL_POSITION_NED")] >= 0.4 * 10
        assert gcs.texts(s)[-1] == "run complete"  # the run's verdict, from every vehicle
        assert "mission phase: approach" in gcs.texts(s)
    for s in (4, 5):  # a new mode is told at once: even a run shorter than a second shows it
        beats = [m for m in gcs.msgs if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == s
                 and m.get_srcComponent() == 1]
        assert "OFFBOARD" in {mavutil.mode_string_v10(m) for m in beats}
        assert any(m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED for m in beats)
        assert "OFFBOARD: companion in control" in gcs.texts(s)


def test_gcs_commands_are_answered_and_unsigned_ones_dropped_and_counted(watched):
    r, gcs = watched
    acks = {(m.get_srcSystem(), m.command): m.result for m in gcs.msgs if m.get_type() == "COMMAND_ACK"}
    assert acks == {(4, mav.MAV_CMD_COMPONENT_ARM_DISARM): mav.MAV_RESULT_DENIED,
                    (5, mav.MAV_CMD_DO_SET_MODE): mav.MAV_RESULT_UNSUPPORTED}
    assert any("disarm denied" in t for t in gcs.texts(4))
    o = r.outcome
    assert o["gcs"]["commands"] == 2 and o["gcs"]["link"]["unsigned"] == 2 and o["events"] == []


def test_the_run_writes_a_gcs_tlog_that_stock_pymavlink_reads(watched):
    r, _ = watched
    log = mavutil.mavlink_connection(str(r.run_dir / "gcs.tlog"), dialect="amstack")
    seen = Counter()
    while (m := log.recv_match()) is not None:
        seen[(m.get_srcSystem(), m.get_srcComponent(), m.get_type())] += 1
    for s in (4, 5):
        assert seen[(s, 1, "HEARTBEAT")] >= 1 and seen[(s, 1, "ATTITUDE")] >= 4 and seen[(s, 191, "HEARTBEAT")] >= 1
    assert seen[(255, 190, "COMMAND_LONG")] == 2 and seen[(255, 190, "HEARTBEAT")] >= 1  # what came in, too
    mavlogdump = str(Path(sys.executable).parent / "mavlogdump.py")
    p = subprocess.run([mavlogdump, "--dialect", "amstack", "--types", "HEARTBEAT,ATTITUDE", str(r.run_dir / "gcs.tlog")],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout.count("ATTITUDE {") == seen[(4, 1, "ATTITUDE")] + seen[(5, 1, "ATTITUDE")]


def test_with_a_flag_each_companion_link_goes_to_a_tlog_too(watched):
    r, _ = watched
    log = mavutil.mavlink_connection(str(r.run_dir / "companion-5.tlog"), dialect="amstack")
    seen = Counter()
    while (m := log.recv_match()) is not None:
        seen[(m.get_srcSystem(), m.get_type())] += 1
    assert seen[(1, "AM_SIM_STEP")] >= 400 and seen[(1, "ODOMETRY")] >= 400  # every step, and the shutdown
    assert seen[(5, "AM_TORQUE_SETPOINT")] >= 400 and seen[(5, "HEARTBEAT")] >= 1 and seen[(1, "AM_SCENARIO")] >= 1


def test_no_gcs_a_reading_gcs_and_one_that_never_reads_leave_the_run_bit_identical(watched, tmp_path):
    """Reference: the in-process run, which has no GCS link at all. The watched run had a GCS
    reading and commanding (nothing that changes the run); this one has a TCP GCS that connects
    and never reads, and its companions reach the simulator over TCP and a serial line."""
    r, _ = watched
    reference = run_in_process(load_scenario(SCENARIOS / "two_am_comp.toml"), duration_s=0.4)["state_digest"]
    tcp, gcs_port = _free_port(), _free_port()
    with pty_pair() as (fc_line, companion_line):
        sim = Sim("two_am_comp.toml", tmp_path, "--duration", "0.4", "--no-telemetry", "--bind", f"tcpin:127.0.0.1:{tcp}",
                  "--bind", f"{fc_line}:921600", "--gcs", f"tcpin:127.0.0.1:{gcs_port}")
        stuck = socket.create_connection(("127.0.0.1", gcs_port))  # connects, never reads
        procs = [companion(4, f"tcp:127.0.0.1:{tcp}", "two_am_comp.toml", "--no-telemetry"),
                 companion(5, f"{companion_line}:921600", "two_am_comp.toml", "--no-telemetry")]
        try:
            code, err = sim.wait(timeout_s=300)
            assert code == 0, err
            for p in procs:
                _, cerr = p.communicate(timeout=60)
                assert p.returncode == 0, cerr
        finally:
            stuck.close()
            sim.kill()
            for p in procs:
                if p.poll() is None:
                    p.kill()
    o = json.loads((tmp_path / "outcome.json").read_text())
    assert o["gcs"]["messages_tx"] > 0 and o["steps"] == r.outcome["steps"] == 400
    assert r.outcome["state_digest"] == o["state_digest"] == reference


def test_nav_land_from_the_gcs_lands_that_vehicle(tmp_path):
    gcs = Gcs(tmp_path / "keys" / "gcs.key", commands=[(5, mav.MAV_CMD_NAV_LAND, _p())])
    gcs.start()
    try:
        r = am_run("two_am_comp.toml", tmp_path, "--duration", "0.6", "--no-telemetry", "--gcs",
                   f"udpout:127.0.0.1:{gcs.port}", timeout_s=300)
        time.sleep(0.3)
    finally:
        gcs.finish()
    assert r.code == 4, r.stderr  # the mission ended by the GCS's command: failed, and the verdict says so
    assert r.outcome["verdict"]["failure_class"] == "commanded"
    assert r.outcome["verdict"]["failures"][0]["reason"].startswith("am5 landed by the GCS at t = ")
    assert r.outcome["rejected_setpoints"] == 0 and r.outcome["ignored_setpoints"]["5"] > 0
    assert gcs.texts(5)[-1].startswith("mission failed: am5 landed (GCS) at t = ")
    acks = [(m.get_srcSystem(), m.command, m.result) for m in gcs.msgs if m.get_type() == "COMMAND_ACK"]
    assert acks == [(5, mav.MAV_CMD_NAV_LAND, mav.MAV_RESULT_ACCEPTED)]
    assert "landing (GCS command)" in gcs.texts(5)
    assert [(e["sysid"], e["event"]) for e in r.outcome["events"]] == [(5, "land")]
    last = [m for m in gcs.msgs if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 5 and m.get_srcComponent() == 1]
    assert mavutil.mode_string_v10(last[-1]) == "LAND"


def test_malformed_endpoints_exit_2_listing_the_accepted_forms(tmp_path):
    for cmd in ([script("simulator"), "--gcs", "udp:nowhere", "--run-dir", str(tmp_path / "a")],
                [script("simulator"), "--bind", "ttyUSB0", "--run-dir", str(tmp_path / "b")],
                [script("companion"), "--sysid", "4", "--sim", "tcp:127.0.0.1"],
                [script("am-run"), "--gcs", "serial:/dev/ttyS0", "--run-dir", str(tmp_path / "c")]):
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        assert p.returncode == 2, (cmd, p.stderr)
        assert "Traceback" not in p.stderr and "udpout:HOST:PORT" in p.stderr and "DEVICE[:BAUD]" in p.stderr
    assert not (tmp_path / "a").exists() and not (tmp_path / "c" / "simulator.log").exists()


def test_a_listening_gcs_endpoint_on_port_0_says_which_port_it_got(tmp_path):
    """docs/mavlink.md: PORT 0 on a listening form picks a free port. The port is of use only
    if the simulator says which: in its ready event, its log line and outcome.json; a GCS
    that sends there is answered."""
    p = subprocess.Popen([script("simulator"), "--config", str(SCENARIOS / "two_am_comp.toml"), "--bind",
                          "udpin:127.0.0.1:0", "--gcs", "udpin:127.0.0.1:0", "--run-dir", str(tmp_path),
                          "--progress", "jsonl", "--insecure", "--no-telemetry", "--peer-timeout", "3"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready = json.loads(p.stdout.readline())
        kind, host, port = ready["gcs"].rsplit(":", 2)
        assert (kind, host) == ("udpin", "127.0.0.1") and int(port) > 0
        gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255, source_component=190)
        try:
            gcs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            assert gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10) is not None  # served on that port
        finally:
            gcs.close()
        _, err = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 1 and f"GCS link udpin:127.0.0.1:{port}" in err  # no companion came
    assert json.loads((tmp_path / "outcome.json").read_text())["gcs"]["endpoint"] == f"udpin:127.0.0.1:{port}"


def test_the_old_companion_sim_udp_form_still_sends_and_says_so(tmp_path):
    sim = Sim("two_am_comp.toml", tmp_path, "--duration", "0.05", "--no-telemetry", "--gcs", "none")
    legacy = sim.bind.replace("udpout:", "udp:")
    procs = [companion(4, legacy, "two_am_comp.toml", "--no-telemetry"),
             companion(5, sim.bind, "two_am_comp.toml", "--no-telemetry")]
    try:
        code, err = sim.wait(timeout_s=120)
        assert code == 0, err
        outs = [p.communicate(timeout=60)[1] for p in procs]
        assert [p.returncode for p in procs] == [0, 0]
        assert "is read as udpout:" in outs[0] and "udpin: (listen)" in outs[0]
        assert "is read as udpout:" not in outs[1]
    finally:
        sim.kill()
        for p in procs:
            if p.poll() is None:
                p.kill()
