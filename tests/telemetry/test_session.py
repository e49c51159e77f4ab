"""Zenoh configuration: role defaults, explicit endpoints, config files, argparse."""
from __future__ import annotations

import argparse
import json

import pytest

from telemetry.session import (DEFAULT_ENDPOINT, TelemetryConfigError, ZenohOptions, add_zenoh_arguments,
                               build_config, config_items, options_from_args)


def test_default_roles_meet_on_loopback_without_scouting():
    pub, rec = config_items(ZenohOptions(role="publisher")), config_items(ZenohOptions(role="recorder"))
    assert pub["mode"] == rec["mode"] == "peer"
    assert pub["connect/endpoints"] == [DEFAULT_ENDPOINT] and pub["listen/endpoints"] == []
    assert rec["listen/endpoints"] == [DEFAULT_ENDPOINT] and rec["connect/endpoints"] == []
    assert DEFAULT_ENDPOINT.startswith("tcp/127.0.0.1:")
    for items in (pub, rec):
        assert items["scouting/multicast/enabled"] is False and items["scouting/gossip/enabled"] is False
        assert items["scouting/delay"] == 0


def test_config_file_keeps_its_own_sections_unless_overridden(tmp_path):
    f = tmp_path / "z.json5"
    f.write_text('{ mode: "client", connect: { endpoints: ["tcp/10.0.0.1:7447"] } }')
    items = config_items(ZenohOptions(config_file=f, mode="client"))
    assert "connect/endpoints" not in items and "scouting/multicast/enabled" not in items
    items = config_items(ZenohOptions(config_file=f, mode="client", connect=("tcp/10.0.0.2:7447",)))
    assert items["connect/endpoints"] == ["tcp/10.0.0.2:7447"]
    cfg = build_config(ZenohOptions(config_file=f, mode="client"))
    assert json.loads(cfg.get_json("connect/endpoints")) == ["tcp/10.0.0.1:7447"]


def test_build_config_holds_the_items():
    opts = ZenohOptions(role="recorder", mode="router", listen=("tcp/0.0.0.0:7448",))
    cfg = build_config(opts)
    assert json.loads(cfg.get_json("mode")) == "router"
    assert json.loads(cfg.get_json("listen/endpoints")) == ["tcp/0.0.0.0:7448"]
    assert json.loads(cfg.get_json("scouting/multicast/enabled")) is False


def test_bad_options_raise_typed_errors(tmp_path):
    with pytest.raises(TelemetryConfigError):
        ZenohOptions(mode="broker")
    with pytest.raises(TelemetryConfigError):
        ZenohOptions(role="viewer")
    with pytest.raises(ValueError):
        ZenohOptions(prefix="amstack/**")
    with pytest.raises(TelemetryConfigError):
        build_config(ZenohOptions(config_file=tmp_path / "missing.json5"))
    bad = tmp_path / "bad.json5"
    bad.write_text("{ mode: ")
    with pytest.raises(TelemetryConfigError):
        build_config(ZenohOptions(config_file=bad))


@pytest.mark.parametrize("role", ["publisher", "recorder"])
def test_argparse_round_trip(role):
    ap = argparse.ArgumentParser()
    add_zenoh_arguments(ap, role)
    default = options_from_args(ap.parse_args(["--insecure"]), role)
    assert default == ZenohOptions(role=role)
    a = ap.parse_args(["--insecure", "--zenoh-mode", "client", "--zenoh-connect", "tcp/192.168.1.5:7447", "--zenoh-connect",
                       "tcp/192.168.1.6:7447", "--zenoh-listen", "none", "--telemetry-prefix", "lab"])
    o = options_from_args(a, role)
    assert (o.mode, o.connect_endpoints, o.listen_endpoints, o.prefix) == (
        "client", ("tcp/192.168.1.5:7447", "tcp/192.168.1.6:7447"), (), "lab")
    if role == "publisher":
        assert options_from_args(ap.parse_args(["--no-telemetry"]), role).enabled is False


@pytest.mark.parametrize("role", ["publisher", "recorder"])
def test_without_a_telemetry_key_nothing_publishes_or_records_unless_insecure(role, tmp_path):
    """Secure by default: no key is a configuration error that says how to pass one; --insecure
    goes without, and a key file gives the options its key."""
    ap = argparse.ArgumentParser()
    add_zenoh_arguments(ap, role)
    with pytest.raises(TelemetryConfigError) as err:
        options_from_args(ap.parse_args([]), role)
    msg = str(err.value)
    assert "no telemetry key" in msg and "--telemetry-key-file FILE" in msg and "--insecure" in msg
    assert "ground-station keys DIR" in msg
    assert options_from_args(ap.parse_args(["--insecure"]), role).auth_key is None
    key = tmp_path / "k"
    key.write_text("ab" * 32 + "\n")
    assert options_from_args(ap.parse_args(["--telemetry-key-file", str(key)]), role).auth_key == bytes.fromhex("ab" * 32)
    if role == "publisher":  # publishing nothing needs no key
        assert options_from_args(ap.parse_args(["--no-telemetry"]), role).enabled is False
    else:
        assert "--no-telemetry" not in msg
