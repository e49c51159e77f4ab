"""telemetry.auth: a message is kept only when the one publisher that may write its key sealed
it with its key of this run."""
from __future__ import annotations

import os

import pytest

from telemetry.auth import TAG, parse_key, publisher_key, publisher_of, seal, unseal
from telemetry.schema import Keys, encode, run_end_event

KEYS = Keys()
MASTER = bytes(range(32))


def test_each_key_has_one_publisher():
    assert publisher_of(KEYS, KEYS.sim_event) == publisher_of(KEYS, KEYS.object) == "simulator"
    assert publisher_of(KEYS, KEYS.am_truth(4)) == publisher_of(KEYS, KEYS.contact(4)) == "simulator"
    assert publisher_of(KEYS, KEYS.controller(4)) == publisher_of(KEYS, KEYS.am_event(4)) == "am4"
    assert publisher_of(KEYS, KEYS.publisher("am5")) == "am5"
    assert publisher_of(KEYS, KEYS.batch("simulator")) == "simulator" and publisher_of(KEYS, KEYS.batch("am4")) == "am4"
    assert publisher_of(KEYS, f"{KEYS.prefix}/batch/a/b") is None
    assert publisher_of(KEYS, f"{KEYS.prefix}/batch/") is None
    assert publisher_of(KEYS, "amstack/other/thing") is None and publisher_of(KEYS, "elsewhere/sim/event") is None


def test_a_sealed_message_opens_with_the_master_and_nothing_else_does():
    body = encode(run_end_event(8.0))[0] + b"\n" + encode(run_end_event(8.0))[0]
    sim = publisher_key(MASTER, "simulator")
    sealed = seal(sim, KEYS.sim_event, body)
    assert sealed.startswith(body) and sealed.rsplit(b"\n", 1)[1].startswith(TAG)
    assert unseal(MASTER, KEYS, KEYS.sim_event, sealed) == body
    forged = [
        body,  # unsealed
        seal(publisher_key(MASTER, "am4"), KEYS.sim_event, body),  # a companion's key: no run_end from it
        seal(publisher_key(os.urandom(32), "simulator"), KEYS.sim_event, body),  # another run's key
        seal(sim, KEYS.object, body),  # sealed for another key expression
        sealed.replace(b"8.0", b"4.9", 1),  # altered after sealing
        sealed[: -1] + (b"0" if sealed[-1:] != b"0" else b"1"),  # a wrong tag
        body + b"\n" + TAG,  # an empty tag
    ]
    for f in forged:
        assert unseal(MASTER, KEYS, KEYS.sim_event, f) is None, f[-60:]
    assert unseal(MASTER, KEYS, "amstack/other/thing", seal(sim, "amstack/other/thing", body)) is None


def test_publisher_keys_differ_per_name_and_run():
    assert len({publisher_key(MASTER, n) for n in ("simulator", "am4", "am5")}) == 3
    assert publisher_key(MASTER, "am4") != publisher_key(bytes(32), "am4")


@pytest.mark.parametrize("text,ok", [("ab" * 32, True), (" " + "AB" * 32 + "\n", True), ("ab" * 31, False),
                                     ("zz" * 32, False), ("", False)])
def test_key_files_hold_64_hex_digits(text, ok):
    if ok:
        assert len(parse_key(text, "f")) == 32
    else:
        with pytest.raises(ValueError, match="f: a telemetry key file holds 64 hex digits"):
            parse_key(text, "f")
