"""Benchmark: encode + decode of the lockstep batches, pymavlink's message objects vs the codec, in one run.

Run ``python -m benchmarks.bench_codec``; prints median microseconds per operation
for the batches built and read as pymavlink message objects (the readable twin,
``tests/amlink/codec_reference.py``: ``Encoder.pack`` / ``Decoder.feed``) next to
:mod:`amlink.codec`'s precompiled structs (``Encoder.pack_payloads`` /
``Decoder.feed_records``) and their ratio.  The two
are timed in alternating rounds so machine load hits both alike.  Not a test:
timings depend on the machine.  The loop budget is 1 ms per step per vehicle
(1 kHz), shared with physics and control.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from amlink import codec
from amlink.types import AttitudeTarget, SensorFrame, TorqueSetpoint
from amlink.wire import now_timestamp
from tests.amlink import codec_reference as ref

KEY = bytes(range(32))
ROUNDS = 10  # old and new alternate this many times per row


def _example(rng: np.random.Generator, n: int = 3) -> tuple[SensorFrame, TorqueSetpoint, AttitudeTarget]:
    quat = rng.normal(size=4)
    frame = SensorFrame(
        step=12345, time_s=12.345, p_WB=rng.normal(size=3), quat_WB_wxyz=quat / np.linalg.norm(quat),
        v_B=rng.normal(size=3), w_B=rng.normal(size=3), q=rng.normal(size=n), qdot=rng.normal(size=n),
        wrench_E=rng.normal(size=6),
    )  # fmt: skip
    sp = TorqueSetpoint(step=12345, thrust_n=20.0, tau_B_nm=rng.normal(size=3), tau_q_nm=rng.normal(size=n))
    att = AttitudeTarget(12345, quat_wxyz=frame.quat_WB_wxyz, rates_rad_s=rng.normal(size=3), thrust_normalized=0.5)
    return frame, sp, att


def _old_decode(dec: codec.Decoder, asm, datagrams):
    def run():
        out = None
        for m in dec.feed(next(datagrams)):
            out = asm.push(m) or out
        assert out is not None
        return out

    return run


def _new_decode(dec: codec.Decoder, asm, datagrams):
    def run():
        out = None
        for mid, _sysid, _compid, body in dec.feed_records(next(datagrams)):
            out = asm.push(mid, body) or out
        assert out is not None
        return out

    return run


def _forever(data: bytes):
    while True:
        yield data


class _Batch:
    """One kind of batch: how each path encodes it, and decoders for its datagrams."""

    def __init__(self, messages, payloads, sysid: int, compid: int, assemblers, signed: bool, count: int):
        key = KEY if signed else None
        self.enc_old = codec.Encoder(sysid, compid, signing_key=key, link_id=2)
        self.enc_new = codec.Encoder(sysid, compid, signing_key=key, link_id=2)
        self.encode_old = lambda: self.enc_old.pack(messages())
        self.encode_new = lambda: self.enc_new.pack_payloads(payloads())
        if signed:  # same signing clock on both, so that the bytes can be compared
            ahead = now_timestamp() + 10**7  # 100 s ahead: pack() keeps it
            self.enc_old.mavlink.signing.timestamp = self.enc_new.mavlink.signing.timestamp = ahead
        assert self.encode_old() == self.encode_new(), "the codec is not bit-identical to its twin on message objects"
        keys = {sysid: KEY} if signed else None
        # signed: every datagram once (a repeat is a replay); each decoder reads the list once
        data = [self.encode_new() for _ in range(count)] if signed else None
        self.size = len(self.encode_new())
        old_asm, new_asm = assemblers
        self.decode_old = _old_decode(codec.Decoder(keys), old_asm,
                                      iter(data) if signed else _forever(self.encode_old()))  # fmt: skip
        self.decode_new = _new_decode(codec.Decoder(keys, readers=codec.READERS), new_asm,
                                      iter(data) if signed else _forever(self.encode_new()))  # fmt: skip


def _time_pair(old, new, repeats: int) -> tuple[float, float]:
    """Median [us] of ``old()`` and ``new()``, timed in alternating rounds after a warm-up."""
    per_round = max(1, repeats // ROUNDS)
    samples: tuple[list[int], list[int]] = ([], [])
    for fn in (old, new):
        for _ in range(min(200, per_round)):
            fn()
    for _ in range(ROUNDS):
        for fn, out in ((old, samples[0]), (new, samples[1])):
            for _ in range(per_round):
                t0 = time.perf_counter_ns()
                fn()
                out.append(time.perf_counter_ns() - t0)
    return statistics.median(samples[0]) / 1e3, statistics.median(samples[1]) / 1e3


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5000, help="timed calls per path and row")
    args = ap.parse_args(argv)
    frame, sp, att = _example(np.random.default_rng(0))
    count = args.repeats + 2 * 200  # enough distinct signed datagrams for warm-up and timing

    def sensor(signed):
        old, new = lambda: ref.sensor_frame_messages(frame), lambda: codec.sensor_frame_payloads(frame)
        assemblers = (ref.SensorFrameAssembler(), codec.SensorFrameAssembler())
        return _Batch(old, new, 1, 1, assemblers, signed, count)

    def setpoint(signed, attitude):
        old, new = lambda: ref.setpoint_messages(sp, attitude), lambda: codec.setpoint_payloads(sp, attitude)
        assemblers = (ref.SetpointAssembler(), codec.SetpointAssembler())
        return _Batch(old, new, 2, 191, assemblers, signed, count)

    batches = [
        ("SensorFrame", sensor(False)),
        ("SensorFrame, signed", sensor(True)),
        ("TorqueSetpoint", setpoint(False, None)),
        ("TorqueSetpoint, signed", setpoint(True, None)),
        ("TorqueSetpoint+AttitudeTarget", setpoint(False, att)),
        ("TorqueSetpoint+AttitudeTarget, signed", setpoint(True, att)),
    ]
    print(f"{'median us per batch (one datagram)':52s} {'objects':>8s} {'structs':>8s} {'speedup':>8s}")
    results = {}
    for name, b in batches:
        for what, old, new in (("encode", b.encode_old, b.encode_new), ("decode", b.decode_old, b.decode_new)):
            label = f"{name} {what}" + (f" ({b.size} B)" if what == "encode" else "")
            t_old, t_new = _time_pair(old, new, args.repeats)
            results[(name, what)] = (t_old, t_new)
            print(f"{label:52s} {t_old:8.1f} {t_new:8.1f} {t_old / t_new:7.1f}x")
    for title, suffix in (("per step and vehicle, unsigned", ""), ("per step and vehicle, signed", ", signed")):
        keys = [(f"SensorFrame{suffix}", w) for w in ("encode", "decode")]
        keys += [(f"TorqueSetpoint+AttitudeTarget{suffix}", w) for w in ("encode", "decode")]
        t_old = sum(results[k][0] for k in keys)
        t_new = sum(results[k][1] for k in keys)
        print(f"{title + ' (sum of the 4 medians)':52s} {t_old:8.1f} {t_new:8.1f} {t_old / t_new:7.1f}x")


if __name__ == "__main__":
    main()
