"""The amstack MAVLink 2 dialect, generated from XML by pymavlink's mavgen on first use.

The generated Python module is never committed.  :func:`load` builds it from
``amlink/dialect/amstack.xml`` (plus pymavlink's own ardupilotmega.xml and all it includes)
into a cache directory and imports it:

* cache directory: ``$AMSTACK_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/amstack``,
  else ``~/.cache/amstack``;
* file name: ``amstack_<hash>.py`` where the hash covers every XML file that
  goes into the build and the pymavlink version, so an edit to the dialect or a
  pymavlink upgrade regenerates it;
* generation happens in a private temporary directory and the result is moved in
  place with ``os.replace``, so several processes starting at once never see a
  half-written file (the last writer wins with identical content).

Usage::

    from amlink import dialect
    mav = dialect.load()          # the generated module
    parser = mav.MAVLink(None, srcSystem=1, srcComponent=1)
"""

from __future__ import annotations

import binascii
import contextlib
import hashlib
import importlib.util
import io
import os
import py_compile
import shutil
import sys
import tempfile
import threading
import types
from pathlib import Path

import pymavlink
from pymavlink.generator import mavgen, mavparse

DIALECT_NAME = "amstack"
XML_PATH = Path(__file__).resolve().parent / "dialect" / f"{DIALECT_NAME}.xml"
# pymavlink ships the included standard definitions next to its generated dialects.
PYMAVLINK_V20_DIR = Path(pymavlink.__file__).resolve().parent / "dialects" / "v20"


def _includes(xml: Path) -> list[str]:
    """The file names a dialect XML <include>s, in order."""
    import xml.etree.ElementTree as ET

    return [(e.text or "").strip() for e in ET.parse(xml).getroot().findall("include")]


def _included_closure(xml: Path, folder: Path) -> tuple[str, ...]:
    """Every XML that `xml` includes, directly or not, from pymavlink's `folder`."""
    seen: list[str] = []
    todo = _includes(xml)
    while todo:
        name = todo.pop(0)
        if name not in seen:
            seen.append(name)
            todo += _includes(folder / name)
    return tuple(seen)


# ardupilotmega.xml and what it includes (common, standard, minimal, ...), as pymavlink ships them:
# the dialect carries everything stock tools (MAVProxy, MAVExplorer) expect of a vehicle
INCLUDED_XML = _included_closure(XML_PATH, PYMAVLINK_V20_DIR)
CACHE_ENV = "AMSTACK_CACHE_DIR"

_lock = threading.Lock()
_module: types.ModuleType | None = None


class DialectGenerationError(RuntimeError):
    """mavgen failed to build the dialect; carries mavgen's captured output."""


def cache_dir() -> Path:
    """Directory holding generated modules (see module docstring for the lookup order)."""
    override = os.environ.get(CACHE_ENV)
    if override:
        return Path(override)
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / DIALECT_NAME


def _pymavlink_version() -> str:
    try:
        from importlib.metadata import version

        return version("pymavlink")
    except Exception:  # pragma: no cover - metadata missing in odd installs
        return getattr(pymavlink, "__version__", "unknown")


def source_hash() -> str:
    """Hash of all XML that goes into the build plus the pymavlink version (16 hex chars)."""
    h = hashlib.sha256()
    h.update(_pymavlink_version().encode())
    for path in (XML_PATH, *(PYMAVLINK_V20_DIR / n for n in INCLUDED_XML)):
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def generated_path() -> Path:
    """Path of the generated module for the current XML and pymavlink version."""
    return cache_dir() / f"{DIALECT_NAME}_{source_hash()}.py"


def generate(dest: Path) -> Path:
    """Run mavgen (MAVLink 2.0, Python) on the dialect and atomically write ``dest``."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="amstack-build-", dir=dest.parent) as build:
        build_dir = Path(build)
        for name in INCLUDED_XML:
            shutil.copyfile(PYMAVLINK_V20_DIR / name, build_dir / name)
        xml = build_dir / XML_PATH.name
        shutil.copyfile(XML_PATH, xml)
        out = build_dir / DIALECT_NAME  # mavgen appends ".py" for Python
        try:
            import lxml  # noqa: F401  (mavgen validates against its XSD only with lxml)

            validate = True
        except ImportError:
            validate = False
        opts = mavgen.Opts(
            str(out),
            wire_protocol=mavparse.PROTOCOL_2_0,
            language="Python",
            validate=validate,
        )
        log = io.StringIO()
        try:
            with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
                ok = mavgen.mavgen(opts, [str(xml)])
        except SystemExit as exc:  # mavgen calls exit() on validation failure
            raise DialectGenerationError(f"mavgen exited ({exc}):\n{log.getvalue()}") from exc
        produced = out.with_suffix(".py")
        if not ok or not produced.exists():
            raise DialectGenerationError(f"mavgen failed on {XML_PATH}:\n{log.getvalue()}")
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.tmp")
        shutil.copyfile(produced, tmp)
        os.replace(tmp, dest)
    return dest


# CRC-16/MCRF4XX (the MAVLink "X.25" checksum) in C speed without extra packages.
# MCRF4XX is CRC-16/CCITT with reflected input and output, so it equals the
# bit-reversed CRC-CCITT (binascii.crc_hqx) of the bit-reversed bytes, started
# from the bit-reversed initial value.  ~35x faster than pymavlink's pure-Python
# fallback; tests compare it against that fallback.
_REV8 = bytes(int(f"{i:08b}"[::-1], 2) for i in range(256))


def _rev16(x: int) -> int:
    return (_REV8[x & 0xFF] << 8) | _REV8[x >> 8]


def mcrf4xx(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/MCRF4XX of ``data`` continuing from ``crc`` (same contract as fastcrc's)."""
    return _rev16(binascii.crc_hqx(bytes(data).translate(_REV8), _rev16(crc)))


def _install_fast_crc(module: types.ModuleType) -> None:
    """Plug :func:`mcrf4xx` into the generated module unless fastcrc already is."""
    if getattr(module, "mcrf4xx", None) is None and hasattr(module, "_x25crc_fast"):
        module.mcrf4xx = mcrf4xx
        module.x25crc = module._x25crc_fast


def _compile_once(path: Path) -> None:
    """Write the module's bytecode beside it if it is missing, even where bytecode writing is
    off (PYTHONDONTWRITEBYTECODE): compiling the 1.8 MB source on every import costs each
    process ~0.3 s and ~40-60 MiB of resident memory that it never returns; unmarshalling the
    bytecode, ~29 MiB."""
    cached = Path(importlib.util.cache_from_source(str(path)))
    if cached.exists():
        return
    with contextlib.suppress(OSError, py_compile.PyCompileError):  # read-only cache: import compiles, as before
        py_compile.compile(str(path), cfile=str(cached), doraise=True)


def load() -> types.ModuleType:
    """Return the generated dialect module, generating it into the cache if needed.

    Cached per process; safe to call from several threads and processes.
    """
    global _module
    with _lock:
        if _module is not None:
            return _module
        path = generated_path()
        if not path.exists():
            generate(path)
        _compile_once(path)
        mod_name = f"amlink._generated.{path.stem}"
        spec = importlib.util.spec_from_file_location(mod_name, path)
        if spec is None or spec.loader is None:  # pragma: no cover
            raise DialectGenerationError(f"cannot import generated module {path}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[mod_name] = module
        spec.loader.exec_module(module)
        _install_fast_crc(module)
        _module = module
        return module
