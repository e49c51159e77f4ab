"""Process behaviour of the SITL: determinism, start-up errors, missing and dead peers, signals.
Short runs (well under a simulated second) through the console scripts."""
from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import time

import pytest

from amruntime import procstats

from .runner import SCENARIOS, Sim, am_run, companion, script

pytestmark = pytest.mark.sitl


def test_same_scenario_gives_a_bit_identical_run(tmp_path):
    a = am_run("two_am_comp.toml", tmp_path / "a", "--duration", "0.4", timeout_s=300)
    b = am_run("two_am_comp.toml", tmp_path / "b", "--duration", "0.4", timeout_s=300)
    assert a.code == 0 and b.code == 0, a.stderr + b.stderr
    assert a.outcome["steps"] == b.outcome["steps"] == 400
    assert a.outcome["state_digest"] == b.outcome["state_digest"]
    # the outcome files say how each process's main thread spent the run (amruntime.procstats)
    if procstats.thread_schedstat() is not None:
        for proc in [a.outcome["process"], *(c["process"] for c in a.companions.values())]:
            t = proc["main_thread"]
            assert t["wall_s"] > 0.0 and t["on_cpu_s"] > 0.0
            assert t["on_cpu_s"] + t["queued_s"] + t["blocked_s"] == pytest.approx(t["wall_s"], abs=2e-3)


def test_digest_sees_a_different_run(tmp_path):
    a = am_run("two_am_comp.toml", tmp_path / "a", "--duration", "0.4", timeout_s=300)
    b = am_run("two_am_comp.toml", tmp_path / "b", "--duration", "0.5", timeout_s=300)
    assert a.outcome["state_digest"] != b.outcome["state_digest"]


def test_missing_companion_is_named_and_nothing_hangs(tmp_path):
    sim = Sim("two_am_comp.toml", tmp_path, "--peer-timeout", "3")
    c4 = companion(4, sim.bind)
    try:
        t0 = time.monotonic()
        code, err = sim.wait(timeout_s=60)
        assert code == 1
        assert "sysid 5" in err, err
        assert time.monotonic() - t0 < 30
        out, cerr = c4.communicate(timeout=30)
        assert c4.returncode == 1, cerr  # told by the simulator that the run failed
        assert "sysid 5" in cerr
    finally:
        sim.kill()
        c4.kill()


def test_companion_of_another_scenario_is_told_so(tmp_path):
    sim = Sim("two_am_comp.toml", tmp_path, "--peer-timeout", "20")
    try:
        c = companion(4, sim.bind, "two_am_nocomp.toml")
        out, err = c.communicate(timeout=60)
        assert c.returncode == 3
        assert "two_am_comp" in err and "two_am_nocomp" in err
    finally:
        sim.kill()


@pytest.mark.parametrize("old,new,file,key", [
    ("mass_kg = 1.0", 'mass_kg = "heavy"', "bad.toml", "[object].mass_kg"),
    ("sysid = 5", "sysid = 4", "bad.toml", "duplicate sysid 4"),
    ("azimuth_deg = 0.0", "azimuth_deg = 0.0\nspeed = 3", "bad.toml", "unknown key 'speed'"),
    ("[object]", "[link]\nloss = 2.0\n[object]", "bad.toml", "[link].loss"),
    ("VEHICLE", "urdf", "am3dof.toml", "urdf: file not found"),
    ("VEHICLE", "gains", "am3dof.toml", "[gains].k_R: must be > 0"),
])
def test_bad_config_exits_2_naming_file_and_key_and_starts_nothing(tmp_path, old, new, file, key):
    vehicle = SCENARIOS.parent / "vehicles" / "am3dof.toml"
    if old == "VEHICLE":  # a broken vehicle file next to the scenario
        vtext = vehicle.read_text().replace('urdf = "am3dof.urdf"', f'urdf = "{vehicle.parent / "am3dof.urdf"}"')
        vtext = vtext.replace(f'urdf = "{vehicle.parent / "am3dof.urdf"}"', 'urdf = "missing.urdf"') if new == "urdf" \
            else vtext.replace("k_R = 30.0", "k_R = -1.0")
        vehicle = tmp_path / "am3dof.toml"
        vehicle.write_text(vtext)
        text = (SCENARIOS / "two_am_comp.toml").read_text()
    else:
        assert old in (SCENARIOS / "two_am_comp.toml").read_text()
        text = (SCENARIOS / "two_am_comp.toml").read_text().replace(old, new, 1)
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('vehicle = "../vehicles/am3dof.toml"', f'vehicle = "{vehicle}"'))
    for cmd in ([script("simulator"), "--config", str(bad), "--bind", "udp:127.0.0.1:0", "--run-dir", str(tmp_path / "s")],
                [script("companion"), "--sysid", "4", "--config", str(bad)],
                [script("am-run"), str(bad), "--run-dir", str(tmp_path / "r")]):
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        assert p.returncode == 2, (cmd, p.stderr)
        assert file in p.stderr and key in p.stderr, p.stderr
        assert p.stderr.count("error:") == 1  # one clear message
    assert not (tmp_path / "s").exists() and not (tmp_path / "r" / "simulator.log").exists()  # nothing started
    p = subprocess.run([script("companion"), "--sysid", "9"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and "sysid 9" in p.stderr


def _wait_for(stream, text: str, limit: int = 100000) -> str:
    for _ in range(limit):
        line = stream.readline()
        if not line:
            raise AssertionError(f"stream ended before {text!r}")
        if text in line:
            return line
    raise AssertionError(f"{text!r} not seen")


def test_sigterm_stops_a_companion_cleanly_and_its_vehicle_goes_to_failsafe(tmp_path):
    sim = Sim("two_am_comp.toml", tmp_path, "--step-timeout", "2", "--peer-timeout", "30", "--duration", "5")
    c4, c5 = companion(4, sim.bind, "two_am_comp.toml", "--outcome", str(tmp_path / "am4.json")), companion(5, sim.bind)
    try:
        _wait_for(sim.proc.stdout, '"progress"')  # the run is under way
        c5.send_signal(signal.SIGTERM)
        out, err5 = c5.communicate(timeout=20)
        assert c5.returncode == 0, err5
        assert "SIGTERM" in err5
        line = _wait_for(sim.proc.stderr, "failsafe")
        assert "sysid 5" in line
        code, err = sim.wait(timeout_s=120)
        assert code == 4  # a vehicle ended the run in failsafe: the mission failed
        assert "mission FAILED: sysid 5 in failsafe at the end" in err
        c4.communicate(timeout=30)
        assert c4.returncode == 0  # the other companion flew on, undisturbed, to the end
        o = json.loads((tmp_path / "outcome.json").read_text())
        assert [e["event"] for e in o["events"]] == ["lost"] and o["failsafe_at_end"] == [5]
        assert o["ams"]["5"]["base_contacts"] == []  # held in the air, did not crash
        am4 = json.loads((tmp_path / "am4.json").read_text())
        assert am4["at"]["end"]["r_c_err"] < 5e-3
    finally:
        for p in (c4, c5):
            if p.poll() is None:
                p.kill()
        sim.kill()


def _wait_for_sim_time(stream, t_s: float) -> float:
    """Read the simulator's JSON progress lines until one reports simulated time >= t_s."""
    while True:
        line = _wait_for(stream, '"progress"')
        t = json.loads(line)["t"]
        if t >= t_s:
            return t


REJOIN_RUN_S = 9.0  # simulated seconds: a restarted companion takes seconds of wall time to start while
# the simulator runs on, so its rejoin comes seconds into the run, and the end must leave it seconds to fly


@contextlib.contextmanager
def _two_am_run_that_loses_companion_5(tmp_path):
    """two_am_comp for REJOIN_RUN_S; companion 5 SIGKILLed once the run is under way. Yields (sim,
    seconds from the kill to the simulator's failsafe message, restart), restart() starting a
    new companion 5 that writes am5.json; every process is killed on leaving."""
    sim = Sim("two_am_comp.toml", tmp_path, "--step-timeout", "2", "--peer-timeout", "30", "--duration", str(REJOIN_RUN_S))
    procs = [companion(4, sim.bind), companion(5, sim.bind)]

    def restart():
        procs.append(companion(5, sim.bind, "two_am_comp.toml", "--outcome", str(tmp_path / "am5.json")))
        return procs[-1]

    try:
        _wait_for(sim.proc.stdout, '"progress"')
        procs[1].kill()
        t_kill = time.monotonic()
        _wait_for(sim.proc.stderr, "failsafe")
        yield sim, time.monotonic() - t_kill, restart
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
        sim.kill()


def test_companion_restarted_seconds_later_takes_its_vehicle_back_from_where_it_is(tmp_path):
    """Restarted while its vehicle has been held by the failsafe for seconds and the mission
    has moved on: it starts from the vehicle's state (companion.pilot, amcore.mission.JoinBlend)
    and takes over for good. Before, its first ~2500 setpoints exceeded the simulator's
    plausibility bounds and were rejected, and the vehicle ended the run in failsafe.

    The restart waits for simulated time, not wall time: the simulator runs on while the new
    companion starts (seconds of wall time, more on a loaded machine), so a restart timed by
    the wall clock rejoined anywhere from 5 s to the end of a 6 s run, and the error at the end
    then caught the first tenth of a second after the rejoin (up to 12 mm) instead of its
    vehicle taken over."""
    with _two_am_run_that_loses_companion_5(tmp_path) as (sim, _, restart):
        _wait_for_sim_time(sim.proc.stdout, 1.5)  # the run goes on without it
        c5b = restart()
        code, err = sim.wait(timeout_s=180)
        assert code == 0, err
        o = json.loads((tmp_path / "outcome.json").read_text())
        events = o["events"]
        assert [e["event"] for e in events] == ["lost", "rejoined"], events
        assert events[1]["t"] - events[0]["t"] > 1.0  # a late rejoin
        # the check below judges the vehicle taken over, seconds after the rejoin
        assert events[1]["t"] < REJOIN_RUN_S - 2.0, f"rejoined at t = {events[1]['t']} s of {REJOIN_RUN_S}: too late to judge"
        assert o["failsafe_at_end"] == [] and o["link"]["rejected_setpoints"] == 0
        c5b.communicate(timeout=30)
        assert c5b.returncode == 0
        am5 = json.loads((tmp_path / "am5.json").read_text())
        assert am5["at"]["end"]["r_c_err"] < 0.01


def test_sigkilled_companion_is_detected_and_a_restarted_one_rejoins(tmp_path):
    with _two_am_run_that_loses_companion_5(tmp_path) as (sim, detected_after_s, restart):
        assert detected_after_s < 10  # detected within the step timeout (+ load)
        c5b = restart()
        line = _wait_for(sim.proc.stderr, "companion back")
        assert "sysid 5" in line
        code, err = sim.wait(timeout_s=180)
        assert code == 0, err
        o = json.loads((tmp_path / "outcome.json").read_text())
        assert [e["event"] for e in o["events"]] == ["lost", "rejoined"]
        assert o["events"][1]["t"] < REJOIN_RUN_S - 2.0, o["events"]  # seconds before the end, to judge the flight after it
        assert o["failsafe_at_end"] == []
        c5b.communicate(timeout=30)
        assert c5b.returncode == 0
        am5 = json.loads((tmp_path / "am5.json").read_text())
        assert am5["at"]["end"]["r_c_err"] < 0.05  # flying its reference again


def test_companion_with_the_wrong_signing_key_is_not_served(tmp_path):
    key_a, key_b = tmp_path / "a.key", tmp_path / "b.key"
    key_a.write_text("11" * 32)
    key_b.write_text("22" * 32)
    sim = Sim("two_am_comp.toml", tmp_path, "--peer-timeout", "4", "--key-file", str(key_a))
    c4 = companion(4, sim.bind, "two_am_comp.toml", "--key-file", str(key_a))
    c5 = companion(5, sim.bind, "two_am_comp.toml", "--key-file", str(key_b), "--connect-timeout", "6")
    try:
        code, err = sim.wait(timeout_s=60)
        assert code == 1
        assert "sysid 5" in err and "sysid 4" not in err.split("link failure")[-1], err
        out, err5 = c5.communicate(timeout=30)
        assert c5.returncode == 1, err5  # never heard AM_SCENARIO: its HEARTBEATs were dropped unsigned-by-us
    finally:
        for p in (c4, c5):
            if p.poll() is None:
                p.kill()
        sim.kill()


def test_killing_the_logger_mid_run_costs_the_run_nothing_and_the_log_is_salvaged(tmp_path):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        endpoint = f"tcp/127.0.0.1:{s.getsockname()[1]}"
    mcap = tmp_path / "run.mcap"
    rec = subprocess.Popen([script("ground-station"), "record", "--insecure", "--out", str(mcap), "--zenoh-listen", endpoint],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    tele = ["--zenoh-connect", endpoint]
    sim = Sim("two_am_comp.toml", tmp_path, "--duration", "4", *tele)
    c4, c5 = companion(4, sim.bind, "two_am_comp.toml", *tele), companion(5, sim.bind, "two_am_comp.toml", *tele)
    try:
        t_kill = None
        for line in sim.proc.stdout:  # progress lines: simulation time
            ev = json.loads(line)
            if ev.get("event") == "progress" and ev["t"] >= 2.0:
                rec.kill()
                t_kill = ev["t"]
                break
        assert t_kill is not None
        code, err = sim.wait(timeout_s=240)
        assert code == 0, err  # the run went on without its logger
        for c in (c4, c5):
            c.communicate(timeout=30)
            assert c.returncode == 0
        r = subprocess.run([script("ground-station"), "review", str(mcap), "--json"], capture_output=True, text=True,
                           timeout=120)
        assert r.returncode == 0, r.stderr
        rv = json.loads(r.stdout)
        assert rv["log"]["salvaged"] is True
        assert rv["log"]["sim_time_s"][1] >= t_kill - 1.5  # lost at most about the last flush period
    finally:
        for p in (c4, c5, rec):
            if p.poll() is None:
                p.kill()
        sim.kill()


def test_am_run_keeps_flying_when_a_companion_dies_and_reports_it(tmp_path):
    """am-run does not tear the run down when a companion dies mid-run: the simulator's
    failsafe takes that vehicle, the run completes, and am-run names the dead process."""
    import os
    import threading

    run_dir = tmp_path / "r"
    p = subprocess.Popen([script("am-run"), str(SCENARIOS / "two_am_comp.toml"), "--run-dir", str(run_dir),
                          "--duration", "4", "--no-telemetry"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)

    def kill_companion_5():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            log = run_dir / "companion-5.log"
            if log.is_file() and "armed" in log.read_text():
                time.sleep(1.0)
                out = subprocess.run(["pgrep", "-f", f"companion.*--sysid 5 .*{run_dir}"], capture_output=True,
                                     text=True).stdout.split()
                for pid in out:
                    os.kill(int(pid), signal.SIGKILL)
                return
            time.sleep(0.1)

    killer = threading.Thread(target=kill_companion_5)
    killer.start()
    try:
        _, err = p.communicate(timeout=400)
    finally:
        killer.join()
        if p.poll() is None:
            p.kill()
    assert p.returncode == 1
    assert "companion 5 exited" in err and "failsafe" in err
    # redirected output: no progress bar, and no process says PyBullet's build time
    assert "s sim [" not in err and "pybullet build time" not in err, err
    assert not any("pybullet build time" in f.read_text() for f in run_dir.glob("*.log"))
    o = json.loads((run_dir / "outcome.json").read_text())
    assert o["steps"] == 4000 and o["failsafe_at_end"] == [5]  # the run was not torn down


def _am_run_under_way(run_dir, *extra):
    """An `am-run` of two_am_comp (8 s) in a process group of its own, returned once both
    companions have armed and the run has flown a second."""
    import os
    p = subprocess.Popen([script("am-run"), str(SCENARIOS / "two_am_comp.toml"), "--run-dir", str(run_dir),
                          "--duration", "8", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline:
        logs = [run_dir / f"companion-{s}.log" for s in (4, 5)]
        if all(f.is_file() and "armed" in f.read_text() for f in logs):
            time.sleep(1.0)
            return p, os.getpgid(p.pid)
        if p.poll() is not None:
            raise AssertionError(f"am-run ended before the run: {p.communicate()}")
        time.sleep(0.1)
    os.killpg(p.pid, signal.SIGKILL)
    raise AssertionError("the companions never armed")


@pytest.mark.parametrize("to", ["am-run", "the group", "the group twice"])
def test_an_interrupted_am_run_ends_the_run_and_exits_130(tmp_path, to):
    """Ctrl-C at a terminal signals every process of the group; a supervisor or `kill -INT`
    signals am-run alone. Either way the run ends within seconds (it would otherwise fly on to
    its end), every process is gone, the simulator's outcome says it was interrupted, the log is
    finished, nothing prints a traceback, and am-run exits 130 (README, "Exit codes")."""
    import os
    run_dir = tmp_path / "r"
    p, group = _am_run_under_way(run_dir)
    t0 = time.monotonic()
    try:
        if to == "am-run":
            p.send_signal(signal.SIGINT)
        else:
            os.killpg(group, signal.SIGINT)
            if to == "the group twice":  # a second Ctrl-C while the run is ending
                time.sleep(0.3)
                os.killpg(group, signal.SIGINT)
        _, err = p.communicate(timeout=60)
        took = time.monotonic() - t0
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(group, signal.SIGKILL)
    assert p.returncode == 130, err
    assert "am-run: interrupted by SIGINT" in err and "Traceback" not in err, err
    o = json.loads((run_dir / "outcome.json").read_text())
    assert o["status"] == "interrupted by SIGINT"
    assert o["sim_time_s"] < 7.0 and took < 20.0  # ended by the interrupt, not by the run's end
    assert subprocess.run(["pgrep", "-f", str(run_dir)], capture_output=True).returncode == 1  # none left
    for log in run_dir.glob("*.log"):
        assert "Traceback" not in log.read_text(), log
    assert "stopped (" in (run_dir / "recorder.log").read_text()
    assert (run_dir / "run.mcap").read_bytes().endswith(b"\x89MCAP0\r\n")  # the log finished, not truncated


def test_bad_endpoints_are_named_not_tracebacks(tmp_path):
    import socket

    for cmd in ([script("simulator"), "--bind", "tcp:127.0.0.1:x", "--run-dir", str(tmp_path / "a")],
                [script("companion"), "--sysid", "4", "--sim", "127.0.0.1"]):
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        assert p.returncode == 2, p.stderr
        assert "Traceback" not in p.stderr and ("--bind" in p.stderr or "--sim" in p.stderr)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:  # the port is taken
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        p = subprocess.run([script("simulator"), "--bind", f"udp:127.0.0.1:{port}", "--run-dir", str(tmp_path / "b"),
                            "--no-telemetry"],
                           capture_output=True, text=True, timeout=60)
    assert p.returncode == 1 and "Traceback" not in p.stderr
    assert f"cannot listen on udp:127.0.0.1:{port}" in p.stderr
