"""What a team of these AMs can hold: the squeeze a grasp needs against the squeeze each AM
can push in a loaded hover with margin left (pure: amcore.authority's static hover).

A team of n AMs holds an object of mass m by friction: each pad pushes

    N_req = margin * m g / (n mu)

at the lowest friction mu planned for. An AM can push N in the loaded hover (its share m / n
on the pad) while the allocation keeps every rotor at or below `thrust_fraction_max` of its
range and leaves at least `yaw_reserve_nm` of yaw torque both ways (contact moments about the
pad, a pad pushed off its face's normal: 0.15-0.34 N m, docs/robust_grasp.md) and at least
`pitch_reserve_nm` of pitch torque both ways, and every arm joint holds its static torque
within `joint_fraction_max` of its limit. Its capacity N_max(m / n) is the largest N such
that every squeeze up to it keeps them (the grasp ramps the squeeze up from zero). The team
holds m when N_req <= N_max(m / n); its payload is the largest such m.

The pitch reserve is for what the static loaded hover does not see. The squeeze tilts the
base toward the object, and the pitch torque that holds the arm's load and the squeeze's
moment comes from the front rotors pushing more and the rear ones less: near the edge the
rear rotors sit at a few per cent of their range, and roll and yaw need them too. Flown
(`two_am_robust`, every device on, torque mode), the mean hover pitch torque exceeded the
static point's (at the true load) by 0.31-0.49 N m (four AM hovers, 1.29 and 1.42 kg
objects squeezed with 16.9 and 17.2 N), and its 99th-percentile excursion about that mean
was 0.13-0.22 N m: the reserve, 0.7 N m, is their sum, the largest of each. The 1.42 kg
flight, with 0.56 N m of pitch left in its static point, saturated its rear rotors on 9.7 %
of the steps (roll first); the 1.29 kg one, 0.71 N m left, on 1 step.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .allocation import Allocation
from .authority import operating_point
from .config import VehicleParams
from .mission import nominal_geometry
from .model import AmModel, AmState, build_model, create_data, decoupled_terms

_SQUEEZE_CEILING_N = 200.0  # no AM of this project pushes more; the bisection's upper end


@dataclass(frozen=True)
class Margins:
    """What the loaded hover must leave: busiest rotor at most this share of its range, and
    this much yaw torque both ways [N m]."""

    thrust_fraction_max: float = 0.8
    yaw_reserve_nm: float = 0.3
    pitch_reserve_nm: float = 0.7  # the static model's measured gap plus the hover's excursions (module docstring)
    joint_fraction_max: float = 0.8  # each arm joint at most this share of its torque limit
    # the squeeze at most N_cr / this (buckling_squeeze_n): the criterion takes the heading's
    # stiffness at the level nominal pose, and the flown edge sat within 10 % of it
    buckling_margin: float = 1.2


@dataclass(frozen=True)
class TeamFit:
    """One team and object: the squeeze needed and the squeeze each AM can push [N]."""

    n_ams: int
    mass_kg: float
    friction: float
    friction_margin: float
    required_n: float
    capacity_n: float

    @property
    def holds(self) -> bool:
        return self.required_n <= self.capacity_n


def required_squeeze_n(mass_kg: float, n_ams: int, friction: float, friction_margin: float,
                       gravity_mps2: float = 9.81) -> float:
    """N_req of the module docstring [N]."""
    return friction_margin * mass_kg * gravity_mps2 / (n_ams * friction)


class Envelope:
    """One vehicle's loaded-hover capacity, cached per load share (see the module docstring)."""

    def __init__(self, vehicle: VehicleParams, margins: Margins = Margins(), model: AmModel | None = None):
        self.vehicle, self.margins = vehicle, margins
        self.model = model or build_model(vehicle)
        self.alloc = Allocation(vehicle.rotors)
        self.q = np.array(vehicle.q_nominal_rad, dtype=float)
        self._cache: dict[float, float] = {}

    @functools.cached_property
    def pad_side_stiffness_n_per_m(self) -> float:
        """`pad_side_stiffness_n_per_m` of this vehicle (formed once)."""
        return pad_side_stiffness_n_per_m(self.vehicle, self.model)

    def _ok(self, squeeze_n: float, load_kg: float) -> bool:
        return self.broken_margin(squeeze_n, load_kg) is None  # one statement of the margins

    def broken_margin(self, squeeze_n: float, load_kg: float) -> str | None:
        """Which margin the loaded hover at (squeeze_n [N], load_kg [kg]) breaks first, in words
        (rotors, yaw and pitch reserves, arm joints); None if it keeps them all."""
        op = operating_point(self.vehicle, self.model, self.q, squeeze_n, load_kg, self.alloc)
        mg = self.margins
        if not op.feasible:
            return "its rotors cannot make the loaded hover at all"
        if max(op.rotor_fractions) > mg.thrust_fraction_max:
            return (f"its busiest rotor at {max(op.rotor_fractions):.0%} of its range, over "
                    f"{mg.thrust_fraction_max:.0%}")
        down, up = op.authority_nm["yaw"]
        if min(down, up) < mg.yaw_reserve_nm:
            return f"{min(down, up):.2f} N m of yaw left, under the {mg.yaw_reserve_nm:g} N m reserve"
        down, up = op.authority_nm["pitch"]
        if min(down, up) < mg.pitch_reserve_nm:
            return f"{min(down, up):.2f} N m of pitch left, under the {mg.pitch_reserve_nm:g} N m reserve"
        if max(op.joint_fractions) > mg.joint_fraction_max:
            return (f"its busiest arm joint at {max(op.joint_fractions):.0%} of its torque limit, over "
                    f"{mg.joint_fraction_max:.0%}")
        return None

    def capacity_n(self, load_kg: float, tol_n: float = 0.01, scan_n: float = 2.0) -> float:
        """N_max: the most squeeze [N] such that every squeeze up to it keeps the margins, carrying
        load_kg (the grasp ramps the squeeze up from zero, so each step on the way must be flyable);
        0.0 if even no squeeze keeps them. The margins are not monotonic in the squeeze (the pitch
        reserve dips and recovers as the base tilts further), so a scan in `scan_n` steps finds the
        first squeeze that breaks one, and bisection the edge inside that step."""
        key = round(load_kg, 6)
        if key in self._cache:
            return self._cache[key]
        if not self._ok(0.0, load_kg):
            cap = 0.0
        else:
            lo = 0.0
            while lo < _SQUEEZE_CEILING_N and self._ok(min(lo + scan_n, _SQUEEZE_CEILING_N), load_kg):
                lo = min(lo + scan_n, _SQUEEZE_CEILING_N)
            if lo >= _SQUEEZE_CEILING_N:
                cap = _SQUEEZE_CEILING_N
            else:
                hi = min(lo + scan_n, _SQUEEZE_CEILING_N)
                while hi - lo > tol_n:
                    mid = 0.5 * (lo + hi)
                    lo, hi = (mid, hi) if self._ok(mid, load_kg) else (lo, mid)
                cap = lo
        self._cache[key] = cap
        return cap

    def fit(self, mass_kg: float, n_ams: int, friction: float, friction_margin: float) -> TeamFit:
        req = required_squeeze_n(mass_kg, n_ams, friction, friction_margin, self.vehicle.gravity_mps2)
        return TeamFit(n_ams, mass_kg, friction, friction_margin, req, self.capacity_n(mass_kg / n_ams))

    def payload_kg(self, n_ams: int, friction: float, friction_margin: float, tol_kg: float = 0.005) -> float:
        """The heaviest object [kg] the team holds (bisection on the mass; 0.0 if none)."""
        lo, hi = 0.0, 1.0
        while self.fit(hi, n_ams, friction, friction_margin).holds:
            lo, hi = hi, 2.0 * hi
            if hi > 1e3:
                return math.inf
        while hi - lo > tol_kg:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.fit(mid, n_ams, friction, friction_margin).holds else (lo, mid)
        return lo

    def smallest_team(self, mass_kg: float, friction: float, friction_margin: float, most: int = 32) -> int | None:
        """The fewest AMs (up to `most`) that hold mass_kg; None if no team that size does."""
        for n in range(1, most + 1):
            if self.fit(mass_kg, n, friction, friction_margin).holds:
                return n
        return None


def verdict_line(env: Envelope, mass_kg: float, n_ams: int, friction: float, friction_margin: float) -> str:
    """One line a user reads before flight, e.g. "2.5 kg at friction 0.5 needs 14.7 N per pad
    from 2 AMs; this team of 2 holds 11.2 N per pad: use 4 AMs"."""
    f = env.fit(mass_kg, n_ams, friction, friction_margin)
    can = (f"each of them can push {f.capacity_n:.1f} N" if f.capacity_n > 0.0 else
           f"none of them keeps its margins carrying its {mass_kg / n_ams:.2f} kg share")
    head = (f"{mass_kg:g} kg at friction {friction:g} (margin {friction_margin:g}) needs {f.required_n:.1f} N per pad "
            f"from {n_ams} AMs; {can}")
    if f.holds:
        return head + ": inside the envelope"
    n = env.smallest_team(mass_kg, friction, friction_margin)
    return head + (f": use {n} AMs" if n else ": no team of up to 32 of these AMs holds it")


# ------------------------------------------------------------------ buckling of the grasp
# Once a box hangs between two crowned pads on opposite faces, nothing but the pads holds its
# turning about the vertical. Turned by theta, it rolls on the crowns (radius R, vertical
# cylinders that do not turn with it): in the box's frame each crown rolls along its face by
# R theta, so in the world each pad moves along its face by a theta (a: the face's distance
# from the box's vertical axis), the two in opposite directions, and the faces come closer
# between the crowns' axes by (a - R) theta^2. The AMs meet the sideways moves with their
# stiffness along the face K (energy K a^2 theta^2, both AMs), and the squeeze N gives up
# N (a - R) theta^2 as the pads close in. The grasp buckles, like a strut between two side
# springs, once
#
#     N > N_cr = K a^2 / (a - R)            (a > R; with R >= a the squeeze steadies it),
#
# and the box turns until the squeeze, relaxing as the pads come together, falls to N_cr.
# K is the pad's sideways stiffness: the CoM's along the face (eq. Com_controller's K_t) in
# series with the heading's, a pad a lever L ahead of the CoM moving L^2 / k_psi per newton
# for a yaw stiffness k_psi (eq. u2's Lambda_w Lambda_wb,d^-1 k_R about the vertical).
# Flown (two_am_robust, every device on; docs/robust_grasp.md, section 9): on the hexarotor
# K = 54 N/m, and a 0.18 m box (N_cr 11.0 N) held at 10.5 N and turned 30-50 deg at 12 and
# 14.6 N; a 0.14 m box (13.2 N) held at 12 N; a 0.24 m box (11.1 N) turned at 12.5 N; with
# K_t doubled along the face (16.7 N) and with crowns of 0.12 m radius (no buckling) the
# 14.6 N grasp held.


def buckling_squeeze_n(half_width_m: float, crown_radius_m: float, stiffness_n_per_m: float) -> float:
    """N_cr = K a^2 / (a - R) [N] (above); inf when the crown's radius is at least a."""
    a, R = half_width_m, crown_radius_m
    return math.inf if a <= R else stiffness_n_per_m * a * a / (a - R)


def pad_side_stiffness_n_per_m(vehicle: VehicleParams, model: AmModel) -> float:
    """K of the buckling criterion: the CoM's stiffness along the face (K_t's horizontal part,
    the smaller) in series with the heading's at the pad, L^2 / k_psi, k_psi the law's yaw
    stiffness (Lambda_w Lambda_wb,d^-1 k_R about the body z axis) at q_nominal, level, and L
    the pad's horizontal distance from the CoM there."""
    g = vehicle.gains
    q = np.array(vehicle.q_nominal_rad, dtype=float)
    state = AmState(p_WB=np.zeros(3), R_WB=np.eye(3), v_B=np.zeros(3), w_B=np.zeros(3), q=q, qdot=np.zeros_like(q))
    Lambda_w = decoupled_terms(model, create_data(model), state).Lambda_w
    k_psi = float((Lambda_w @ np.diag(1.0 / np.asarray(g.Lambda_wb_d, dtype=float)))[2, 2]) * g.k_R
    d = nominal_geometry(model)
    lever = float(np.hypot(*(d.p_BE - d.r_BC)[:2]))
    return 1.0 / (1.0 / min(g.K_t[0], g.K_t[1]) + lever * lever / k_psi)
