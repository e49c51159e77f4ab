"""Telemetry speed figures (never timed tests): CPU per step, publish cost on the caller, recorder throughput.

    python -m benchmarks.bench_telemetry [--ams 10] [--rate 1000] [--truth-every 1] [--seconds 5]
        [--encoding binary|json] [--skip-cpu] [--skip-caller] [--skip-throughput] [--skip-recorder-work]
        [--cpu-steps 3000] [--cpu-rounds 3] [--recorder-rounds 7]
        [--before REV] [--cpu-setups "binary,binary (before)"]

0. Telemetry CPU per step of a companion (its controller sample) and of the simulator (truth
   and contact of 2 AMs and the object), JSON and binary samples in the same run, alternating,
   in place: a loop paced at 1 kHz does the process's own work each step (the companion's
   controller step, whose StepResult the sample is built from; the simulator's physics step
   and ground truth) and then publishes through telemetry.wiring as the mains do, sealed with
   a per-run key, to a live `ground-station record`. Counted: the telemetry call's time on
   the loop's thread, plus every other thread's CPU time (the sender's, zenoh's) until the
   queue is drained. Medians over rounds. (The same calls back to back, with hot caches, cost
   a third as much: printed too, they are what a microbenchmark says.) With --before REV,
   one more setup, "binary (before)": the telemetry package as it was at git revision REV
   (its publisher, capture and wiring, loaded from `git archive` under another name), in the
   same run, alternating with the others.
1. Caller-side cost of one controller sample, paced at 1 kHz like a control loop, with
   no subscriber, with a live recorder, and with a frozen (SIGSTOP) recorder, for
   (a) TelemetryPublisher.publish (stamp + bounded queue; a thread encodes and puts) and
   (b) encoding and putting on the caller's thread with zenoh congestion control DROP.
2. Recorder throughput: `ground-station record` as a subprocess, N companion processes
   publishing controller samples at --rate and one simulator process publishing truth and
   contact of every AM plus the object at --rate, for --seconds, all paced in real time.
   Payloads are real: one simulated second of the two-AM scenario, cycled, in --encoding
   (binary: the JSON templates converted once, t and sysid patched per step).
3. Recorder capacity: pre-encoded samples (--encoding) put as fast as the recorder takes them.
4. Recorder work per simulated step, in process (no zenoh, no pacing): one simulated second of
   the two-AM scenario's samples in publication order, JSON and binary, translated
   (ground_station.contract) and written to MCAP (ground_station.mcap_io) as the recorder's
   drain loop does; CPU time of the process, medians over --recorder-rounds rounds.
Run from the repository root (it reuses the tests' short-run helper for real payloads: `tests.ground_station.simrun`).
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import struct
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

import numpy as np

from telemetry import binary, capture, schema, wire
from telemetry.auth import publisher_key
from telemetry.publisher import TelemetryPublisher
from telemetry.schema import Channel, Keys
from telemetry.session import ZenohOptions, build_config
from telemetry.wiring import CompanionTelemetry, SimulatorTelemetry
from tests.telemetry.zenoh_testing import free_endpoint

ROOT = Path(__file__).resolve().parents[1]

KEYS = Keys()
MASTER = bytes(range(32))  # the run key of the CPU benchmark's recorders (every message sealed, as am-run does)
FORMS = ("json", "binary")
# part 0's publishers: JSON and binary as they are, and JSON as it was before the binary channels
# (the sender woke every 20 ms; zenoh's shared-memory transport was on)
SETUPS = {"json (before)": "json", "json": "json", "binary": "binary"}
IMPLS: dict = {}  # setup -> (TelemetryPublisher, CompanionTelemetry, SimulatorTelemetry) if not today's (--before)
BEFORE_ZENOH = """{scouting: {multicast: {enabled: false}, gossip: {enabled: false}, delay: 0},
                   transport: {shared_memory: {enabled: true}}}"""


def capture_real_run(seconds: float) -> dict:
    """Payload templates (JSON dicts) from a real in-process run of the two-AM scenario, and
    what they were built from: StepResults per AM and the GroundTruths."""
    from amcore.config import load_scenario
    from amcore.model import build_model
    from tests.ground_station import simrun

    spec = simrun.short_spec(load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml"))
    model = build_model(spec.vehicle)
    out: dict = {"controller": {}, "truth": {}, "contact": {}, "object": [], "steps": {}, "truths": [], "spec": spec,
                 "model": model}
    got = []
    simrun.run(spec, model, seconds, lambda k, p: got.append((k, p)), KEYS, encoding="json",
               on_truth=out["truths"].append,
               on_step=lambda s, t, phase, res: out["steps"].setdefault(s, []).append((phase, res)))
    for k, p in got:
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


def stats_us(ns: np.ndarray) -> str:
    us = ns / 1e3
    return f"median {np.median(us):6.1f} us  p99 {np.percentile(us, 99):7.1f} us  max {us.max():8.1f} us"


# ----------------------------------------------------------------------------- part 0
class _KeyedRecorder:
    """`ground-station record` as a subprocess on a fresh endpoint, keeping only what the
    run's publishers sealed (MASTER), as in an am-run run."""

    def __init__(self, tmp: Path, name: str):
        self.endpoint = free_endpoint()
        keyfile = tmp / f"{name}.key"
        keyfile.write_text(MASTER.hex())
        self.proc = subprocess.Popen([sys.executable, "-m", "ground_station", "record", "--insecure",
                                      "--out", str(tmp / f"{name}.mcap"), "--zenoh-listen", self.endpoint,
                                      "--telemetry-key-file", str(keyfile), "--summary-json"],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.proc.stderr.readline()

    def stop(self) -> dict:
        time.sleep(1.0)  # the last messages in
        self.proc.send_signal(signal.SIGINT)
        return json.loads(self.proc.communicate(timeout=60)[0])


def load_before(rev: str) -> None:
    """Add the setup "binary (before)": the telemetry package at git revision `rev`, imported
    as the package `telemetry_before` (its imports of itself are relative), from its own folder."""
    import importlib
    import importlib.util
    import io
    import tarfile

    out = Path(tempfile.mkdtemp(prefix="telemetry-before-"))
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "telemetry"], check=True,
                             capture_output=True).stdout
    tarfile.open(fileobj=io.BytesIO(archive)).extractall(out)
    package = (out / "telemetry").rename(out / "telemetry_before")
    spec = importlib.util.spec_from_file_location("telemetry_before", package / "__init__.py",
                                                  submodule_search_locations=[str(package)])
    sys.modules["telemetry_before"] = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sys.modules["telemetry_before"])
    pub, wiring = (importlib.import_module(f"telemetry_before.{m}") for m in ("publisher", "wiring"))
    SETUPS["binary (before)"] = "binary"
    IMPLS["binary (before)"] = (pub.TelemetryPublisher, wiring.CompanionTelemetry, wiring.SimulatorTelemetry)


def _drain(pub: TelemetryPublisher, timeout_s: float = 20.0) -> None:
    """Until the sender thread has handed every queued sample to zenoh."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        st = pub.stats()
        if st.queued == 0 and st.sent + st.encode_errors + st.send_errors >= st.published:
            return
        time.sleep(0.002)


class _Loop:
    """One process's own work per step, as in its main: the companion's controller step (the
    sample is built from its StepResult), or the simulator's physics step and ground truth."""

    def __init__(self, kind: str, templates: dict):
        from amcore.control import ControllerMemory, ControllerParams, step
        from amcore.mission import am_mission
        from amcore.model import create_data
        from simulator.world import World

        self.kind, spec = kind, templates["spec"]
        if kind == "companion":
            model = templates["model"]
            m = am_mission(spec, spec.ams[0], model)
            params, data = ControllerParams.from_vehicle(spec.vehicle, m.frame), create_data(model)
            x0 = m.initial_state()
            self.work = lambda t: (m.phase(t), step(model, data, params, x0, m.reference(t), np.zeros(6),
                                                    ControllerMemory(), t))
        else:
            missions = {a.sysid: am_mission(spec, a, templates["model"]) for a in spec.ams}
            self.world = World(spec, {s: mi.initial_state() for s, mi in missions.items()})
            self.world.connect()

            def work(t):
                self.world.step()
                return self.world.ground_truth()
            self.work = work

    def close(self) -> None:
        if self.kind == "simulator":
            self.world.close()


def _cpu_round(loop: _Loop, setup: str, n: int, templates: dict, recorder, sysid: int, tmp: Path
               ) -> tuple[float, float, int]:
    """One paced 1 kHz loop of n steps publishing as `setup` (a key of SETUPS): (caller's
    share, background share) in us per step, and the publisher's drops. Caller: wall time of
    each telemetry call on the loop's thread (perf_counter; the slowest 1 % dropped as
    preempted). Background: the process's CPU time (every thread) minus the loop thread's
    own, from before the first sample until the queue is drained: the sender thread and zenoh's."""
    name = "simulator" if loop.kind == "simulator" else f"am{sysid}"
    form = SETUPS[setup]
    config = None
    if setup == "json (before)":
        config = tmp / "before.json5"
        config.write_text(BEFORE_ZENOH)
    publisher, companion, simulator = IMPLS.get(setup, (TelemetryPublisher, CompanionTelemetry, SimulatorTelemetry))
    pub = publisher(ZenohOptions(connect=(recorder.endpoint,), auth_key=publisher_key(MASTER, name),
                                 config_file=config),
                    name=name, queue_size=20000, poll_period_s=0.02 if setup == "json (before)" else 0.1)
    pub.open()
    if not pub.wait_for_subscriber(KEYS.sim_event if loop.kind == "simulator" else KEYS.controller(sysid), 20.0):
        raise RuntimeError("recorder not reachable")
    if loop.kind == "simulator":
        tele = simulator(pub, templates["spec"], encoding=form)
        call = lambda t, out: tele.truth(out)  # noqa: E731
    else:
        tele = companion(pub, sysid, encoding=form)
        call = lambda t, out: tele.step(t, out[0], out[1])  # noqa: E731
    time.sleep(0.3)
    ts = np.empty(n)
    c0, m0 = time.process_time_ns(), time.thread_time_ns()
    t0 = time.perf_counter()
    for i in range(n):
        t = i * 1e-3
        out = loop.work(t)
        a = time.perf_counter_ns()
        call(t, out)
        ts[i] = time.perf_counter_ns() - a
        wait = t0 + (i + 1) * 1e-3 - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
    _drain(pub)
    background = (time.process_time_ns() - c0) - (time.thread_time_ns() - m0)
    dropped = pub.close(timeout_s=10.0).dropped
    ts.sort()
    return float(ts[:int(0.99 * n)].mean()) / 1e3, background / n / 1e3, dropped


def cpu_per_step(templates: dict, n: int, rounds: int) -> None:
    """Part 0: telemetry CPU per step, JSON and binary samples (see the module docstring)."""
    print(f"\n0. telemetry CPU per step at 1 kHz (build, encode, seal, batch, zenoh put; sealed, to a live keyed "
          f"recorder): {rounds} rounds x {n} steps per form, alternating; medians over rounds")
    got: dict = {}
    drops = {f: 0 for f in SETUPS}
    with tempfile.TemporaryDirectory() as tmp:
        recs = {f: _KeyedRecorder(Path(tmp), f"rec{i}") for i, f in enumerate(SETUPS)}
        try:
            sysid = 10
            for kind in ("companion", "simulator"):
                loop = _Loop(kind, templates)
                try:
                    for r in range(rounds):
                        for setup in list(SETUPS) if r % 2 == 0 else list(SETUPS)[::-1]:
                            sysid += 1
                            caller, bg, d = _cpu_round(loop, setup, n, templates, recs[setup], sysid, Path(tmp))
                            got.setdefault((kind, setup), []).append((caller, bg))
                            drops[setup] += d
                finally:
                    loop.close()
        finally:
            summaries = {f: r.stop() for f, r in recs.items()}
    for kind, what in (("companion", "one AM's controller sample per step, after its controller step"),
                       ("simulator", "truth + contact of 2 AMs + the object per step, after its physics step")):
        print(f"  {kind} ({what}):")
        total = {}
        for f in SETUPS:
            rows = got[kind, f]
            caller, bg = (float(np.median([r[i] for r in rows])) for i in (0, 1))
            total[f] = float(np.median([sum(r) for r in rows]))
            print(f"    {f:13s} caller {caller:6.1f} + background {bg:6.1f} = {total[f]:6.1f} us/step   "
                  f"(rounds: {', '.join(f'{sum(r):.1f}' for r in rows)})")
        for other in ("json", "json (before)", "binary (before)"):
            if other in total:
                print(f"    binary/{other}: {total['binary'] / total[other]:.2f} "
                      f"({total[other] / total['binary']:.1f}x less CPU)")
        if kind == "companion":
            print(f"    target <= 10 us: {'met' if total['binary'] <= 10 else 'NOT met'}; "
                  f"goal <= 5 us: {'met' if total['binary'] <= 5 else 'not met'}")
    for f in SETUPS:
        s = summaries[f]
        print(f"  loss, {f}: {drops[f]} dropped by the publishers; recorder: {s['received']} samples received, "
              f"missing {s['missing']}, rejected {s['rejected']}, malformed {s['malformed']}")
    # the same calls back to back (hot caches): what a microbenchmark of them says
    phase, res = templates["steps"][4][0]
    d, c = res.diagnostics, res.command
    calls = {"schema.controller_sample": lambda: schema.controller_sample(0.1, phase, d, c, sysid=4),
             "  + schema.encode (json.dumps)": lambda: schema.encode(schema.controller_sample(0.1, phase, d, c,
                                                                                              sysid=4)),
             "capture.controller (caller)": lambda: capture.controller(0.1, phase, d, c, sysid=4),
             "  + finish (sender)": lambda: capture.finished(capture.controller(0.1, phase, d, c, sysid=4))}
    print("  the same builders called back to back (hot caches), best of 7 x 2000:")
    for name, fn in calls.items():
        best = min(timeit.repeat(fn, number=2000, repeat=7)) / 2000 * 1e6
        print(f"    {name:32s} {best:5.1f} us")


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
                rec = subprocess.Popen([sys.executable, "-m", "ground_station", "record", "--insecure", "--out", f"{tmp}/b.mcap",
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
_TEMPLATES = ("controller", "truth", "contact", "object", "run_start")  # what the children get (JSON)
_HEAD = binary.HEADER
_HEAD_SYSID = struct.Struct("<dQI")  # t, seq, sysid: how controller, truth and contact start
def child(a) -> None:
    """One publishing process of the throughput test."""
    data = json.loads(Path(a.data).read_text())
    name = "simulator" if a.child == "sim" else f"am{a.sysid}"
    pub = TelemetryPublisher(ZenohOptions(connect=(a.endpoint,)), name=name, queue_size=20000)
    pub.open()
    pub.wait_for_subscriber(KEYS.sim_event, 20.0)
    steps = int(a.seconds * a.rate)
    if a.encoding == "binary":  # each template converted once; per step only t, sysid patched
        for name, ch in (("controller", Channel.CONTROLLER), ("truth", Channel.AM_TRUTH), ("contact", Channel.CONTACT)):
            data[name] = {s: [bytearray(binary.from_dict(ch, p)) for p in ps] for s, ps in data[name].items()}
        data["object"] = [bytearray(binary.from_dict(Channel.OBJECT, p)) for p in data["object"]]

    def sample(template, t: float, sysid: int | None = None):
        if a.encoding == "json":
            return dict(template, t=t) if sysid is None else dict(template, t=t, sysid=sysid)
        out = bytes(template)  # a copy: the publisher keeps it until it is sent
        return _HEAD.pack(t, 0) + out[16:] if sysid is None else _HEAD_SYSID.pack(t, 0, sysid) + out[20:]

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
            pub.publish(KEYS.controller(a.sysid), sample(src(data["controller"], a.sysid)[j], t, a.sysid))
        elif k % a.truth_every == 0:
            for s in range(a.ams):
                pub.publish(KEYS.am_truth(s), sample(src(data["truth"], s)[j], t, s))
                pub.publish(KEYS.contact(s), sample(src(data["contact"], s)[j], t, s))
            pub.publish(KEYS.object, sample(data["object"][j], t))
    wall = time.perf_counter() - t0
    st = pub.close(timeout_s=10.0)
    print(json.dumps({"who": a.child, "sysid": a.sysid, "published": st.published, "sent": st.sent,
                      "dropped": st.dropped, "wall_s": wall, "late_steps": late}), flush=True)


def throughput(templates: dict, n_ams: int, rate: float, seconds: float, truth_every: int, encoding: str) -> None:
    print(f"\n2. recorder throughput, {encoding} samples: {n_ams} companions x {rate:.0f} Hz controller + simulator "
          f"({n_ams} truth + {n_ams} contact + object) x {rate / truth_every:.0f} Hz, {seconds:.0f} s")
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "templates.json"
        data.write_text(json.dumps({k: ({str(s): v for s, v in t.items()} if isinstance(t, dict) and k != "run_start"
                                        else t) for k, t in templates.items() if k in _TEMPLATES}))
        ep, out = free_endpoint(), Path(tmp) / "run.mcap"
        rec = subprocess.Popen([sys.executable, "-m", "ground_station", "record", "--insecure", "--out", str(out), "--zenoh-listen",
                                ep, "--summary-json", "--linger", "2"], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        rec.stderr.readline()
        start_at = time.time() + 4.0 + 0.3 * n_ams  # every child imported and connected by then
        common = ["--data", str(data), "--endpoint", ep, "--rate", str(rate), "--seconds", str(seconds),
                  "--ams", str(n_ams), "--start-at", str(start_at), "--truth-every", str(truth_every),
                  "--encoding", encoding]
        child = [sys.executable, "-m", "benchmarks.bench_telemetry", "--child"]
        kids = [subprocess.Popen([*child, "companion", "--sysid", str(s), *common], stdout=subprocess.PIPE, text=True,
                                 cwd=ROOT) for s in range(n_ams)]
        kids.append(subprocess.Popen([*child, "sim", *common], stdout=subprocess.PIPE, text=True, cwd=ROOT))
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


def recorder_capacity(templates: dict, n_ams: int, seconds: float, encoding: str) -> None:
    """The recorder alone: one process puts pre-encoded real payloads (no encoding cost on the
    sending side), one sample per message, as fast as zenoh's BLOCK congestion control lets
    it, i.e. as fast as the recorder takes them."""
    import zenoh

    def enc(ch, p, **kw):
        p = dict(p, **kw)
        return schema.encode(p)[0] if encoding == "json" else wire.binary_message([binary.from_dict(ch, p)])

    per_step = []
    for s in range(n_ams):
        for name, ch, key in (("controller", Channel.CONTROLLER, KEYS.controller(s)),
                              ("truth", Channel.AM_TRUTH, KEYS.am_truth(s)),
                              ("contact", Channel.CONTACT, KEYS.contact(s))):
            per_step.append((key, [enc(ch, p, sysid=s) for p in templates[name][4 + s % 2][:200]]))
    print(f"\n3. recorder capacity: controller + truth + contact of {n_ams} AMs, pre-encoded {encoding}, "
          f"one sample per message, for {seconds:.0f} s")
    with tempfile.TemporaryDirectory() as tmp:
        ep = free_endpoint()
        rec = subprocess.Popen([sys.executable, "-m", "ground_station", "record", "--insecure", "--out", f"{tmp}/c.mcap",
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


# ----------------------------------------------------------------------------- part 4
def _published_second(templates: dict, form: str) -> list[tuple[str, bytes, bool]]:
    """(key, sample, binary?) of the captured second in the order the processes publish them:
    the run_start event, then per step each AM's controller sample, each AM's truth and
    contact, the object; seq stamped per key."""
    seqs: dict[str, int] = {}
    out = []

    def add(key: str, ch: Channel, p: dict) -> None:
        seq = seqs[key] = seqs.get(key, -1) + 1
        p = dict(p, seq=seq)
        out.append((key, binary.from_dict(ch, p), True) if form == "binary" else (key, schema.encode(p)[0], False))

    out.append((KEYS.sim_event, schema.encode(dict(templates["run_start"], seq=0))[0], False))
    sysids = sorted(templates["controller"])
    n = min(len(templates["object"]), *(len(templates[c][s]) for c in ("controller", "truth", "contact")
                                        for s in sysids))
    for j in range(n):
        for s in sysids:
            add(KEYS.controller(s), Channel.CONTROLLER, templates["controller"][s][j])
        for s in sysids:
            add(KEYS.am_truth(s), Channel.AM_TRUTH, templates["truth"][s][j])
            add(KEYS.contact(s), Channel.CONTACT, templates["contact"][s][j])
        add(KEYS.object, Channel.OBJECT, templates["object"][j])
    return out


def recorder_work(templates: dict, rounds: int) -> None:
    """Part 4: the recorder's translation and writing of one simulated second, in process."""
    from ground_station.contract import Translator
    from ground_station.mcap_io import McapLogWriter

    n_steps = len(templates["object"])
    print(f"\n4. recorder work in process (translate + write MCAP, zstd), one simulated second of the two-AM "
          f"scenario ({n_steps} steps), {rounds} rounds per form, alternating; medians over rounds")
    samples = {form: _published_second(templates, form) for form in FORMS}
    got: dict[str, list[tuple[float, int, int]]] = {form: [] for form in FORMS}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            for form in FORMS if r % 2 == 0 else FORMS[::-1]:
                path = Path(tmp) / f"{form}.mcap"
                translate = Translator(KEYS).translate
                writer = McapLogWriter(path)
                writer.open()
                c0 = time.process_time_ns()
                for key, data, is_binary in samples[form]:
                    for out in translate(key, data, is_binary):
                        writer.write(out)
                writer.close()
                got[form].append(((time.process_time_ns() - c0) / 1e3, writer.messages, path.stat().st_size))
    for form in FORMS:
        us = [g[0] for g in got[form]]
        n = len(samples[form])
        per_step = float(np.median(us)) / n_steps
        print(f"  {form:6s}: {per_step:5.1f} us per simulated step ({float(np.median(us)) / n:4.2f} us per sample, "
              f"{n / (float(np.median(us)) * 1e-6):7.0f} samples/s of one core; rounds: "
              f"{', '.join(f'{u / n_steps:.1f}' for u in us)}), {got[form][0][1]} MCAP messages, "
              f"{got[form][0][2] / 1e6:.2f} MB")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ams", type=int, default=10)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--truth-every", type=int, default=1, help="simulator publishes ground truth every N steps")
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--encoding", choices=FORMS, default="binary", help="samples of parts 2 and 3")
    ap.add_argument("--cpu-steps", type=int, default=3000, help="part 0: steps per round")
    ap.add_argument("--cpu-rounds", type=int, default=3)
    ap.add_argument("--before", metavar="REV", help="part 0: also the telemetry package at git revision REV")
    ap.add_argument("--cpu-setups", help="part 0: a comma-separated subset of the setups (default: all)")
    ap.add_argument("--skip-cpu", action="store_true")
    ap.add_argument("--skip-caller", action="store_true")
    ap.add_argument("--skip-throughput", action="store_true")
    ap.add_argument("--skip-recorder-work", action="store_true")
    ap.add_argument("--recorder-rounds", type=int, default=7, help="part 4: rounds per form")
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
    if a.before:
        load_before(a.before)
    if a.cpu_setups:
        keep = a.cpu_setups.split(",")
        for name in [k for k in SETUPS if k not in keep]:
            del SETUPS[name]
    if not a.skip_cpu:
        cpu_per_step(templates, a.cpu_steps, a.cpu_rounds)
    if not a.skip_caller:
        caller_costs(templates, a.calls)
    if not a.skip_throughput:
        throughput(templates, a.ams, a.rate, a.seconds, a.truth_every, a.encoding)
        recorder_capacity(templates, a.ams, a.seconds, a.encoding)
    if not a.skip_recorder_work:
        recorder_work(templates, a.recorder_rounds)


if __name__ == "__main__":
    main()
