"""Free-flight demo: one AM under the paper's controller in the ideal model (no contact).

    am-demo [--config configs/scenarios/two_am_comp_attitude.toml] [--sysid 4] [--duration 5]

Starts the AM off its reference (5 cm, 0.13 rad, and every arm joint off by `joint_offsets`),
flies the approach phase against pinocchio's forward dynamics and prints the errors of
Theorem 1 over time.
This is the process-free use of the public API: load, build, step.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from amcore import cliargs
from amcore.config import DEFAULT_SCENARIO, ConfigError, load_scenario
from amcore.control import ControllerParams
from amcore.ideal import run_closed_loop
from amcore.mission import am_mission
from amcore.model import AmState, build_model
from amcore.so3 import exp_so3


def joint_offsets(n: int) -> np.ndarray:
    """The start's joint error [rad]: 0.1 on each of the n joints with alternating sign, halved on
    the last (the wrist, whose task inertia is the smallest); 0.1, -0.1, 0.05 for the paper's arm."""
    d = np.array([0.1 * (-1) ** i for i in range(n)])
    d[-1] *= 0.5
    return d


def main(argv: list[str] | None = None) -> int:
    ap = cliargs.ArgumentParser(prog="am-demo", description=" ".join(__doc__.split("\n\n")[0].split()),
                                epilog=cliargs.exit_codes(0, 2, c0="the demo ran"))
    ap.add_argument("--config", type=Path, default=DEFAULT_SCENARIO)
    ap.add_argument("--sysid", type=cliargs.number(2, 255, integer=True), default=None)
    ap.add_argument("--duration", type=cliargs.number(0.0, 3600.0, lo_open=True, unit=" s"), default=5.0)
    a = ap.parse_args(argv)
    try:
        spec = load_scenario(a.config)
        am = spec.am(a.sysid) if a.sysid is not None else spec.ams[0]
    except ConfigError as exc:
        return cliargs.fail("am-demo", str(exc))
    model = build_model(spec.vehicle)
    mission = am_mission(spec, am, model)
    params = ControllerParams.from_vehicle(spec.vehicle, mission.frame)
    x = mission.initial_state()
    x0 = AmState(x.p_WB + np.array([0.05, -0.03, 0.04]), x.R_WB @ exp_so3(np.array([0.05, -0.04, 0.1])),
                 x.v_B, x.w_B, x.q + joint_offsets(model.n), x.qdot)
    print(f"scenario {spec.name}, AM sysid {am.sysid}: m = {model.mass_kg:.3f} kg, n = {model.n} joints, "
          f"hover thrust {model.mass_kg * model.gravity_mps2:.2f} N")
    print(f"{'t [s]':>6} {'|r~_c| [mm]':>12} {'|e_R| [rad]':>12} {'|y~| max':>10} {'thrust [N]':>11} {'sigma_min':>10}")
    t0 = time.perf_counter()
    out = run_closed_loop(model, params, mission.reference, x0, a.duration, every=250)
    wall = time.perf_counter() - t0
    for s in out:
        d = s.result.diagnostics
        print(f"{s.t:6.2f} {1e3 * np.linalg.norm(d.r_c_err):12.3f} {np.linalg.norm(d.e_R):12.5f} "
              f"{np.abs(d.y_err).max():10.5f} {s.result.command.thrust_n:11.3f} {d.sigma_min_J3:10.3f}")
    print(f"simulated {a.duration:.1f} s in {wall:.1f} s wall ({a.duration / wall:.2f}x real time, RK4 plant at 1 kHz)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
