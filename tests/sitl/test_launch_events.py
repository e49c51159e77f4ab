"""am-run reads the simulator's events on their own pipe: what a library prints on the
simulator's stdout or stderr cannot break the run, and a simulator that refuses its
configuration makes am-run exit 2 with the simulator's own message."""
from __future__ import annotations

import sys
from pathlib import Path

from sitl import launch

SCENARIOS = Path(__file__).resolve().parents[2] / "configs" / "scenarios"

# a simulator whose libraries print on stdout and stderr, before and during the run (as PyBullet does)
NOISY = """
import sys, threading, time
print("b3Printf: not JSON, from a library", flush=True)
print("{ half a JSON object", flush=True)
def chatter():
    while True:
        print("pybullet build time: not an event", flush=True)
        print("warning: also on stderr", file=sys.stderr, flush=True)
        time.sleep(0.05)
threading.Thread(target=chatter, daemon=True).start()
from simulator.main import main
sys.exit(main(sys.argv[1:]))
"""

REFUSING = """
import sys
print("b3Printf: chatter first", flush=True)
print("simulator: error: /some/vehicle.toml: [vehicle].urdf: the simulator's own reason", file=sys.stderr, flush=True)
sys.exit(2)
"""


def _with_simulator(monkeypatch, tmp_path, code):
    stub = tmp_path / "stub_simulator.py"
    stub.write_text(code)
    real = launch._command
    monkeypatch.setattr(launch, "_command", lambda name: [sys.executable, str(stub)] if name == "simulator"
                        else real(name))


def test_library_output_on_the_simulators_stdout_does_not_break_am_run(monkeypatch, tmp_path, capsys):
    _with_simulator(monkeypatch, tmp_path, NOISY)
    run = tmp_path / "run"
    code = launch.main([str(SCENARIOS / "two_am_short.toml"), "--duration", "0.3", "--no-telemetry", "--gcs", "none",
                        "--run-dir", str(run), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0, err
    assert (run / "outcome.json").is_file()
    log = (run / "simulator.log").read_text()
    assert "b3Printf: not JSON" in log and "also on stderr" in log  # kept, in the log


def test_a_simulator_that_refuses_its_configuration_makes_am_run_exit_2_with_its_message(monkeypatch, tmp_path,
                                                                                           capsys):
    _with_simulator(monkeypatch, tmp_path, REFUSING)
    code = launch.main([str(SCENARIOS / "two_am_short.toml"), "--no-telemetry", "--gcs", "none",
                        "--run-dir", str(tmp_path / "run"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "the simulator's own reason" in err and "Traceback" not in err


def test_a_urdf_pybullet_cannot_load_is_a_configuration_error_on_am_runs_terminal(tmp_path, capsys):
    """A collision mesh that does not exist: pinocchio (no geometry) loads the file, PyBullet does
    not. The real simulator exits 2 with its message, and am-run exits 2 and prints it."""
    vehicles = SCENARIOS.parent / "vehicles"
    urdf = (vehicles / "am3dof.urdf").read_text()
    box = '<collision>\n      <geometry><box size="0.24 0.24 0.06"/></geometry>'
    assert urdf.count(box) == 1
    (tmp_path / "am3dof.urdf").write_text(urdf.replace(box, '<collision>\n      <geometry><mesh filename="missing.stl"/>'
                                                             '</geometry>'))
    (tmp_path / "am3dof.toml").write_text((vehicles / "am3dof.toml").read_text())
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'base = "{SCENARIOS / "two_am_short.toml"}"\n\n[scenario]\nvehicle = "{tmp_path / "am3dof.toml"}"\n')
    code = launch.main([str(scenario), "--no-telemetry", "--gcs", "none", "--run-dir", str(tmp_path / "run"),
                        "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "simulator: error:" in err and "PyBullet cannot load" in err and str(tmp_path / "am3dof.urdf") in err
    assert "Traceback" not in err
