"""The pre-flight envelope check: can this team hold the object it is asked to lift? (pure:
numpy and pinocchio through amcore.envelope, no I/O)

From the scenario alone, before anything flies: the vehicle's authority (amcore.envelope's
loaded hover), the team's size n, the object's design mass m (the planned mass over
1 - [mission].mass_tolerance, `amcore.config.design_mass_kg`) and the lowest pad friction
planned for, mu = [mission].friction_assumed, with [mission].friction_margin:

    N_req = friction_margin * m g / (n mu)             the squeeze each pad needs
    N_plan                                             what the mission squeezes (amcore.mission.squeeze_for:
                                                       the sizing's caps, [mission].squeeze_max_n among them)
    N_max(m / n)                                       the most an AM pushes carrying its share m / n with
                                                       its margins kept (amcore.envelope.Envelope.capacity_n)

    N_cr                                               the squeeze above which a box hanging between two
                                                       crowned pads buckles out of them by turning about the
                                                       vertical (amcore.envelope.buckling_squeeze_n, the
                                                       smallest over the faces the AMs grasp; inf otherwise)

The team holds the object when N_req <= N_plan <= N_max(m / n) and N_plan <= N_cr / margin:
the planned squeeze is enough, each AM can push it while it carries its share, and it does
not buckle the grasp. Otherwise the check names the
limit (the scenario's squeeze cap, the rotors' thrust, or the envelope's margin that breaks)
and the smallest team of these AMs that would hold it.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from .config import ConfigError, ScenarioSpec, VehicleParams, design_mass_kg, grasped_face
from .envelope import Envelope, Margins, buckling_squeeze_n
from .mission import squeeze_for
from .model import build_model

TEAM_MOST = 32  # the largest team the check proposes


@dataclass(frozen=True)
class TeamCheck:
    """One team size against the object: squeezes per pad [N] and whether it holds."""

    n_ams: int
    required_n: float  # N_req
    planned_n: float  # N_plan
    capacity_n: float  # N_max at the share
    limit: str  # what caps the squeeze (empty when the team holds)
    buckling_n: float = math.inf  # N_cr / the margin: the most squeeze the grasp takes without buckling

    @property
    def holds(self) -> bool:
        return (self.required_n <= self.planned_n + 1e-9 and self.planned_n <= self.capacity_n
                and self.planned_n <= self.buckling_n)


@dataclass(frozen=True)
class Preflight:
    """The check's answer for one scenario."""

    design_mass_kg: float
    friction: float
    team: TeamCheck
    smallest_team: int | None  # the fewest AMs that hold the object (None: no team up to TEAM_MOST)
    message: str

    @property
    def inside(self) -> bool:
        return self.team.holds


@functools.lru_cache(maxsize=8)
def _envelope(vehicle: VehicleParams, thrust_fraction_max: float) -> Envelope:
    """One Envelope per vehicle and rotor margin in a process (its capacities are cached per share)."""
    return Envelope(vehicle, Margins(thrust_fraction_max=thrust_fraction_max), build_model(vehicle))


def team_check(spec: ScenarioSpec, n: int, env: Envelope | None = None) -> TeamCheck:
    """The scenario's object and plan, held by n of its AMs."""
    ms, v = spec.mission, spec.vehicle
    env = env or _envelope(v, ms.thrust_fraction_max)
    m = design_mass_kg(spec)
    plan = squeeze_for(ms, v, env.model.mass_kg, m, n)
    share = m / n
    cap = env.capacity_n(share)
    limit = ""
    if plan.force_n < plan.required_n:
        limit = (f"[mission].squeeze_max_n = {ms.squeeze_max_n:g} N" if plan.feasible_n == ms.squeeze_max_n else
                 f"its thrust within {ms.thrust_fraction_max:.0%} of its maximum" if ms.squeeze_sizing else
                 f"the fixed squeeze ([mission].squeeze_sizing = false)")
    elif plan.force_n > cap:
        limit = env.broken_margin(plan.force_n, share) or "its margins"
    buckle, why = _buckling(spec, env)
    if not limit and plan.force_n > buckle:
        limit = why
    return TeamCheck(n, plan.required_n, plan.force_n, cap, limit, buckle)


def _buckling(spec: ScenarioSpec, env: Envelope) -> tuple[float, str]:
    """N_cr / margin over the faces the scenario's AMs grasp [N] (inf but for a box between
    crowned pads), and the limit in words."""
    obj, pad = spec.object, spec.vehicle.pad
    if obj.shape != "box" or pad.shape != "crowned":
        return math.inf, ""
    halves = {grasped_face(spec, am)[1] for am in spec.ams}
    K = env.pad_side_stiffness_n_per_m
    a, n_cr = min(((h, buckling_squeeze_n(h, pad.crown_radius_m, K)) for h in halves), key=lambda x: x[1])
    margin = env.margins.buckling_margin
    if math.isinf(n_cr):
        return math.inf, ""
    return n_cr / margin, (f"the grasp buckles: a box face {a:.3f} m from its axis between crowns of "
                           f"{pad.crown_radius_m:g} m radius turns out of the pads above {n_cr:.1f} N "
                           f"(side stiffness {K:.0f} N/m), and {n_cr / margin:.1f} N keeps the margin "
                           f"{margin:g}; crowns of radius {a:.2f} m or more do not buckle")


def preflight(spec: ScenarioSpec) -> Preflight:
    """The envelope check of `spec` (module docstring), with the sentence a user reads."""
    ms = spec.mission
    env = _envelope(spec.vehicle, ms.thrust_fraction_max)
    n = len(spec.ams)
    mine = team_check(spec, n, env)
    m = design_mass_kg(spec)
    planned = ms.planned_mass_kg if ms.planned_mass_kg > 0.0 else spec.object.mass_kg
    what = (f"{m:.2f} kg (planned {planned:.2f} kg, known to +/-{ms.mass_tolerance:.0%})" if ms.mass_tolerance > 0.0
            else f"{m:.2f} kg")
    head = f"{what} at friction {ms.friction_assumed:g} (margin {ms.friction_margin:g})"
    smallest = n if mine.holds else next((k for k in range(1, TEAM_MOST + 1) if team_check(spec, k, env).holds), None)
    if mine.holds:
        message = (f"{head} needs {mine.required_n:.1f} N per pad from {n} AMs; each squeezes {mine.planned_n:.1f} N "
                   f"and can push {mine.capacity_n:.1f} N carrying its {m / n:.2f} kg share: inside the envelope")
    else:
        holds = (f"this team of {n} holds {mine.planned_n:.1f} N per pad ({mine.limit})"
                 if mine.planned_n < mine.required_n or mine.planned_n > mine.buckling_n else
                 f"each AM of this team of {n} can push {mine.capacity_n:.1f} N per pad carrying its {m / n:.2f} kg "
                 f"share ({mine.limit})")
        if smallest is None:
            use = f"no team of up to {TEAM_MOST} of these AMs holds it"
            head = f"{head} needs {mine.required_n:.1f} N per pad from {n} AMs"
        else:
            use = f"use {smallest} AMs"
            need = team_check(spec, smallest, env).required_n
            head = f"{head} needs {need:.1f} N per pad from {smallest} AMs and {mine.required_n:.1f} N from {n}"
        message = f"{head}; {holds}: {use}"
    return Preflight(m, ms.friction_assumed, mine, smallest, message)


def refusal(spec: ScenarioSpec) -> str | None:
    """The refusal a runner prints before flight (exit 2) when [mission].envelope_check is on and
    the object is outside the team's envelope; None otherwise (and always with the check off)."""
    if not spec.mission.envelope_check:
        return None
    p = preflight(spec)
    return None if p.inside else f"{spec.path}: outside the team's envelope: {p.message}"


def check(spec: ScenarioSpec) -> None:
    """Raise ConfigError with `refusal`'s sentence when the team refuses the scenario (runners
    exit 2 on it, before anything flies)."""
    why = refusal(spec)
    if why is not None:
        raise ConfigError(why)
