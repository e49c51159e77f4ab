"""What `am-run` writes into a run folder besides the processes' own output: the manifest
(what was flown, how, with which software, where and when), the scenario as flown with its
vehicle files, and the keys/ folder (mode 0700) that holds the run's secrets.

    RUN/manifest.json     scenario name and source, command line, version and commit, host, start time
    RUN/scenario.toml     the scenario as flown (--duration applied), replayable: am-run RUN/scenario.toml
    RUN/vehicle/          its vehicle TOML and URDF
    RUN/keys/             link.key, gcs.key, telemetry*.key (each 0600)

Not math: file I/O at the edge of am-run.
"""
from __future__ import annotations

import copy
import datetime
import json
import os
import platform
import shutil
import socket
import subprocess
import sys
from importlib import metadata
from pathlib import Path

from amcore.config import SCENARIOS_DIR, _read_toml, load_scenario, read_scenario  # noqa: F401 (SCENARIOS_DIR: am-run)

MANIFEST = "manifest.json"
SCENARIO_AS_FLOWN = "scenario.toml"
KEYS = "keys"


def keys_dir(run_dir: Path) -> Path:
    """RUN/keys, created with mode 0700 (only its owner may list or open it), and made 0700 if
    it was there already."""
    d = Path(run_dir) / KEYS
    d.mkdir(mode=0o700, parents=True, exist_ok=True)
    os.chmod(d, 0o700)
    return d


def version() -> str:
    """The installed distribution's version ("unknown" when it is not installed)."""
    try:
        return metadata.version("amstack")
    except metadata.PackageNotFoundError:
        return "unknown"


def commit(where: Path | None = None) -> str | None:
    """The git commit of the source tree this code runs from, with "-dirty" when it has
    uncommitted changes; None outside a git work tree (an installed wheel)."""
    here = Path(where or Path(__file__).resolve().parents[1])
    if not (here / ".git").exists():
        return None
    try:
        head = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("-dirty" if dirty else "")


def write_scenario_as_flown(run_dir: Path, scenario: Path, duration_s: float | None = None) -> Path:
    """RUN/scenario.toml: `scenario` with its vehicle files copied into RUN/vehicle/ and the
    vehicle key pointing there, and [scenario].duration_s set to `duration_s` when given, so
    that `am-run RUN/scenario.toml` flies the same run again. Checked by loading it."""
    from amcore.toml_write import dumps  # a plain TOML writer (no I/O of its own)

    scenario = Path(scenario).resolve()
    data = copy.deepcopy(read_scenario(scenario))  # resolved: RUN/scenario.toml needs no base
    sc = data.setdefault("scenario", {})
    vdst = Path(run_dir) / "vehicle"
    if "vehicle" in sc:
        vpath = (scenario.parent / sc["vehicle"]).resolve()
        vdst.mkdir(exist_ok=True)
        shutil.copy2(vpath, vdst / vpath.name)
        urdf = _read_toml(vpath).get("vehicle", {}).get("urdf")
        if urdf and (vpath.parent / urdf).is_file():
            shutil.copy2(vpath.parent / urdf, vdst / Path(urdf).name)
        sc["vehicle"] = f"vehicle/{vpath.name}"
    key_file = data.get("link", {}).get("key_file")
    if key_file:  # a secret: named where it is, not copied
        data["link"]["key_file"] = str((scenario.parent / key_file).resolve())
    if duration_s is not None:
        sc["duration_s"] = float(duration_s)
    out = Path(run_dir) / SCENARIO_AS_FLOWN
    out.write_text(f"# the scenario as flown, from {scenario}\n" + dumps(data))
    load_scenario(out)
    return out


def write_manifest(run_dir: Path, scenario: Path, name: str, argv: list[str], started: datetime.datetime,
                   extra: dict | None = None) -> Path:
    """RUN/manifest.json: what this run flew and how it was started."""
    m = {
        "scenario": name,
        "scenario_source": str(Path(scenario).resolve()),
        "scenario_as_flown": SCENARIO_AS_FLOWN,
        "command_line": [Path(sys.argv[0]).name if argv is sys.argv else "am-run", *argv[1:]]
        if argv is sys.argv else ["am-run", *argv],
        "cwd": os.getcwd(),
        "version": version(),
        "commit": commit(),
        "python": platform.python_version(),
        "host": socket.gethostname(),
        "platform": platform.platform(),
        "started_utc": started.astimezone(datetime.timezone.utc).isoformat(timespec="seconds"),
        **(extra or {}),
    }
    path = Path(run_dir) / MANIFEST
    path.write_text(json.dumps(m, indent=2) + "\n")
    return path


def list_scenarios(folder: Path = SCENARIOS_DIR) -> list[dict]:
    """Every shipped scenario, loaded (so a broken one raises ConfigError naming it): its name,
    file, number of AMs, vehicle, flight-controller mode, controller, object and duration."""
    rows = []
    for p in sorted(Path(folder).glob("*.toml")):
        s = load_scenario(p)
        rows.append({"name": p.stem, "file": p, "ams": len(s.ams), "vehicle": s.vehicle.name,
                     "mode": s.vehicle.flight_controller.mode,
                     "controller": getattr(s.vehicle.options, "controller", "passivity"),
                     "object": f"{s.object.mass_kg:g} kg {s.object.shape}", "duration_s": s.duration_s})
    return rows


def format_scenarios(rows: list[dict]) -> str:
    """`list_scenarios` as the table `am-run --list` prints."""
    head = ("scenario", "AMs", "vehicle", "mode", "controller", "object", "duration")
    lines = [(r["name"], str(r["ams"]), r["vehicle"], r["mode"], r["controller"], r["object"],
              f"{r['duration_s']:g} s") for r in rows]
    w = [max(len(x[i]) for x in [head, *lines]) for i in range(len(head))]
    fmt = "  ".join(f"{{:<{n}}}" for n in w)
    return "\n".join(fmt.format(*x).rstrip() for x in [head, *lines])
