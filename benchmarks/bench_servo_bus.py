"""Round trip of one arm cycle over the emulated servo bus: one SYNC READ (present current,
velocity, position) and one SYNC WRITE (goal current) of 3 servos through dynamixel-sdk over
TCP (companion.devices.arm.ArmClient against simulator.servo_bus.ServoBus).

    python -m benchmarks.bench_servo_bus [--cycles 1000] [--servos 3]

The bus runs in its own process (as the simulator does), served two ways:
- "select": it wakes when bytes arrive (the latency floor of the protocol and the SDK);
- "tick 1 kHz": it polls once per 1 ms deadline (drift-free), as a 1 kHz free-running loop
  that calls `poll` once a physics step would.
Prints median, p99 and max of the cycle time [ms] and how many cycles fit a 4 ms (250 Hz) period.
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import select
import statistics
import time

from companion.devices.arm import ArmClient
from simulator.servo_bus import ServoBus


def serve(n: int, mode: str, ready, stop) -> None:
    bus = ServoBus(n, endpoint="tcpin:127.0.0.1:0")
    bus.open()
    ready.put(bus.address)
    period_ns, deadline = 1_000_000, time.monotonic_ns()
    while not stop.is_set():
        if mode == "select":
            select.select(bus.fds(), [], [], 0.05)
        else:
            deadline += period_ns
            time.sleep(max(0.0, (deadline - time.monotonic_ns()) * 1e-9))
        bus.poll(time.monotonic())
    bus.close()


def measure(n: int, cycles: int, mode: str) -> list[float]:
    ctx = mp.get_context("spawn")
    ready, stop = ctx.Queue(), ctx.Event()
    p = ctx.Process(target=serve, args=(n, mode, ready, stop), daemon=True)
    p.start()
    host, port = ready.get(timeout=30)
    arm = ArmClient(f"tcp:{host}:{port}", n)
    arm.open()
    out = []
    try:
        for _ in range(50):  # warm up
            arm.read()
            arm.write_torques([0.0] * n)
        for _ in range(cycles):
            t0 = time.perf_counter_ns()
            arm.read()
            arm.write_torques([0.01] * n)
            out.append((time.perf_counter_ns() - t0) * 1e-6)
    finally:
        arm.close()
        stop.set()
        p.join(5)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=1000)
    ap.add_argument("--servos", type=int, default=3)
    a = ap.parse_args()
    for mode, label in (("select", "select"), ("tick", "tick 1 kHz")):
        ms = sorted(measure(a.servos, a.cycles, mode))
        p99 = ms[min(len(ms) - 1, int(0.99 * len(ms)))]
        fit = sum(m < 4.0 for m in ms) / len(ms)
        print(f"{label:11s} {a.servos} servos, {len(ms)} cycles: median {statistics.median(ms):.3f} ms, "
              f"p99 {p99:.3f} ms, max {ms[-1]:.3f} ms, under 4 ms {100 * fit:.1f} %")


if __name__ == "__main__":
    main()
