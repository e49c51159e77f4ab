"""Ten AMs hold a 5 kg cylinder; one companion dies in the hover phase (issue 5).

Runs ten_am in-process (`sitl.inprocess`, the SITL minus sockets) with the companion
of one AM silent from --lose-at on: its flight controller goes to failsafe (hold position
and attitude with a compliant arm, then land; `simulator.failsafe`) while the other nine keep their
decentralized control. Reports whether the object stays held and how the load is shared.

    python experiments/ten_am_lose_one.py [--lose-at 14] [--sysid 2]
"""
from __future__ import annotations

import argparse
from pathlib import Path

from amcore.config import load_scenario
from sitl.inprocess import run

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--lose-at", type=float, default=14.0)
    ap.add_argument("--sysid", type=int, default=2)
    ap.add_argument("--scenario", default=str(ROOT / "configs" / "scenarios" / "ten_am.toml"))
    a = ap.parse_args()
    spec = load_scenario(a.scenario)
    o = run(spec, lost=lambda t: {a.sysid} if t >= a.lose_at else set())
    obj = o["object"]
    print(f"companion of sysid {a.sysid} silent from t = {a.lose_at} s; events: {o['events']}")
    print(f"object: final lift {100 * obj['final_lift_m']:.1f} cm, hover-window min "
          f"{100 * (obj['hover_min_lift_m'] or 0):.1f} cm, touching in hover: {obj['touching_in_hover']}")
    share = spec.object.mass_kg * spec.vehicle.gravity_mps2 / len(spec.ams)
    for s, am in o["ams"].items():
        c = o["companions"][int(s)]["at"].get("end", {})
        print(f"  sysid {s:>2}: F/T up {-am['hover_mean_ft_force_W_n'][2]:5.2f} N (share {share:.2f}), "
              f"normal {am['hover_mean_normal_force_n']:5.2f} N, slip {1e3 * am['slip_max_m']:6.2f} mm, "
              f"|r~c| end {1e3 * c.get('r_c_err', float('nan')):7.2f} mm, saturated {am['saturated_steps']}, "
              f"base hit {am['base_contacts']}")
    held = obj["hover_min_lift_m"] is not None and obj["final_lift_m"] >= 0.2 and not obj["touching_in_hover"]
    print("HELD" if held else "DROPPED")


if __name__ == "__main__":
    main()
