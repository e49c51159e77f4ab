"""Telemetry speed figures (never timed tests): publish cost on the caller, recorder throughput.

    python benchmarks/bench_telemetry.py [--ams 10] [--rate 1000] [--truth-every 1] [--seconds 5] [--skip-caller]

1. Caller-side cost of one controller sample, paced at 1 kHz like a control loop, with
   no subscriber, with a live recorder, and with a frozen (SIGSTOP) recorder, for
   (a) TelemetryPublisher.publish (stamp + bounded queue; a thread encodes and puts) and
   (b) encoding and putting on the caller's thread with zenoh congestion control DROP.
2. Recorder throughput: `ground-station record` as a subprocess, N companion processes
   publishing controller samples at --rate and one simulator process publishing truth and
   contact of every AM plus the object at --rate, for --seconds, all paced in real time.
   Payloads are real: one simulated second of the two-AM scenario, cycled.
Run from the repository root (it reuses the tests' short-run helper for real payloads).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from telemetry import schema  # noqa: E402
from telemetry.publisher import TelemetryPublisher  # noqa: E402
from telemetry.schema import Keys  # noqa: E402
from telemetry.session import ZenohOptions, build_config  # noqa: E402
from tests.telemetry.zenoh_testing import free_endpoint  # noqa: E402

KEYS = Keys()


def capture_real_run(seconds: float) -> dict:
    """Payload templates from a real in-process run of the two-AM scenario."""
    from amcore.config import load_scenario
    from amcore.model import build_model
    from tests.ground_station import simrun

    spec = simrun.short_spec(load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml"))
    model = build_model(spec.vehicle)
    out: dict = {"controller": {}, "truth": {}, "contact": {}, "object": []}
    for k, p in _collect(simrun, spec, model, seconds):
        m = KEYS.parse(k)
        if m.channel is schema.Channel.CONTROLLER:
            out["controller"].setdefault(m.sysid, []).append(p)
        elif m.channel is schema.Channel.AM_TRUTH:
            out["truth"].setdefault(m.sysid, []).append(p)
        elif m.channel is schema.Channel.CONTACT:
            out["contact"].setdefault(m.sysid, []).append(p)
        elif m.channel is schema.Channel.OBJECT:
            out["object"].append(p)
    out["run_start"] = schema.run_start_event(0.0, spec)
    return out


def _collect(simrun, spec, model, seconds):
    got = []
    simrun.run(spec, model, seconds, lambda k, p: got.append((k, p)), KEYS)
    return got


def stats_us(ns: np.ndarray) -> str:
    us = ns / 1e3
    return f"median {np.median(us):6.1f} us  p99 {np.percentile(us, 99):7.1f} us  max {us.max():8.1f} us"


# ----------------------------------------------------------------------------- part 1
def paced_costs(publish, payloads: list, n: int) -> np.ndarray:
    ts = np.empty(n)
    next_t = time.perf_counter()
    for i in range(n):
        p = dict(payloads[i % len(payloads)])
        t0 = time.perf_counter_ns()
        publish(p)
        ts[i] = time.perf_counter_ns() - t0
        next_t += 1e-3
        delay = next_t - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    return ts


def caller_costs(templates: dict, n: int) -> None:
    import zenoh

    payloads = templates["controller"][4]
    size = len(schema.encode(payloads[0])[0])
    print(f"\n1. caller cost per controller sample ({size} B JSON), {n} calls paced at 1 kHz")
    cases = [("no subscriber", None, False), ("live recorder", "live", False), ("frozen recorder (SIGSTOP)", "live", True)]
    for name, rec_kind, freeze in cases:
        ep = free_endpoint()
        rec = None
        with tempfile.TemporaryDirectory() as tmp:
            if rec_kind:
                rec = subprocess.Popen([sys.executable, "-m", "ground_station", "record", "--out", f"{tmp}/b.mcap",
                                        "--zenoh-listen", ep], stderr=subprocess.PIPE, text=True)
                rec.stderr.readline()
            try:
                pub = TelemetryPublisher(ZenohOptions(connect=(ep,)), queue_size=4096)
                pub.open()
                if rec:
                    pub.wait_for_subscriber(KEYS.controller(4), 10.0)
                    if freeze:
                        os.kill(rec.pid, signal.SIGSTOP)
                ts = paced_costs(lambda p: pub.publish(KEYS.controller(4), p), payloads, n)
                st = pub.close(timeout_s=1.0)
                print(f"  queue  {name:28s} {stats_us(ts)}  sent {st.sent} dropped {st.dropped}")
                s = zenoh.open(build_config(ZenohOptions(connect=(ep,))))
                zp = s.declare_publisher(KEYS.controller(4), congestion_control=zenoh.CongestionControl.DROP)
                time.sleep(0.5)
                ts = paced_costs(lambda p: zp.put(schema.encode(p)[0]), payloads, n)
                print(f"  direct {name:28s} {stats_us(ts)}")
                zp.undeclare()
                s.close()
            finally:
                if rec:
                    os.kill(rec.pid, signal.SIGCONT)
                    rec.send_signal(signal.SIGINT)
                    try:
                        rec.wait(10)
                    except subprocess.TimeoutExpired:
                        rec.kill()
                        rec.wait()
    # what the builder adds on the caller, from Diagnostics (once per step, any mode)
    from amcore.config import load_scenario
    from amcore.control import ControllerMemory, ControllerParams, step
    from amcore.mission import am_mission
    from amcore.model import build_model, create_data
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    model = build_model(spec.vehicle)
    m = am_mission(spec, spec.ams[0], model)
    res = step(model, create_data(model), ControllerParams.from_vehicle(spec.vehicle, m.frame), m.initial_state(),
               m.reference(0.1), np.zeros(6), ControllerMemory(), 0.1)
    ts = np.empty(5000)
    for i in range(len(ts)):
        t0 = time.perf_counter_ns()
        schema.controller_sample(0.1, "approach", res.diagnostics, res.command, sysid=4)
        ts[i] = time.perf_counter_ns() - t0
    print(f"  schema.controller_sample (builder, on the caller in both modes): {stats_us(ts)}")


# ----------------------------------------------------------------------------- part 2
def child(a) -> None:
    """One publishing process of the throughput test."""
    data = json.loads(Path(a.data).read_text())
    name = "simulator" if a.child == "sim" else f"am{a.sysid}"
    pub = TelemetryPublisher(ZenohOptions(connect=(a.endpoint,)), name=name, queue_size=20000)
    pub.open()
    pub.wait_for_subscriber(KEYS.sim_event, 20.0)
    steps = int(a.seconds * a.rate)
    src = lambda table, s: table[str(4 + s % 2)]  # noqa: E731  real AM 4/5 samples for any sysid
    if a.child == "sim":
        pub.publish(KEYS.sim_event, dict(data["run_start"]))
    while time.time() < a.start_at:
        time.sleep(1e-3)
    t0, late = time.perf_counter(), 0
    for k in range(steps):
        t = k / a.rate
        wait = t0 + t - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        else:
            late += 1
        j = k % len(data["object"])
        if a.child == "companion":
            p = dict(src(data["controller"], a.sysid)[j], t=t, sysid=a.sysid)
            pub.publish(KEYS.controller(a.sysid), p)
        elif k % a.truth_every == 0:
            for s in range(a.ams):
                pub.publish(KEYS.am_truth(s), dict(src(data["truth"], s)[j], t=t, sysid=s))
                pub.publish(KEYS.contact(s), dict(src(data["contact"], s)[j], t=t, sysid=s))
            pub.publish(KEYS.object, dict(data["object"][j], t=t))
    wall = time.perf_counter() - t0
    st = pub.close(timeout_s=10.0)
    print(json.dumps({"who": a.child, "sysid": a.sysid, "published": st.published, "sent": st.sent,
                      "dropped": st.dropped, "wall_s": wall, "late_steps": late}), flush=True)


def throughput(templates: dict, n_ams: int, rate: float, seconds: float, truth_every: int) -> None:
    print(f"\n2. recorder throughput: {n_ams} companions x {rate:.0f} Hz controller + simulator "
          f"({n_ams} truth + {n_ams} contact + object) x {rate / truth_every:.0f} Hz, {seconds:.0f} s")
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "templates.json"
        data.write_text(json.dumps({k: ({str(s): v for s, v in t.items()} if isinstance(t, dict) and k != "run_start"
                                        else t) for k, t in templates.items()}))
        ep, out = free_endpoint(), Path(tmp) / "run.mcap"
        rec = subprocess.Popen([sys.executable, "-m", "ground_station", "record", "--out", str(out), "--zenoh-listen",
                                ep, "--summary-json", "--linger", "2"], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        rec.stderr.readline()
        start_at = time.time() + 4.0 + 0.3 * n_ams  # every child imported and connected by then
        common = ["--data", str(data), "--endpoint", ep, "--rate", str(rate), "--seconds", str(seconds),
                  "--ams", str(n_ams), "--start-at", str(start_at), "--truth-every", str(truth_every)]
        kids = [subprocess.Popen([sys.executable, __file__, "--child", "companion", "--sysid", str(s), *common],
                                 stdout=subprocess.PIPE, text=True) for s in range(n_ams)]
        kids.append(subprocess.Popen([sys.executable, __file__, "--child", "sim", *common], stdout=subprocess.PIPE,
                                     text=True))
        reports = [json.loads(k.communicate(timeout=120 + 5 * seconds)[0].strip().splitlines()[-1]) for k in kids]
        last, quiet, deadline = -1, 0, time.monotonic() + 60.0
        while quiet < 3 and time.monotonic() < deadline:  # the recorder flushes every second: wait until idle
            time.sleep(1.0)
            size = out.stat().st_size
            quiet, last = (quiet + 1, last) if size == last else (0, size)
        rec.send_signal(signal.SIGINT)
        summary = json.loads(rec.communicate(timeout=60)[0])
        size = out.stat().st_size
    sent = sum(r["sent"] for r in reports)
    pub_dropped = sum(r["dropped"] for r in reports)
    # every sample dropped at a source used up a seq number: the recorder must see it as a gap
    late = max(r["late_steps"] for r in reports)
    walls = [r["wall_s"] for r in reports]
    comp_drop = sum(r["dropped"] for r in reports if r["who"] == "companion")
    print(f"  publishers: {sum(r['published'] for r in reports)} queued, {sent} sent, {pub_dropped} dropped at the "
          f"source ({comp_drop} by the companions, {pub_dropped - comp_drop} by the simulator); paced loops took "
          f"{min(walls):.2f}..{max(walls):.2f} s wall for {seconds:.0f} s (worst: {late} steps late)")
    print(f"  recorder:   {summary['received']} received ({summary['received'] / seconds:.0f} samples/s, the "
          f"publishers' own 1 Hz stats included), {summary['written']} MCAP messages; missing {summary['missing']} "
          f"(seq gaps + tails from the publishers' final stats), inbox overflow {summary['inbox_overflow']}: "
          f"{'exactly' if summary['missing'] == pub_dropped else 'NOT'} the sources' drops, "
          f"{summary['missing'] - pub_dropped} lost in transit")
    print(f"  MCAP: {size / 1e6:.1f} MB for {summary['sim_time_s']:.2f} s simulated = "
          f"{size / 1e6 / max(summary['sim_time_s'], 1e-9):.2f} MB per simulated second (zstd, 1 s chunks)")


def recorder_capacity(templates: dict, n_ams: int, seconds: float) -> None:
    """The recorder alone: one process puts pre-encoded real payloads (no JSON cost on the
    sending side) as fast as zenoh's BLOCK congestion control lets it, i.e. as fast as the
    recorder takes them."""
    import zenoh

    enc = lambda p, **kw: schema.encode(dict(p, **kw))[0]  # noqa: E731
    per_step = []
    for s in range(n_ams):
        per_step.append((KEYS.controller(s), [enc(p, sysid=s) for p in templates["controller"][4 + s % 2][:200]]))
        per_step.append((KEYS.am_truth(s), [enc(p, sysid=s) for p in templates["truth"][4 + s % 2][:200]]))
        per_step.append((KEYS.contact(s), [enc(p, sysid=s) for p in templates["contact"][4 + s % 2][:200]]))
    print(f"\n3. recorder capacity: controller + truth + contact of {n_ams} AMs, pre-encoded, for {seconds:.0f} s")
    with tempfile.TemporaryDirectory() as tmp:
        ep = free_endpoint()
        rec = subprocess.Popen([sys.executable, "-m", "ground_station", "record", "--out", f"{tmp}/c.mcap",
                                "--zenoh-listen", ep, "--summary-json"], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        rec.stderr.readline()
        s = zenoh.open(build_config(ZenohOptions(connect=(ep,))))
        pubs = {k: s.declare_publisher(k, congestion_control=zenoh.CongestionControl.BLOCK) for k, _ in per_step}
        time.sleep(1.0)
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            for k, variants in per_step:
                pubs[k].put(variants[n % 200])
            n += 1
        wall = time.perf_counter() - t0
        s.close()
        time.sleep(2.0)
        rec.send_signal(signal.SIGINT)
        summary = json.loads(rec.communicate(timeout=60)[0])
    total = n * len(per_step)
    print(f"  put {total} samples in {wall:.1f} s = {total / wall:.0f} samples/s; recorder received "
          f"{summary['received']}, seq gaps {summary['missing']}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ams", type=int, default=10)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--truth-every", type=int, default=1, help="simulator publishes ground truth every N steps")
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--skip-caller", action="store_true")
    ap.add_argument("--skip-throughput", action="store_true")
    ap.add_argument("--child", choices=("companion", "sim"))
    ap.add_argument("--sysid", type=int, default=0)
    ap.add_argument("--data")
    ap.add_argument("--endpoint")
    ap.add_argument("--start-at", type=float, default=0.0)
    a = ap.parse_args()
    if a.child:
        child(a)
        return
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    t0 = time.perf_counter()
    templates = capture_real_run(1.0)
    print(f"captured 1 s of the two-AM scenario for payload templates in {time.perf_counter() - t0:.1f} s")
    if not a.skip_caller:
        caller_costs(templates, a.calls)
    if not a.skip_throughput:
        throughput(templates, a.ams, a.rate, a.seconds, a.truth_every)
        recorder_capacity(templates, a.ams, a.seconds)


if __name__ == "__main__":
    main()
