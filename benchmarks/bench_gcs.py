"""What the GCS link costs: on the lockstep's main loop, on its own thread, and on a whole run.

    python -m benchmarks.bench_gcs [--runs 3] [--duration 2]

1. Main loop: `GcsSession.update` (snapshot, status changes, commands) per call and per
   step (it runs every `snapshot_every` steps), for the 2- and 10-AM scenarios.
2. The link's thread: one telemetry round (ATTITUDE + LOCAL_POSITION_NED, signed) and one
   HEARTBEAT round (HEARTBEAT + SYS_STATUS) per vehicle, built, packed and signed.
3. Whole runs (`am-run --no-telemetry`, two_am_comp): real-time factor with `--gcs none`
   and with a GCS that reads everything, alternated `--runs` times.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from tempfile import TemporaryDirectory

from amcore.config import load_scenario
from amlink.codec import Encoder
from simulator import gcs_messages
from simulator.core import SitlCore
from simulator.gcs import GcsSession, snapshot_every
from simulator.gcs_link import GcsLink

ROOT = Path(__file__).resolve().parents[1]


def main_loop_cost(scenario: str, calls: int = 2000) -> tuple[float, int]:
    spec = load_scenario(ROOT / "configs" / "scenarios" / scenario)
    core = SitlCore(spec)
    core.connect()
    try:
        link = GcsLink(None, core.sysids)  # not opened: update only stores and queues
        session = GcsSession(core, link, lambda s: True, snapshot_every(spec.rate_hz))
        core.frames(0)
        t0 = time.perf_counter()
        for _ in range(calls):
            session.update()
            link._outbox.clear()
        return (time.perf_counter() - t0) / calls, session.every
    finally:
        core.close()


def thread_cost(n_vehicles: int, rounds: int = 500) -> tuple[float, float]:
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    core = SitlCore(spec)
    core.connect()
    try:
        v = core.snapshot({s: True for s in core.sysids}).vehicles[0]
    finally:
        core.close()
    enc = Encoder(4, 1, signing_key=bytes(range(32)))
    t0 = time.perf_counter()
    for i in range(rounds):
        for _ in range(n_vehicles):
            enc.pack([gcs_messages.attitude(v, i), gcs_messages.local_position_ned(v, i)])
    telemetry = (time.perf_counter() - t0) / rounds
    t0 = time.perf_counter()
    for _ in range(rounds):
        for _ in range(n_vehicles):
            enc.pack([gcs_messages.heartbeat(v), gcs_messages.sys_status(v)])
    return telemetry, (time.perf_counter() - t0) / rounds


def whole_run(duration: float, gcs: bool) -> float:
    from pymavlink import mavutil

    stop = threading.Event()
    conn = mavutil.mavlink_connection("udpin:127.0.0.1:0", dialect="common") if gcs else None
    reader = None
    if conn is not None:
        def read() -> None:
            while not stop.is_set():
                conn.recv_match(blocking=True, timeout=0.05)
        reader = threading.Thread(target=read, daemon=True)
        reader.start()
    endpoint = f"udpout:127.0.0.1:{conn.port.getsockname()[1]}" if conn else "none"
    with TemporaryDirectory() as tmp:
        exe = str(Path(sys.executable).parent / "am-run")
        subprocess.run([exe, str(ROOT / "configs" / "scenarios" / "two_am_comp.toml"), "--run-dir", tmp,
                        "--duration", str(duration), "--no-telemetry", "--no-progress", "--gcs", endpoint],
                       capture_output=True, check=True)
        rtf = json.loads((Path(tmp) / "outcome.json").read_text())["real_time_factor"]
    stop.set()
    if reader is not None:
        reader.join()
        conn.close()
    return rtf


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--duration", type=float, default=2.0)
    a = ap.parse_args()
    for scenario in ("two_am_comp.toml", "ten_am.toml"):
        per_call, every = main_loop_cost(scenario)
        print(f"main loop, {scenario}: GcsSession.update {per_call * 1e6:.1f} us per call, every {every} steps: "
              f"{per_call / every * 1e6:.2f} us per step")
    for n in (2, 10):
        tel, beat = thread_cost(n)
        print(f"link thread, {n} vehicles: telemetry round {tel * 1e6:.0f} us (x25/s: {tel * 25 * 100:.1f} % "
              f"of a core), heartbeat round {beat * 1e6:.0f} us (x1/s)")
    none, read = [], []
    for _ in range(a.runs):
        none.append(whole_run(a.duration, gcs=False))
        read.append(whole_run(a.duration, gcs=True))
    print(f"two_am_comp, {a.duration:g} s, real-time factor: --gcs none {', '.join(f'{x:.3f}' for x in none)} "
          f"(median {statistics.median(none):.3f}); a GCS reading {', '.join(f'{x:.3f}' for x in read)} "
          f"(median {statistics.median(read):.3f})")


if __name__ == "__main__":
    main()
