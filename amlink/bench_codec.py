"""Benchmark: encode + decode of one SensorFrame batch and one TorqueSetpoint batch.

Run ``python -m amlink.bench_codec``; prints median microseconds per operation.
Not a test: timings depend on the machine.  The loop budget is 1 ms per step per
vehicle (1 kHz), shared with physics and control.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from amlink import codec
from amlink.types import AttitudeTarget, SensorFrame, TorqueSetpoint


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


def _median_us(fn, repeats: int) -> float:
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        samples.append(time.perf_counter_ns() - t0)
    return statistics.median(samples) / 1e3


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5000)
    args = ap.parse_args(argv)
    frame, sp, att = _example(np.random.default_rng(0))
    sim_enc, comp_enc = codec.Encoder(1, 1), codec.Encoder(2, 191)
    comp_dec, sim_dec = codec.Decoder(), codec.Decoder()
    frames_asm, sp_asm = codec.SensorFrameAssembler(), codec.SetpointAssembler()

    def enc_frame():
        return sim_enc.pack(codec.sensor_frame_messages(frame))

    frame_bytes = enc_frame()

    def dec_frame():
        out = None
        for m in comp_dec.feed(frame_bytes):
            out = frames_asm.push(m) or out
        assert out is not None
        return out

    def enc_sp():
        return comp_enc.pack(codec.setpoint_messages(sp))

    def enc_sp_att():
        return comp_enc.pack(codec.setpoint_messages(sp, att))

    sp_bytes, sp_att_bytes = enc_sp(), enc_sp_att()

    def dec(data):
        def run():
            out = None
            for m in sim_dec.feed(data):
                out = sp_asm.push(m) or out
            assert out is not None
            return out

        return run

    rows = [
        (f"SensorFrame encode ({len(frame_bytes)} B datagram)", enc_frame),
        ("SensorFrame decode", dec_frame),
        (f"TorqueSetpoint encode ({len(sp_bytes)} B)", enc_sp),
        ("TorqueSetpoint decode", dec(sp_bytes)),
        (f"TorqueSetpoint+AttitudeTarget encode ({len(sp_att_bytes)} B)", enc_sp_att),
        ("TorqueSetpoint+AttitudeTarget decode", dec(sp_att_bytes)),
    ]
    key = bytes(range(32))
    signed_enc = codec.Encoder(2, 191, signing_key=key, link_id=2)
    signed_dec = codec.Decoder({2: key})

    def enc_sp_signed():
        return signed_enc.pack(codec.setpoint_messages(sp))

    n_signed = args.repeats + 200
    signed_bytes = iter([enc_sp_signed() for _ in range(n_signed)])  # distinct: a repeat is a replay

    def dec_sp_signed():
        out = None
        for m in signed_dec.feed(next(signed_bytes)):
            out = sp_asm.push(m) or out
        assert out is not None
        return out

    rows += [
        (f"TorqueSetpoint encode, signed ({len(enc_sp_signed())} B)", enc_sp_signed),
        ("TorqueSetpoint decode, signed (verify + replay check)", dec_sp_signed),
    ]
    results = {}
    for name, fn in rows:
        for _ in range(200):  # warm-up
            fn()
        results[name] = _median_us(fn, args.repeats)
        print(f"{name:55s} median {results[name]:8.1f} us")
    signed_cost = results[rows[-2][0]] + results[rows[-1][0]] - results[rows[2][0]] - results[rows[3][0]]
    print(f"{'signing cost per setpoint packet (enc+dec, signed - unsigned)':55s} median {signed_cost:8.1f} us")
    total = sum(results[n] for n, _ in rows[:4])
    print(f"{'round trip (frame enc+dec + setpoint enc+dec)':55s} median {total:8.1f} us (sum of medians)")


if __name__ == "__main__":
    main()
