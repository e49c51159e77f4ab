"""Start the SITL's processes through their console scripts (helpers of the SITL tests)."""
from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = ROOT / "configs" / "scenarios"


def script(name: str) -> str:
    exe = shutil.which(name, path=str(Path(sys.executable).parent))
    if exe is None:
        raise RuntimeError(f"console script '{name}' is not installed next to {sys.executable}: pip install -e .")
    return exe


@dataclass
class Run:
    code: int
    stderr: str
    outcome: dict
    companions: dict[int, dict]
    run_dir: Path


def am_run(scenario: str, run_dir: Path, *extra: str, timeout_s: float = 1500.0) -> Run:
    """`am-run` a scenario to completion and read its run folder."""
    p = subprocess.run([script("am-run"), str(SCENARIOS / scenario), "--run-dir", str(run_dir), "--no-progress",
                        *extra], capture_output=True, text=True, timeout=timeout_s)
    outcome = json.loads((run_dir / "outcome.json").read_text()) if (run_dir / "outcome.json").is_file() else {}
    comps = {int(f.stem[2:]): json.loads(f.read_text()) for f in run_dir.glob("am*.json")}
    return Run(p.returncode, p.stderr, outcome, comps, run_dir)


class Sim:
    """A `simulator` process on a free loopback port; `bind` is its endpoint once ready."""

    def __init__(self, scenario: str, run_dir: Path, *extra: str) -> None:
        self.proc = subprocess.Popen([script("simulator"), "--config", str(SCENARIOS / scenario), "--bind",
                                      "udp:127.0.0.1:0", "--run-dir", str(run_dir), "--progress", "jsonl", "--insecure",
                                      *extra],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.run_dir = run_dir
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"simulator did not start: {self.proc.stderr.read()}")
        self.bind = json.loads(line)["connect"]  # what a companion passes as --sim

    def wait(self, timeout_s: float) -> tuple[int, str]:
        out, err = self.proc.communicate(timeout=timeout_s)
        return self.proc.returncode, err

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


def companion(sysid: int, sim: str, scenario: str = "two_am_comp.toml", *extra: str) -> subprocess.Popen:
    return subprocess.Popen([script("companion"), "--sysid", str(sysid), "--sim", sim, "--config",
                             str(SCENARIOS / scenario), "--insecure", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def scenario_copy(tmp_path: Path) -> Path:
    path = tmp_path / "two_am_comp_attitude.toml"
    path.write_text(f'base = "{SCENARIOS / "two_am_comp_attitude.toml"}"\n')
    return path


class FreeSim:
    """`simulator --realtime` sending vehicle i's PX4 port to ports[i]; returns once it says its
    ports are open (its kernels may compile first, once per machine)."""

    def __init__(self, tmp_path: Path, ports: list[int], duration_s: float = 60.0, gcs: tuple = ("--gcs", "none")) -> None:
        self.run_dir = tmp_path / "run"
        onboard = [a for p in ports for a in ("--onboard", f"udpout:127.0.0.1:{p}")]
        self.proc = subprocess.Popen([script("simulator"), "--config", str(scenario_copy(tmp_path)), "--realtime",
                                      "--duration", str(duration_s), "--run-dir", str(self.run_dir), "--no-telemetry", *onboard, *gcs],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.lines: list[str] = []
        ready = threading.Event()

        def read() -> None:  # keep the pipe drained; note when the ports are up
            for line in self.proc.stderr:
                self.lines.append(line)
                if "PX4 onboard ports" in line:
                    ready.set()
            ready.set()

        self._reader = threading.Thread(target=read, daemon=True)
        self._reader.start()
        if not ready.wait(180.0) or self.proc.poll() is not None:
            self.proc.kill()
            raise RuntimeError("the simulator did not open its ports:\n" + "".join(self.lines))

    def stop(self) -> tuple[int, str, dict]:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._reader.join(5.0)
        path = self.run_dir / "outcome.json"
        return self.proc.returncode, "".join(self.lines), json.loads(path.read_text()) if path.is_file() else {}
