"""The amstack dialect: free message IDs, MAVLink 2 limits, generation and caching."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from amlink import dialect
from amlink.types import SetpointFlag, StepFlag

SHIPPED_XML = sorted(dialect.PYMAVLINK_V20_DIR.glob("*.xml"))
OUR_MESSAGES = ("AM_SIM_STEP", "AM_JOINT_STATE", "AM_WRENCH", "AM_TORQUE_SETPOINT", "AM_SCENARIO",
                "AM_JOINT_TORQUE_SETPOINT", "AM_OBJECT_POSE")
REPO = Path(__file__).resolve().parents[2]


def _messages(path: Path) -> dict[int, str]:
    return {int(m.get("id")): m.get("name") for m in ET.parse(path).getroot().iter("message")}


def test_pymavlink_ships_dialects_to_check_against():
    names = {p.name for p in SHIPPED_XML}
    assert {"common.xml", "ardupilotmega.xml", "all.xml", "development.xml"} <= names


def test_our_ids_collide_with_no_shipped_dialect():
    ours = _messages(dialect.XML_PATH)
    assert sorted(ours.values()) == sorted(OUR_MESSAGES)
    for path in SHIPPED_XML:
        theirs = _messages(path)
        clash = {i: (ours[i], theirs[i]) for i in set(ours) & set(theirs)}
        assert not clash, f"{path.name} already uses {clash}"
        same_name = set(ours.values()) & set(theirs.values())
        assert not same_name, f"{path.name} already defines {same_name}"


def _commands(path: Path) -> dict[int, str]:
    return {int(e.get("value")): e.get("name") for enum in ET.parse(path).getroot().iter("enum")
            if enum.get("name") == "MAV_CMD" for e in enum.iter("entry")}


def test_our_commands_collide_with_no_shipped_dialect():
    ours = _commands(dialect.XML_PATH)
    assert ours == {24000: "MAV_CMD_AM_ABORT_MISSION"}
    for path in SHIPPED_XML:
        theirs = _commands(path)
        assert not set(ours) & set(theirs), f"{path.name} already uses MAV_CMD {set(ours) & set(theirs)}"
    mav = dialect.load()
    assert mav.MAV_CMD_AM_ABORT_MISSION == 24000 and mav.MAV_CMD_NAV_LAND == 21  # merged into common's MAV_CMD


def test_our_ids_fit_mavlink2_and_uint16_message_id_fields():
    for msg_id in _messages(dialect.XML_PATH):
        assert 255 < msg_id < 2**24  # MAVLink 2 only, 24-bit id
        assert msg_id < 2**16  # MESSAGE_INTERVAL.message_id is uint16


def test_generated_module_has_our_messages_with_payload_within_255_bytes():
    mav = dialect.load()
    ours = _messages(dialect.XML_PATH)
    for msg_id, name in ours.items():
        cls = mav.mavlink_map[msg_id]
        assert cls.msgname == name
        assert cls.unpacker.size <= 255, f"{name} payload {cls.unpacker.size} B"
    assert mav.WIRE_PROTOCOL_VERSION == "2.0"


def test_flag_enums_mirror_the_xml():
    mav = dialect.load()
    assert int(StepFlag.SHUTDOWN) == mav.AM_STEP_FLAG_SHUTDOWN
    assert int(StepFlag.FAILSAFE) == mav.AM_STEP_FLAG_FAILSAFE
    assert int(SetpointFlag.FAULT) == mav.AM_SETPOINT_FLAG_FAULT
    assert int(SetpointFlag.SATURATED) == mav.AM_SETPOINT_FLAG_SATURATED


@settings(database=None)
@given(st.binary(max_size=300), st.integers(0, 0xFFFF))
def test_fast_crc_equals_pymavlink_reference(data, init):
    ref = dialect.load()._x25crc_slow()
    ref.crc = init
    ref.accumulate(data)
    assert dialect.mcrf4xx(data, init) == ref.crc


def test_generated_module_lives_in_cache_not_in_package():
    mod = dialect.load()
    path = Path(mod.__file__).resolve()
    assert path.parent == dialect.cache_dir().resolve()
    assert dialect.source_hash() in path.name
    assert not list((REPO / "amlink").rglob("amstack*.py"))


def test_cache_dir_env_override(monkeypatch, tmp_path):
    monkeypatch.setenv(dialect.CACHE_ENV, str(tmp_path / "c"))
    assert dialect.generated_path().parent == tmp_path / "c"
    monkeypatch.delenv(dialect.CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert dialect.cache_dir() == tmp_path / "xdg" / "amstack"


def test_concurrent_first_use_generates_one_complete_module(tmp_path):
    """Three processes start at once on an empty cache; all import the same module."""
    cache = tmp_path / "cache"
    env = {**os.environ, dialect.CACHE_ENV: str(cache), "PYTHONPATH": str(REPO)}
    code = "from amlink import dialect; m = dialect.load(); print(m.MAVLINK_MSG_ID_AM_SIM_STEP, m.__file__)"
    run = [sys.executable, "-c", code]
    procs = [subprocess.Popen(run, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(3)]
    outs = [p.communicate(timeout=60) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err
    files = {out.split()[1] for out, _ in outs}
    assert {out.split()[0] for out, _ in outs} == {"24000"}
    assert len(files) == 1
    name = Path(files.pop()).name
    assert sorted(f.name for f in cache.iterdir()) == ["__pycache__", name]  # no temp leftovers
    # and its bytecode, written once beside it (PYTHONDONTWRITEBYTECODE or not)
    assert [f.name for f in (cache / "__pycache__").iterdir()] == [Path(importlib.util.cache_from_source(name)).name]


def test_generation_failure_is_a_typed_error(monkeypatch, tmp_path):
    bad = tmp_path / "amstack.xml"
    bad.write_text(dialect.XML_PATH.read_text().replace('id="24001"', 'id="24000"'))  # duplicate id
    monkeypatch.setattr(dialect, "XML_PATH", bad)
    with pytest.raises(dialect.DialectGenerationError):
        dialect.generate(tmp_path / "out" / "amstack_x.py")
    assert not (tmp_path / "out" / "amstack_x.py").exists()
