"""The scenario's [link] table and per-AM keys, and how amlink turns them into keys and an impairment."""

from __future__ import annotations

import pytest

from amcore.config import ConfigError, load_scenario
from amlink import signing
from amlink.impair import LinkImpairment
from tests.conftest import SCENARIO

KEY_HEX = "ab" * 32


def scenario_with(tmp_path, text: str):
    body = SCENARIO.read_text().replace('vehicle = "../vehicles/am3dof.toml"',
                                        f'vehicle = "{SCENARIO.parent.parent / "vehicles" / "am3dof.toml"}"')
    p = tmp_path / "s.toml"
    p.write_text(body + "\n" + text)
    return p


def test_existing_scenarios_load_with_signing_on_and_public_development_keys(spec):
    assert spec.link.signing and spec.link.key_file == "" and all(am.signing_key_hex == "" for am in spec.ams)
    keys = signing.keys_for_scenario(spec)
    assert set(keys) == {am.sysid for am in spec.ams}
    assert {src for _k, src in keys.values()} == {"development"}
    assert len({k for k, _src in keys.values()}) == len(keys)
    assert LinkImpairment.for_scenario(spec).is_ideal


def test_link_table_key_file_and_per_am_key(tmp_path):
    (tmp_path / "link.key").write_text(KEY_HEX + "\n")
    text = '[link]\nsigning = true\nkey_file = "link.key"\nloss = 0.1\ndelay_s = 0.004\n'
    path = scenario_with(tmp_path, text)
    path.write_text(path.read_text().replace("sysid = 5\n", f'sysid = 5\nsigning_key_hex = "{"cd" * 32}"\n'))
    spec = load_scenario(path)
    keys = signing.keys_for_scenario(spec)
    assert keys[4] == (signing.derive_vehicle_key(bytes.fromhex(KEY_HEX), 4), "master")
    assert keys[5] == (bytes.fromhex("cd" * 32), "vehicle")
    imp = LinkImpairment.for_scenario(spec)
    assert (imp.loss, imp.delay_steps, imp.seed) == (0.1, 4, spec.seed)


@pytest.mark.parametrize("text,match", [
    ("[link]\nsign = true\n", "unknown key 'sign'"),
    ("[link]\nloss = 1.5\n", "loss"),
    ("[link]\ndelay_s = -0.1\n", "delay_s"),
    ('[link]\nkey_file = "nope.key"\n', "key_file"),
    ("[link]\nsigning = 1\n", "signing"),
    ('[link]\njoints = "can_bus"\n', r"\[link\]\.joints: expected one of servo_bus, link, got 'can_bus'"),
])  # fmt: skip
def test_bad_link_tables_are_rejected_naming_the_key(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        load_scenario(scenario_with(tmp_path, text))


def test_bad_per_am_key_is_rejected(tmp_path):
    path = scenario_with(tmp_path, "")
    path.write_text(path.read_text().replace("sysid = 5\n", 'sysid = 5\nsigning_key_hex = "abc"\n'))
    with pytest.raises(ConfigError, match="signing_key_hex"):
        load_scenario(path)
