"""How much link impairment the two-AM grasp tolerates (issue 5).

Sweeps packet loss and delay on the companion -> flight-controller path (`[link]` of the
scenario, applied in simulation time by `amlink.impair`; the flight controller holds the
newest command) and runs the whole two_am_comp mission in-process (`sitl.inprocess`,
bit-identical to the multi-process SITL on an ideal link). A grasp "holds" when, in the
hover window, the object is >= 0.2 m up and off the table, pad slip < 2 mm, no base touched
anything and no vehicle saturated for more than 1 % of the run.

    python experiments/link_tolerance.py [--loss 0 0.2 0.4 0.6 0.8] [--delay-ms 0 5 10 20 40]
"""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from amcore.config import load_scenario
from sitl.inprocess import run

ROOT = Path(__file__).resolve().parents[1]


def holds(o: dict) -> tuple[bool, str]:
    obj = o["object"]
    lift = obj["hover_min_lift_m"]
    slip = max(a["slip_max_m"] for a in o["ams"].values())
    sat = max(a["saturated_steps"] for a in o["ams"].values()) / o["steps"]
    crash = any(a["base_contacts"] for a in o["ams"].values())
    ok = lift is not None and lift >= 0.2 and not obj["touching_in_hover"] and slip < 2e-3 and not crash and sat < 0.01
    return ok, f"lift {100 * (lift or 0):5.1f} cm, slip {1e3 * slip:6.2f} mm, saturated {100 * sat:4.1f} %" + (
        ", base hit" if crash else "")


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--scenario", default=str(ROOT / "configs" / "scenarios" / "two_am_comp.toml"))
    ap.add_argument("--loss", type=float, nargs="+", default=[0.0, 0.2, 0.4, 0.6, 0.8])
    ap.add_argument("--delay-ms", type=float, nargs="+", default=[0.0, 5.0, 10.0, 20.0, 40.0])
    a = ap.parse_args()
    spec = load_scenario(a.scenario)
    print(f"{spec.name}: loss sweep at zero delay, then delay sweep at zero loss (seed {spec.seed})")
    for loss in a.loss:
        o = run(dataclasses.replace(spec, link=dataclasses.replace(spec.link, loss=loss)))
        ok, text = holds(o)
        print(f"loss {100 * loss:4.0f} %  delay   0 ms: {'HOLDS' if ok else 'FAILS'}  {text}", flush=True)
    for d in a.delay_ms:
        o = run(dataclasses.replace(spec, link=dataclasses.replace(spec.link, delay_s=d * 1e-3)))
        ok, text = holds(o)
        print(f"loss    0 %  delay {d:3.0f} ms: {'HOLDS' if ok else 'FAILS'}  {text}", flush=True)


if __name__ == "__main__":
    main()
