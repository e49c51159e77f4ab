"""PEP 517 build backend: setuptools', plus the files that let stock pymavlink tools load the
amstack dialect by name (``mavlogdump.py --dialect amstack``; see amlink/pymavlink_dialect.py).

setuptools cannot put a ``.pth`` file at the top of site-packages for both regular and
editable installs, so the wheel it builds (``pip install .``, ``pip install -e .``,
``python -m build``) is completed here: ``_amstack_pymavlink.py`` (a copy of
amlink/pymavlink_dialect.py) and ``_amstack_pymavlink.pth`` (``import _amstack_pymavlink``)
are added at the wheel's root and to its RECORD.  Everything else is setuptools' own.
"""
from __future__ import annotations

import base64
import hashlib
import os
import zipfile
from pathlib import Path

from setuptools import build_meta as _setuptools
from setuptools.build_meta import *  # noqa: F401,F403  (every other hook unchanged)

HOOK_SOURCE = Path(__file__).resolve().parents[1] / "amlink" / "pymavlink_dialect.py"
HOOK_MODULE = "_amstack_pymavlink"


CONFIGS = Path(__file__).resolve().parents[1] / "configs"
CONFIGS_IN_WHEEL = "amcore/configs"  # where amcore.config.CONFIGS_DIR looks outside a source tree


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    name = _setuptools.build_wheel(wheel_directory, config_settings, metadata_directory)
    add_dialect_hook(Path(wheel_directory) / name, shipped_configs())
    return name


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    name = _setuptools.build_editable(wheel_directory, config_settings, metadata_directory)
    add_dialect_hook(Path(wheel_directory) / name)
    return name


def _record_line(path: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{path},sha256={digest},{len(data)}"


def shipped_configs() -> dict[str, bytes]:
    """configs/ (the scenarios, vehicles, randomizations and Zenoh settings) as wheel entries
    under amcore/configs/: a regular install's `am-run` then finds its default scenario.
    An editable install reads the source tree's configs/ instead."""
    return {f"{CONFIGS_IN_WHEEL}/{p.relative_to(CONFIGS).as_posix()}": p.read_bytes()
            for p in sorted(CONFIGS.rglob("*")) if p.is_file() and "__pycache__" not in p.parts}


def add_dialect_hook(wheel: Path, extra: dict[str, bytes] | None = None) -> None:
    """Rewrite ``wheel`` with the hook module and its .pth at the root (and the `extra` entries),
    listed in RECORD."""
    added = {f"{HOOK_MODULE}.py": HOOK_SOURCE.read_bytes(), f"{HOOK_MODULE}.pth": f"import {HOOK_MODULE}\n".encode(),
             **(extra or {})}
    tmp = wheel.with_suffix(".tmp")
    with zipfile.ZipFile(wheel) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as dst:
        record = next(n for n in src.namelist() if n.endswith(".dist-info/RECORD"))
        for item in src.infolist():
            if item.filename != record and item.filename not in added:
                dst.writestr(item, src.read(item.filename))
        for name, data in added.items():
            dst.writestr(name, data)
        lines = [ln for ln in src.read(record).decode().splitlines() if ln and ln.split(",")[0] not in added]
        lines[-1:-1] = [_record_line(n, d) for n, d in added.items()]  # RECORD's own line stays last
        dst.writestr(record, "\n".join(lines) + "\n")
    os.replace(tmp, wheel)
