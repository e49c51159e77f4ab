"""The hexarotor's cant, swept: yaw authority at hover, thrust lost, and the loaded hover's
busiest rotor, from the rotor table of configs/vehicles/hex3dof.toml with each rotor's axis
turned by +-alpha about its own arm (amcore.authority's static figures).

    python experiments/cant_sweep.py [--squeeze 9] [--load 0.5]
"""
from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from amcore.authority import vehicle_authority
from amcore.config import load_vehicle

HEX = Path(__file__).resolve().parents[1] / "configs" / "vehicles" / "hex3dof.toml"


def canted(vehicle, alpha_deg: float):
    """The vehicle with every rotor's axis turned about its arm by alpha, the sense of each
    rotor's own cant kept (the sign that makes the cant's yaw add to its drag's)."""
    a = math.radians(alpha_deg)
    rows = []
    for r in vehicle.rotors.rotor:
        radial = np.array([r.position_m[0], r.position_m[1], 0.0])
        radial /= np.linalg.norm(radial)
        tangential = np.array([-radial[1], radial[0], 0.0])
        sense = -1.0 if r.spin == "ccw" else 1.0
        axis = math.cos(a) * np.array([0.0, 0.0, 1.0]) + sense * math.sin(a) * tangential
        rows.append(dataclasses.replace(r, axis=tuple(axis.tolist())))
    return dataclasses.replace(vehicle, rotors=dataclasses.replace(vehicle.rotors, rotor=tuple(rows)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--squeeze", type=float, default=9.0)
    ap.add_argument("--load", type=float, default=0.5)
    args = ap.parse_args()
    base = load_vehicle(HEX)
    print(f"{'cant':>5} {'yaw at hover':>13} {'thrust lost':>12} {'loaded: busiest rotor':>22} {'yaw left':>9}")
    for alpha in (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0):
        va = vehicle_authority(canted(base, alpha), args.squeeze, args.load)
        op = va.loaded
        yaw_left = min(op.authority_nm["yaw"]) if op.feasible else 0.0
        print(f"{alpha:4.0f}d {min(va.hover.authority_nm['yaw']):10.2f} Nm {va.cant_loss * 100:10.1f} % "
              f"{max(op.rotor_fractions) * 100:19.0f} % {yaw_left:6.2f} Nm" + ("" if op.feasible else "  infeasible"))


if __name__ == "__main__":
    main()
