"""One variation at a time: the base scenario with each single change of the default
randomization's kinds, run in-process, with the mission verdict of each.

    python experiments/one_factor.py [configs/scenarios/two_am_comp.toml] [--workers 2] [--duration S]

Shows which variation breaks the grasp on its own (trial campaigns mix them all).
"""
from __future__ import annotations

import argparse
import copy
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from amcore.config import read_scenario
from trials.randomize import load_randomize

ROOT = Path(__file__).resolve().parents[1]

SENSORS = load_randomize(ROOT / "configs" / "randomize" / "stress_states.toml").sensors  # white noise on the states
DEVICES = load_randomize(ROOT / "configs" / "randomize" / "default.toml").devices  # devices and estimator


def _devices_only(part: str) -> dict:
    """The default devices with every level zeroed but those of [devices.<part>]."""
    d = copy.deepcopy(DEVICES)
    for name, table in d.items():
        if isinstance(table, dict) and name not in (part, "estimator"):
            for k, v in table.items():
                if not k.endswith(("rate_hz", "latency_s", "correlation_time_s", "tare_at_s", "tare_window_s")):
                    table[k] = type(v)(0)
    return d


def variations(base: dict) -> dict[str, dict]:
    first = base["am"][0]["sysid"]

    def with_(**changes):
        d = copy.deepcopy(base)
        for table, values in changes.items():
            if table == "am0":
                d["am"][0].update(values)
            else:
                d.setdefault(table, {}).update(values)
        return d

    size = base["object"].get("size_m", [0.2, 0.2, 0.2])
    return {
        "nominal": with_(),
        "sensors on the states (stress)": with_(sensors=SENSORS),
        "devices (default levels)": with_(devices=DEVICES),
        "devices: IMU only": with_(devices=_devices_only("imu")),
        "devices: motion capture only": with_(devices=_devices_only("mocap")),
        "devices: F/T only": with_(devices=_devices_only("ft")),
        "devices: encoders only": with_(devices=_devices_only("encoders")),
        "sensor latency 2 ms": with_(sensors={"latency_s": 0.002}),
        f"am{first} start offset 5 cm, 5 deg": with_(am0={"start_offset_m": [0.05, 0.05, 0.05],
                                                         "start_heading_deg": 5.0}),
        f"am{first} misaligned 0.1 deg": with_(am0={"misalignment_deg": 0.1}),
        f"am{first} misaligned 2 deg": with_(am0={"misalignment_deg": 2.0}),
        f"am{first} misaligned 5 deg": with_(am0={"misalignment_deg": 5.0}),
        "object 2 kg": with_(object={"mass_kg": 2.0}),
        "pad friction 0.5": with_(object={"pad_friction": 0.5}),
        "object 0.5 kg, friction 1.2": with_(object={"mass_kg": 0.5, "pad_friction": 1.2}),
        "object size x0.8": with_(object={"size_m": [0.8 * s for s in size]}),
        "object size x1.2": with_(object={"size_m": [1.2 * s for s in size]}),
        "setpoint loss 10 %": with_(link={"loss": 0.1}),
    }


def _run(args):
    name, data, path, duration = args
    from amcore.config import scenario_from_dict
    from sitl.inprocess import run
    r = run(scenario_from_dict(data, Path(path)), duration)
    o = r["object"]
    slip = max(a["slip_max_m"] for a in r["ams"].values())
    sat = max(a["saturated_steps"] for a in r["ams"].values())
    return name, r["verdict"], o["hover_min_lift_m"], slip, sat


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("scenario", nargs="?", default=str(ROOT / "configs" / "scenarios" / "two_am_comp.toml"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--only", default=None, help="run only variations whose name contains this")
    a = ap.parse_args()
    path = Path(a.scenario).resolve()
    base = read_scenario(path)
    jobs = [(n, d, str(path), a.duration) for n, d in variations(base).items() if a.only is None or a.only in n]
    with ProcessPoolExecutor(a.workers) as ex:
        for name, v, lift, slip, sat in ex.map(_run, jobs):
            lift_txt = f"{lift * 100:5.1f} cm" if lift is not None else "   -   "
            print(f"{name:34s} {v['status']:10s} lift {lift_txt}  slip {slip * 1e3:7.1f} mm  sat {sat:6d}  "
                  f"{v['failure_class'] or ''}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
