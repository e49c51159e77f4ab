"""A companion without a controller, for measuring the lockstep's own cost.

    python -m benchmarks.echo_companion --sysid 2 --sim udp:127.0.0.1:PORT --config scenario.toml [--spin-us 175]

It connects, arms and answers every sensor frame at once, through the same `amlink` client,
codec and signing as the real companion: in torque mode with the same torque setpoint (the
vehicle's hover thrust, zero torques); in attitude mode with an attitude setpoint that holds
the frame's attitude at hover thrust, zero rates and zero joint torques, so that the
simulator's autopilot flies it as it flies a companion's (a torque setpoint would be ignored
there, and the autopilot's work left out). `bench_sitl.py` runs it in place of `companion` to report
what the simulator, MAVLink and the processes cost when the controller costs nothing.
With --spin-us it busy-waits that long before each answer: a controller's compute time
without its memory traffic (`bench_controller.py`'s companion step is ~175 us).
Not a product: the vehicles it flies are not controlled.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from amcore.config import load_scenario
from amcore.model import build_model
from amlink import signing
from amlink.lockstep import CompanionClient
from amlink.types import AttitudeSetpoint, AttitudeTarget, TorqueSetpoint


def main() -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--sysid", type=int, required=True)
    ap.add_argument("--sim", required=True)
    ap.add_argument("--config", type=Path, required=True)
    ap.add_argument("--spin-us", type=float, default=0.0, help="busy-wait this long before each answer [us]")
    a = ap.parse_args()
    spin_s = a.spin_us * 1e-6
    spec = load_scenario(a.config)
    keys, _ = signing.keys_for_run(spec, None)
    model = build_model(spec.vehicle)
    hover_n = model.mass_kg * model.gravity_mps2
    zero3, zero_q = np.zeros(3), np.zeros(model.n)
    attitude = spec.vehicle.flight_controller.mode == "attitude"
    hover = hover_n / spec.vehicle.rotors.thrust_max_total_n  # normalized collective thrust
    with CompanionClient(a.sysid, a.sim, signing_key=None if keys is None else keys[a.sysid]) as client:
        client.connect(timeout_s=60.0)
        client.arm(timeout_s=5.0)
        while (frame := client.recv_frame(timeout_s=10.0)) is not None:
            if spin_s > 0.0:
                until = time.perf_counter() + spin_s
                while time.perf_counter() < until:
                    pass
            if attitude:
                target = AttitudeTarget(frame.step, frame.quat_WB_wxyz, zero3, hover)
                client.send_setpoint(AttitudeSetpoint(frame.step, target, zero_q))
            else:
                client.send_setpoint(TorqueSetpoint(frame.step, hover_n, zero3, zero_q))
    return 0


if __name__ == "__main__":
    sys.exit(main())
