"""The companion process main's own messages (in-process: nothing is started)."""
from __future__ import annotations

from pathlib import Path

from companion.main import main


def test_a_bad_sim_endpoint_lists_udp_as_a_send_form_as_the_companion_reads_it(capsys):
    """mavutil's udp: listens; the companion's --sim udp: has always sent: its error's list of
    forms says so, instead of calling udp: the same as udpin:."""
    assert main(["--sysid", "4", "--sim", "udp:1.2.3"]) == 2
    err = capsys.readouterr().err
    assert "--sim: endpoint 'udp:1.2.3'" in err
    assert "(udp:HOST:PORT is the same)" not in err
    assert "udpout:HOST:PORT   send UDP to HOST:PORT (udp:HOST:PORT is read as this here" in err


def test_without_a_telemetry_key_the_companion_exits_2_saying_how_to_pass_one(capsys):
    short = str(Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_short.toml")
    assert main(["--sysid", "4", "--config", short]) == 2
    err = capsys.readouterr().err
    assert "no telemetry key" in err and "--telemetry-key-file FILE" in err and "--insecure" in err
    assert "--no-telemetry" in err
