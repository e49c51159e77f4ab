"""The recorder's listening socket under junk: raw bytes on its TCP port and malformed
payloads on every kind of key. It survives, counts what it cannot use, keeps every valid
sample, and still stops on the run's end and leaves a readable log."""
from __future__ import annotations

import json
import math
import random
import socket
import struct

import zenoh

from ground_station.mcap_io import read_log
from telemetry import schema, wire
from telemetry.session import ZenohOptions, build_config

from ..telemetry.zenoh_testing import free_endpoint
from .proc import RecorderProcess


def _junk(rng: random.Random) -> bytes:
    kind = rng.randrange(10)
    if kind == 7:  # binary framing, random content
        return wire.MAGIC + rng.randbytes(rng.randrange(0, 600))
    if kind == 8:  # well-framed binary samples of random bytes (some long enough for a t/seq header)
        return wire.binary_message([rng.randbytes(rng.randrange(0, 700)) for _ in range(rng.randrange(1, 5))])
    if kind == 9:  # a frame longer than the message
        return wire.MAGIC + struct.pack("<I", 10**6) + rng.randbytes(50)
    if kind == 0:
        return rng.randbytes(rng.randrange(0, 2000))
    if kind == 1:
        return b"{not json"
    if kind == 2:
        return json.dumps({"t": "soon", "seq": -1}).encode()
    if kind == 3:
        return b'{"t": NaN, "seq": 1, "r_c": [Infinity, 1, 2]}'
    if kind == 4:
        return json.dumps({"t": 1e308, "seq": 2**70, "sysid": "x" * 100000}).encode()
    if kind == 5:
        return json.dumps([1, 2, 3]).encode()
    return json.dumps({"t": rng.random(), "seq": rng.randrange(5), "phase": None}).encode()


def test_recorder_survives_junk_and_keeps_the_valid_samples(tmp_path):
    endpoint = free_endpoint()
    host, port = endpoint.split("/")[1].rsplit(":", 1)
    rng = random.Random(7)
    keys = schema.Keys()
    with RecorderProcess(tmp_path / "fuzz.mcap", endpoint) as rec:
        for _ in range(50):  # raw junk on the zenoh port: not even a zenoh session
            with socket.create_connection((host, int(port)), timeout=2) as s:
                try:
                    s.sendall(rng.randbytes(rng.randrange(1, 4096)))
                except OSError:
                    pass  # the recorder may drop the connection: that is fine
        session = zenoh.open(build_config(ZenohOptions(role="publisher", connect=(endpoint,))))
        try:
            targets = [keys.controller(4), keys.object, keys.sim_event, keys.contact(4), keys.am_truth(4),
                       f"{keys.prefix}/am/notanumber/controller", f"{keys.prefix}/whatever/else"]
            for i in range(3000):
                session.put(rng.choice(targets), _junk(rng))
            # and genuine samples after them, sent as the project's publisher sends (congestion
            # control BLOCK, telemetry.publisher): zenoh's default for a put drops when the queue
            # toward a recorder still busy with the junk is full, which on a loaded machine lost
            # 194 of these 200 before they reached it
            block = zenoh.CongestionControl.BLOCK
            for i in range(200):
                ev = schema.phase_event(i * 0.01, "approach", "simulator") | {"seq": i}
                session.put(keys.sim_event, schema.encode(ev)[0], congestion_control=block)
            session.put(keys.sim_event, schema.encode(schema.run_end_event(2.0, "completed") | {"seq": 200})[0],
                        congestion_control=block)
        finally:
            session.close()
        code, out = rec.wait(timeout_s=60)
    assert code == 0, rec.stderr_lines
    summary = json.loads(out)
    assert summary["malformed"] + summary["unknown"] > 1000, summary
    log = read_log(tmp_path / "fuzz.mcap")
    assert not log.truncated
    events = [m for _, m in log.decoded("/sim/event")]
    assert len([e for e in events if e.get("kind") == "phase"]) == 200
    assert all(math.isfinite(e["t"]) for e in events)
