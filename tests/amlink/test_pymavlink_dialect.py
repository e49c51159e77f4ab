"""Stock pymavlink tools find the amstack dialect by name once amstack is installed."""

from __future__ import annotations

import base64
import hashlib
import importlib.util
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from amlink.codec import mav
from amlink.tlog import TlogWriter
from amlink.wire import Encoder
from tests.amlink import codec_reference as ref
from tests.amlink.kit import make_frame

REPO = Path(__file__).resolve().parents[2]
SITE_HOOK = "_amstack_pymavlink.pth"


def _mavlogdump() -> str:
    exe = shutil.which("mavlogdump.py", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.fail(f"pymavlink's mavlogdump.py is not installed next to {sys.executable}")
    return exe


def _require_installed_hook() -> None:
    if not any((Path(p) / SITE_HOOK).is_file() for p in sys.path):
        pytest.fail(f"{SITE_HOOK} is not in site-packages: reinstall amstack (pip install -e .), whose build "
                    f"backend adds it")


def test_mavlogdump_decodes_our_messages_with_dialect_amstack(tmp_path):
    _require_installed_hook()
    log = tmp_path / "t.tlog"
    enc = Encoder(4, 1, signing_key=bytes(range(32)), link_id=4)
    with TlogWriter(log) as w:
        w.write(enc.pack([mav.MAVLink_heartbeat_message(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4, 129,
                                                        6 << 16, mav.MAV_STATE_ACTIVE, 3)]))
        w.write(enc.pack(ref.sensor_frame_messages(make_frame(2, 3), 7)))  # one datagram, four records
        w.write(enc.pack([mav.MAVLink_command_long_message(4, 1, mav.MAV_CMD_AM_ABORT_MISSION, 0, 0, 0, 0, 0, 0, 0,
                                                           0)]))
    assert w.records == 6
    p = subprocess.run([_mavlogdump(), "--dialect", "amstack", str(log)], capture_output=True, text=True, timeout=60,
                       env=_clean_env(), cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    lines = p.stdout.splitlines()
    assert [ln.split(": ", 1)[1].split(" ", 1)[0] for ln in lines] == [
        "HEARTBEAT", "ODOMETRY", "AM_JOINT_STATE", "AM_WRENCH", "AM_SIM_STEP", "COMMAND_LONG"]
    assert "step : 3" in lines[2] and "command : 24000" in lines[5]
    # MAVLINK_DIALECT=amstack: mavutil loads it when imported (it raised FileNotFoundError); mavlogdump then
    # switches to its own --dialect default, so it is --dialect amstack that decodes our messages
    p = subprocess.run([_mavlogdump(), str(log)], capture_output=True, text=True, timeout=60,
                       env={**_clean_env(), "MAVLINK_DIALECT": "amstack"}, cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    p = subprocess.run([sys.executable, "-c", "from pymavlink import mavutil; print(mavutil.mavlink.MAV_CMD_AM_ABORT_MISSION)"],
                       capture_output=True, text=True, timeout=60, env={**_clean_env(), "MAVLINK_DIALECT": "amstack"},
                       cwd=tmp_path)
    assert p.stdout.strip() == "24000", p.stderr
    stock = subprocess.run([_mavlogdump(), str(log)], capture_output=True, text=True, timeout=60, env=_clean_env(),
                           cwd=tmp_path)
    assert "UNKNOWN_24001" in stock.stdout  # without the dialect: what the issue saw


def _clean_env() -> dict:
    import os

    return {k: v for k, v in os.environ.items() if k not in ("MAVLINK_DIALECT", "MAVLINK20", "MDEF", "PYTHONPATH")}


def test_build_backend_adds_the_hook_and_its_record_lines_to_a_wheel(tmp_path):
    pytest.importorskip("setuptools")
    spec = importlib.util.spec_from_file_location("amstack_build", REPO / "build_backend" / "amstack_build.py")
    backend = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(backend)
    wheel = tmp_path / "demo-1.0-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as z:
        z.writestr("demo/__init__.py", "x = 1\n")
        z.writestr("demo-1.0.dist-info/RECORD", "demo/__init__.py,,6\ndemo-1.0.dist-info/RECORD,,\n")
    backend.add_dialect_hook(wheel)
    with zipfile.ZipFile(wheel) as z:
        assert z.read("_amstack_pymavlink.pth") == b"import _amstack_pymavlink\n"
        assert z.read("_amstack_pymavlink.py") == (REPO / "amlink" / "pymavlink_dialect.py").read_bytes()
        record = z.read("demo-1.0.dist-info/RECORD").decode().splitlines()
        assert record[-1] == "demo-1.0.dist-info/RECORD,,"
        for name in ("_amstack_pymavlink.pth", "_amstack_pymavlink.py"):
            data = z.read(name)
            digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
            assert f"{name},sha256={digest},{len(data)}" in record


def test_the_finder_answers_only_the_amstack_dialect_names():
    from amlink.pymavlink_dialect import MODULE_NAMES, DialectFinder

    finder = DialectFinder()
    assert finder.find_spec("pymavlink.dialects.v20.common") is None
    assert finder.find_spec("amstack") is None
    for name in MODULE_NAMES:
        spec = finder.find_spec(name)
        assert spec is not None and spec.name == name and spec.origin.endswith(".py")
