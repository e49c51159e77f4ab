"""A run's telemetry keys as files (telemetry.auth): the recorder's master key and each
publisher's own key, derived from it, each in a file only its owner can read (mode 0600).

    telemetry.key                 the master key: `ground-station record --telemetry-key-file`
    telemetry-simulator.key       `simulator --telemetry-key-file`
    telemetry-am<sysid>.key       `companion --sysid <sysid> --telemetry-key-file`

`am-run` writes a new set into every run folder; `ground-station keys DIR` writes one for
processes started by hand (docs/architecture.md).
"""
from __future__ import annotations

import os
from pathlib import Path

from .auth import KEY_BYTES, publisher_key

MASTER_FILE = "telemetry.key"


def publisher_file(name: str) -> str:
    """The file name of publisher `name`'s key ('simulator', 'am4', ...)."""
    return f"telemetry-{name}.key"


def write_secret(path: Path, text: str) -> Path:
    """`text` and a newline in a file only its owner can read or write (mode 0600)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as fh:
        fh.write(text + "\n")
    return path


def write_run_keys(folder: Path, sysids, master: bytes | None = None) -> dict[str, Path]:
    """A random master key (or `master`) and the keys of the simulator and of the companions
    `sysids`, in `folder` (created if need be): {"recorder": master file, "simulator": ..., "am<sysid>": ...}.
    All or nothing: if one cannot be written (OSError), those written are removed again, so
    that a retry is not refused for a master key left behind without its publishers' keys."""
    master = os.urandom(KEY_BYTES) if master is None else master
    Path(folder).mkdir(parents=True, exist_ok=True)
    keys = {"recorder": (Path(folder) / MASTER_FILE, master.hex())}
    for name in ["simulator"] + [f"am{s}" for s in sysids]:
        keys[name] = (Path(folder) / publisher_file(name), publisher_key(master, name).hex())
    files: dict[str, Path] = {}
    try:
        for name, (path, text) in keys.items():
            files[name] = path  # before the write: a file that fails half-written goes too
            write_secret(path, text)
    except OSError:
        for path in files.values():
            path.unlink(missing_ok=True)
        raise
    return files
