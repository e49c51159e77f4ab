"""am-vehicle: print what a vehicle's rotors can do (amcore.authority).

    am-vehicle configs/vehicles/hex3dof.toml
    am-vehicle configs/vehicles/am3dof.toml --squeeze 9 --load 0.5

Exit codes: 0 printed; 2 bad arguments or a bad vehicle file (named in the message).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from amcore.config import ConfigError, load_vehicle


def _nonneg(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not (math.isfinite(x) and x >= 0.0):
        raise argparse.ArgumentTypeError(f"must be finite and >= 0, got {text!r}")
    return x


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="am-vehicle", description="Thrust margin and torque authority of a vehicle "
                                 "file: at hover, and in a loaded hover squeezing a vertical face.",
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("vehicle", type=Path, help="a vehicle TOML (configs/vehicles/*.toml)")
    ap.add_argument("--squeeze", type=_nonneg, default=0.0, metavar="N",
                    help="normal force the pad pushes the object's face with [N]")
    ap.add_argument("--load", type=_nonneg, default=0.0, metavar="KG", help="object mass this AM carries [kg]")
    args = ap.parse_args(argv)
    try:
        vehicle = load_vehicle(args.vehicle)
    except ConfigError as exc:
        print(f"am-vehicle: {exc}", file=sys.stderr)
        return 2
    from amcore.authority import report_lines, vehicle_authority  # pinocchio: after the arguments are checked

    for line in report_lines(vehicle_authority(vehicle, args.squeeze, args.load)):
        print(line)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
