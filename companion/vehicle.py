"""am-vehicle: print what a vehicle's rotors can do (amcore.authority).

    am-vehicle configs/vehicles/hex3dof.toml
    am-vehicle configs/vehicles/am3dof.toml --squeeze 9 --load 0.5
    am-vehicle configs/vehicles/hex3dof.toml --team 2 --friction 0.5 --mass 2.5

It prints what tuning the vehicle needs (amcore.tuning): the whole AM's mass and inertia,
PX4's torque units and the attitude-mode gains in effect beside the rule that derives them
(amcore.px4_gains), sigma_min of Jbar_3 and the task inertia at the nominal pose; the loader's
warnings (a task component the arm cannot move) on stderr. With --team, it also prints the
team's payload (amcore.envelope: the squeeze the object needs at that friction against what
each AM can push with its margins kept) and, with --mass, whether that object is inside the
envelope or how many AMs it needs.

Exit codes: 0 the vehicle can do what was asked; 2 bad arguments or a bad vehicle file (named
in the message); 4 it cannot (a hover the rotors cannot make, an arm joint beyond its torque
limit, or an object outside the team's envelope), the reason printed.
"""
from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

from amcore.config import ConfigError, ConfigWarning, load_vehicle

CANNOT = 4  # the vehicle cannot do what it was asked


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
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter,
                                 epilog="Exit codes: 0 printed; 2 bad arguments or a bad vehicle file (named in the "
                                        "message).")
    ap.add_argument("vehicle", type=Path, help="a vehicle TOML (configs/vehicles/*.toml)")
    ap.add_argument("--squeeze", type=_nonneg, default=0.0, metavar="N",
                    help="normal force the pad pushes the object's face with [N]")
    ap.add_argument("--load", type=_nonneg, default=0.0, metavar="KG", help="object mass this AM carries [kg]")
    ap.add_argument("--team", type=int, default=0, metavar="N", help="a team of N of these AMs: print its payload")
    ap.add_argument("--friction", type=_nonneg, default=0.5, help="the lowest pad friction planned for (with --team)")
    ap.add_argument("--friction-margin", type=_nonneg, default=1.2, help="squeeze margin over friction (with --team)")
    ap.add_argument("--mass", type=_nonneg, default=None, metavar="KG", help="an object's mass: inside the team's "
                    "envelope? (with --team)")
    args = ap.parse_args(argv)
    if args.team < 0 or args.team > 64 or (args.team and not (args.friction > 0.0 and args.friction_margin > 0.0)):
        ap.error("--team must be 0 to 64, and --friction and --friction-margin > 0")
    if args.mass is not None and not args.team:
        ap.error("--mass needs --team")
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConfigWarning)
            vehicle = load_vehicle(args.vehicle)
    except ConfigError as exc:
        print(f"am-vehicle: {exc}", file=sys.stderr)
        return 2
    for w in caught:
        print(f"am-vehicle: warning: {w.message}", file=sys.stderr)
    from amcore.authority import report_lines, vehicle_authority  # pinocchio: after the arguments are checked
    from amcore.model import build_model
    from amcore.tuning import nominal_tuning, tuning_lines

    try:
        va = vehicle_authority(vehicle, args.squeeze, args.load)
    except ConfigError as exc:  # an arm the loaded hover's model does not fit (amcore.authority)
        print(f"am-vehicle: {exc}", file=sys.stderr)
        return 2
    for line in report_lines(va):
        print(line)
    for line in tuning_lines(vehicle, nominal_tuning(vehicle, build_model(vehicle))):
        print(line)
    cannot = [f"the {label}: {why}" for label, op in (("hover", va.hover), ("loaded hover", va.loaded))
              if op is not None for why in _infeasible(op)]
    if args.team:
        from amcore.envelope import Envelope, verdict_line

        env = Envelope(vehicle)
        try:
            m = env.payload_kg(args.team, args.friction, args.friction_margin)
        except ConfigError as exc:
            print(f"am-vehicle: {exc}", file=sys.stderr)
            return 2
        mg = env.margins
        print(f"team of {args.team} at friction {args.friction:g} (margin {args.friction_margin:g}) holds up to "
              f"{m:.2f} kg (rotors within {mg.thrust_fraction_max:.0%}, {mg.yaw_reserve_nm:g} N m of yaw and {mg.pitch_reserve_nm:g} N m of pitch left, "
              f"arm joints within {mg.joint_fraction_max:.0%})")
        if args.mass is not None:
            print(verdict_line(env, args.mass, args.team, args.friction, args.friction_margin))
            if not env.fit(args.mass, args.team, args.friction, args.friction_margin).holds:
                cannot.append(f"a {args.mass:g} kg object is outside the envelope of a team of {args.team}")
    if cannot:
        print(f"am-vehicle: NOT FEASIBLE: {'; '.join(cannot)}", file=sys.stderr)
        return CANNOT
    return 0


def _infeasible(op) -> list[str]:
    """Why an operating point (amcore.authority) cannot be flown; empty if it can."""
    out = [] if op.feasible else ["the rotors cannot make it"]
    if max(op.joint_fractions) > 1.0:
        out.append(f"an arm joint needs {max(op.joint_fractions):.0%} of its torque limit")
    return out


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
