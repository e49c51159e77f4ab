"""A short simulated run captured once per session: the telemetry it produced and its ground truth."""
from __future__ import annotations

from dataclasses import dataclass

import pytest

from telemetry.schema import Keys

from . import simrun


@dataclass
class Capture:
    spec: object
    samples: list  # (key, payload) in publication order, seq not yet stamped
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
        q = dict(p)
        q["seq"] = counters.get(k, 0)
        counters[k] = q["seq"] + 1
        out.append((k, q))
    return out


def write_mcap(path, samples, scene_rate_hz: float = 20.0, finish: bool = True):
    """Write (key, payload) samples as the recorder would (without zenoh); returns the translator."""
    from ground_station.contract import Translator
    from ground_station.mcap_io import McapLogWriter
    from telemetry.schema import encode

    tr = Translator(Keys(), scene_rate_hz=scene_rate_hz)
    w = McapLogWriter(path)
    w.open()
    for k, p in stamped(samples):
        for out in tr.translate(k, encode(p)[0]):
            w.write(out)
    w.write(tr.stats_out(0.0, 0))
    if finish:
        w.close()
    else:
        w.flush()
    return tr
