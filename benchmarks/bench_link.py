"""Benchmark: lockstep steps per second over loopback, signed or not, clean or lossy.

Run ``python -m benchmarks.bench_link``; prints steps/s for each case.  Not a test:
timings depend on the machine (and the companions here are trivial threads).
"""

from __future__ import annotations

import argparse
import threading
import time

from amlink.lockstep import CompanionClient, SimServer
from amlink.shim import LossyShim
from amlink.types import ScenarioInfo, SensorFrame, TorqueSetpoint

_SCENARIO = ScenarioInfo(scenario_id=1, n_am=2, name="bench", seed=0, rate_hz=1000.0)


def _frame(step: int) -> SensorFrame:
    return SensorFrame(step, step * 1e-3, [0, 0, 1], [1, 0, 0, 0], [0] * 3, [0] * 3, [0.1] * 3, [0] * 3, [0] * 6)


def _companion(client: CompanionClient) -> None:
    client.connect(10.0)
    client.arm(10.0)
    while (f := client.recv_frame(10.0)) is not None:
        client.send_setpoint(TorqueSetpoint(f.step, 20.0, [0, 0, 0], f.q))


def run(steps: int, signing: bool, loss: float, n_am: int = 2, retry_s: float = 0.005) -> float:
    """Steps per second of ``steps`` lockstep steps with ``n_am`` companion threads."""
    sysids = list(range(2, 2 + n_am))
    keys = {s: bytes([s]) * 32 for s in sysids} if signing else {s: None for s in sysids}
    shim = (lambda seed: LossyShim(loss=loss, duplicate=loss / 2, reorder=loss / 2, seed=seed)) if loss else (
        lambda seed: None)  # fmt: skip
    server = SimServer("udp:127.0.0.1:0", sysids=sysids, scenario=_SCENARIO, timeout_s=10.0,
                       signing_keys=keys if signing else None, retry_s=retry_s, shim=shim(1))  # fmt: skip
    server.open()
    url = f"udp:127.0.0.1:{server.address[1]}"
    clients = [CompanionClient(s, url, signing_key=keys[s], shim=shim(s)) for s in sysids]
    threads = [threading.Thread(target=_companion, args=(c,), daemon=True) for c in clients]
    for t in threads:
        t.start()
    try:
        server.wait_for_peers(10.0)
        server.wait_for_armed(10.0)
        t0 = time.perf_counter()
        for k in range(steps):
            server.exchange({s: _frame(k) for s in sysids})
        return steps / (time.perf_counter() - t0)
    finally:
        server.close()
        for t in threads:
            t.join(2.0)
        for c in clients:
            c.close()


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=2000)
    args = ap.parse_args(argv)
    for signing in (False, True):
        for loss in (0.0, 0.05, 0.2):
            rate = run(args.steps if loss == 0 else args.steps // 4, signing, loss)
            print(f"{'signed' if signing else 'unsigned':8s} loss {loss:4.2f} (+dup, reorder {loss / 2:.3f}):"
                  f" {rate:8.0f} steps/s (2 companions, retry 5 ms)")  # fmt: skip


if __name__ == "__main__":
    main()
