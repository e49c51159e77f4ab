"""A simulator or companion process with its per-step parts timed in place (bench_inplace.py).

    python -m benchmarks.inplace_parts simulator|companion OUT.json -- <the process's arguments>

Wraps the methods that make up a lockstep step (the list below) so that each call adds its
thread CPU time (`time.thread_time_ns`: waiting in select() costs nothing) to its part, then
runs the process's main as `am-run` would. At exit it writes, per part, the number of calls
and the median, 90th percentile and sum of their CPU times to OUT.json. Parts nest (the
companion's `command` contains `control.step`); each timed call adds two clock reads, about
a microsecond here.
"""
from __future__ import annotations

import importlib
import json
import sys
import time
from collections import defaultdict

# (module, name in it: a function or Class.method, part name)
SIMULATOR_PARTS = [
    ("simulator.core", "SitlCore.hold", "hold step: devices, truth, autopilot"),
    ("simulator.core", "SitlCore.actuate", "actuate (all AMs)"),
    ("simulator.core", "SitlCore.on_setpoint", "apply on arrival"),
    ("simulator.core", "SitlCore._sense", "devices and estimator (one AM)"),
    ("simulator.core", "SitlCore._apply", "flight controller (one AM)"),
    ("simulator.core", "SitlCore.observe", "digest and truth"),
    ("simulator.core", "SitlCore.step", "physics step"),
    ("simulator.world", "World.step", "pybullet stepSimulation"),
    ("amlink.server", "SimServer.exchange", "exchange (send frames, wait, receive, apply)"),
    ("amlink.server", "SimServer.send_frames", "send frames (sense, devices, encode, sign)"),
    ("amlink.server", "SimServer.collect", "collect setpoints"),
    ("amlink.server", "SimServer._handle", "decode and verify a datagram"),
    ("amlink.codec", "sensor_frame_payloads", "encode a frame"),
    ("simulator.world", "World.sensor_values", "sense: PyBullet's getters (one AM)"),
    ("simulator.core", "sensor_frame_of_array", "the frame from its values, the autopilot's reports in it (one AM)"),
    ("amlink.wire", "Encoder.pack_payloads", "frame, CRC and sign the payloads"),
    ("amlink.transport", "Udp.send", "socket: sendto"),
    ("simulator.gcs", "GcsSession.tick", "GCS link"),
]
COMPANION_PARTS = [
    ("amlink.client", "CompanionClient.recv_frame", "receive a frame"),
    ("amlink.transport", "Udp.recv", "socket: select and recvfrom"),
    ("amlink.wire", "Decoder.feed_records", "verify and decode"),
    ("amlink.client", "CompanionClient._on_message", "frame assembly and checks"),
    ("companion.pilot", "Pilot.command", "command (state, references, law)"),
    ("companion.pilot", "offboard_step", "attitude-mode law (offboard_step)"),
    ("amcore.offboard", "step", "control.step (pinocchio and the compiled law)"),  # attitude mode
    ("amcore.control", "step", "control.step (pinocchio and the compiled law)"),  # torque mode (Pilot.law)
    ("amcore.mission", "AmMission.reference", "references"),
    ("amlink.client", "CompanionClient.send_setpoint", "encode, sign, send"),
    ("companion.pilot", "Pilot.record", "per-phase bookkeeping"),
    ("telemetry.wiring", "CompanionTelemetry.step", "telemetry"),
]

_samples: dict[str, list[int]] = defaultdict(list)


def _timed(fn, part: str):
    record = _samples[part].append
    clock = time.thread_time_ns

    def timed(*args, **kwargs):
        t0 = clock()
        try:
            return fn(*args, **kwargs)
        finally:
            record(clock() - t0)
    timed.__wrapped__ = fn
    return timed


def instrument(parts) -> None:
    for module, name, part in parts:
        owner = importlib.import_module(module)
        *path, attr = name.split(".")
        for p in path:
            owner = getattr(owner, p)
        setattr(owner, attr, _timed(getattr(owner, attr), part))


def summary() -> dict:
    out = {}
    for part, xs in _samples.items():
        xs = sorted(xs)
        if xs:
            out[part] = {"calls": len(xs), "median_us": xs[len(xs) // 2] / 1e3,
                         "p90_us": xs[int(0.9 * (len(xs) - 1))] / 1e3, "sum_s": sum(xs) / 1e9}
    return out


def main() -> int:
    role, out = sys.argv[1], sys.argv[2]
    args = sys.argv[sys.argv.index("--") + 1:]
    if role == "simulator":
        instrument(SIMULATOR_PARTS)
        from simulator.main import main as run
    elif role == "companion":
        instrument(COMPANION_PARTS)
        from companion.main import main as run
    else:
        raise SystemExit(f"role must be simulator or companion, got {role!r}")
    t0 = time.thread_time()
    try:
        return run(args)
    finally:
        with open(out, "w") as f:
            json.dump({"role": role, "thread_cpu_s": time.thread_time() - t0, "parts": summary()}, f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
