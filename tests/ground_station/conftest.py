"""A short simulated run captured once per session: the telemetry it produced and its ground truth."""
from __future__ import annotations

from dataclasses import dataclass

import pytest

from telemetry import binary
from telemetry.schema import Keys

from . import simrun


@dataclass
class Capture:
    spec: object
    samples: list  # (key, payload) in publication order, seq not yet stamped; hot channels binary (bytes)
    truths: list  # simulator GroundTruth of every published step


@pytest.fixture(scope="session")
def capture(spec, model) -> Capture:
    short = simrun.short_spec(spec)
    samples, truths = [], []
    simrun.run(short, model, 1.3, lambda k, p: samples.append((k, p)), Keys(), on_truth=truths.append)
    return Capture(short, samples, truths)


def stamped(samples):
    """Copies of (key, payload) with per-key seq, as a publisher would send them."""
    counters: dict[str, int] = {}
    out = []
    for k, p in samples:
        seq = counters.get(k, 0)
        counters[k] = seq + 1
        out.append((k, binary.with_seq(p, seq) if isinstance(p, bytes) else {**p, "seq": seq}))
    return out


def as_json(samples):
    """The samples with every binary one as the JSON payload it stands for (what a publisher
    of JSON samples sends)."""
    keys = Keys()
    return [(k, binary.to_dict(keys.parse(k).channel, p) if isinstance(p, bytes) else p) for k, p in samples]


def sample_time(payload) -> float:
    return binary.header(payload)[0] if isinstance(payload, bytes) else payload["t"]


def wire_form(payload) -> tuple[bytes, bool]:
    """(sample bytes, binary?) as the recorder's translator takes a sample."""
    from telemetry.schema import encode

    return (payload, True) if isinstance(payload, bytes) else (encode(payload)[0], False)


def message_of(payload) -> bytes:
    """A zenoh message carrying one sample (not sealed), as the publisher frames it."""
    from telemetry import wire

    data, is_binary = wire_form(payload)
    return wire.binary_message([data]) if is_binary else wire.json_message([data])


def write_mcap(path, samples, scene_rate_hz: float = 20.0, finish: bool = True):
    """Write (key, payload) samples as the recorder would (without zenoh); returns the translator."""
    from ground_station.contract import Translator
    from ground_station.mcap_io import McapLogWriter

    tr = Translator(Keys(), scene_rate_hz=scene_rate_hz)
    w = McapLogWriter(path)
    w.open()
    for k, p in stamped(samples):
        for out in tr.translate(k, *wire_form(p)):
            w.write(out)
    w.write(tr.stats_out(0.0, 0))
    if finish:
        w.close()
    else:
        w.flush()
    return tr
