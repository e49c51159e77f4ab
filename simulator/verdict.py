"""The mission verdict: did the team grasp, lift and hold the object? (pure: numpy only)

Judged from the simulator's ground truth (`simulator.outcome.RunOutcome`) against the
scenario's [success] criteria (`amcore.config.SuccessCriteria`), never from what the
controllers believe. Every criterion the run misses becomes a `Failure` with its class,
the time it failed and a sentence saying by how much; the verdict's class is the first
in `FAILURE_CLASSES` order (the most fundamental): a base that crashed into the table
usually also dropped the object, and the crash is what a user needs to hear about.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from amcore.config import SuccessCriteria

from .outcome import RunOutcome

MISSION_FAILED = 4  # exit code of every runner (simulator, am-run, in-process) whose mission failed

# "commanded" first: a GCS that aborted the mission, landed a vehicle or disarmed it in flight
# decided the run's end, and what followed (the object dropped, a base on the ground) follows
# from it. "rejected setpoints" before "failsafe": K refused setpoints in a row send a vehicle
# to its failsafe (amcore.config.FlightControllerParams), and the refusals are then the cause
FAILURE_CLASSES = ("commanded", "failover", "diverged", "base contact", "never lifted", "dropped", "slipped", "rejected setpoints",
                   "failsafe", "saturated")


@dataclass(frozen=True)
class Failure:
    kind: str  # one of FAILURE_CLASSES
    t_s: float | None  # when the criterion was first missed [s]
    reason: str


@dataclass(frozen=True)
class Verdict:
    """failures: every criterion missed, most fundamental first; incomplete: why the run
    could not be judged whole (it ended before the hover window did), or "" if it could.

    status: "success" (judged whole, nothing missed), "failed" (something missed, however
    far the run got) or "incomplete" (nothing missed so far)."""

    failures: tuple[Failure, ...]
    incomplete: str = ""

    @property
    def status(self) -> str:
        return "failed" if self.failures else ("incomplete" if self.incomplete else "success")

    @property
    def success(self) -> bool:
        return self.status == "success"

    @property
    def failure_class(self) -> str | None:
        return self.failures[0].kind if self.failures else None

    @property
    def text(self) -> str:
        if self.failures:
            return "mission FAILED: " + "; ".join(f.reason for f in self.failures)
        if self.incomplete:
            return f"mission incomplete: {self.incomplete}; nothing failed so far"
        return "mission success"

    def to_dict(self) -> dict:
        return {"status": self.status, "success": self.success, "failure_class": self.failure_class,
                "text": self.text, "incomplete": self.incomplete,
                "failures": [{"class": f.kind, "t_s": f.t_s, "reason": f.reason} for f in self.failures]}


def judge(outcome: RunOutcome, criteria: SuccessCriteria, n_steps: int, failsafe_at_end: Iterable[int] = (),
          rejected: Iterable[tuple[float, int, str]] = (),
          controller_errors: Iterable[tuple[float, int, str]] = (),
          commanded: Iterable[tuple[float, int, str]] = (),
          failovers: Iterable[tuple[float, int, str, float | None]] = ()) -> Verdict:
    """The verdict of a finished run.

    n_steps: physics steps run (the saturation fraction's denominator); failsafe_at_end: sysids
    whose flight controller is in failsafe at the end; rejected: (t, sysid, why) of every
    setpoint the simulator refused as implausible; controller_errors: (t, sysid, what) of
    controllers that raised instead of answering (in-process runs); commanded: (t, sysid, what)
    of GCS commands that took a vehicle from its companion, what = "abort" (the mission abort,
    one entry per vehicle), "land" (NAV_LAND) or "disarm" (forced, in flight). A base that
    touches something after its own vehicle was commanded down is that landing, not a crash.
    failovers: (t, sysid, why, back_t) of a vehicle taken out of OFFBOARD in flight (free-running:
    a PX4 failsafe, or a mode another client asked for), back_t when a companion engaged it again
    (or None): the mission was not flown by its companions throughout."""
    commanded = sorted(commanded)
    down_at: dict[int, float] = {}
    for t, s, _ in commanded:
        down_at.setdefault(s, t)
    found: dict[str, Failure] = {}
    w0, w1 = outcome.hover_window
    complete = bool(outcome.t_series) and outcome.t_series[-1] >= w1 - 1e-9
    for f in (*_commanded(commanded), *_failover(failovers), *_diverged(outcome, criteria, controller_errors), *_base_contact(outcome, down_at),
              *_lift(outcome, criteria, complete), *_slip(outcome, criteria), *_failsafe(failsafe_at_end),
              *_rejected(rejected), *_saturation(outcome, criteria, n_steps)):
        found.setdefault(f.kind, f)
    incomplete = "" if complete else (f"the run ended at t = {outcome.t_last:.2f} s, before the end of the hover "
                                      f"window ({w0:g}-{w1:g} s)")
    return Verdict(tuple(found[k] for k in FAILURE_CLASSES if k in found), incomplete)


def _diverged(o: RunOutcome, c: SuccessCriteria, errors) -> list[Failure]:
    out = [Failure("diverged", t, f"am{s}'s controller failed at t = {t:.2f} s: {what}") for t, s, what in errors]
    d = np.asarray(o.base_distance_series)
    bad = np.flatnonzero(~(d <= c.max_distance_m))
    if bad.size:
        i = int(bad[0])
        t = o.t_series[i]
        what = "a state turned non-finite" if not np.isfinite(d[i]) else \
            f"a base {d[i]:.2f} m from the object's rest position > {c.max_distance_m:g} m"
        out.append(Failure("diverged", t, f"diverged at t = {t:.2f} s ({what})"))
    return sorted(out, key=lambda f: f.t_s)[:1]


def _commanded(commanded: list[tuple[float, int, str]]) -> list[Failure]:
    if not commanded:
        return []
    t, s, what = commanded[0]
    if what == "abort":
        return [Failure("commanded", t, f"aborted by the GCS at t = {t:.2f} s")]
    others = {x for _, x, _ in commanded} - {s}
    more = f" (then am{', am'.join(map(str, sorted(others)))})" if others else ""
    done = "landed by the GCS" if what == "land" else "disarmed in flight by the GCS"
    return [Failure("commanded", t, f"am{s} {done} at t = {t:.2f} s{more}")]


def _failover(failovers: Iterable[tuple[float, int, str, float | None]]) -> list[Failure]:
    f = sorted(failovers, key=lambda x: x[0])
    if not f:
        return []
    t, s, why, back = f[0]
    again = f"; engaged again at t = {back:.2f} s" if back is not None else ""
    more = f" ({len(f)} in all)" if len(f) > 1 else ""
    return [Failure("failover", t, f"am{s} left OFFBOARD at t = {t:.2f} s ({why}){again}{more}")]


def _base_contact(o: RunOutcome, down_at: Mapping[int, float]) -> list[Failure]:
    hits = [(a.first_base_contact, s) for s, a in o.ams.items()
            if a.first_base_contact is not None and a.first_base_contact[0] < down_at.get(s, float("inf"))]
    if not hits:
        return []
    (t, names), s = min(hits, key=lambda h: h[0][0])
    more = f" ({len(hits)} AMs in all)" if len(hits) > 1 else ""
    return [Failure("base contact", t, f"base of am{s} touched {', '.join(names)} at t = {t:.2f} s{more}")]


def _lift(o: RunOutcome, c: SuccessCriteria, complete: bool) -> list[Failure]:
    """Up and off the table throughout the hover window. A run that ended before the window
    did is judged only on what it shows: an object that was up and came down."""
    t = np.asarray(o.t_series)
    lift = np.asarray(o.lift_series)
    support = np.asarray(o.on_support_series, dtype=bool)
    w0, w1 = o.hover_window
    hover = (t >= w0) & (t <= w1)
    ok = (lift >= c.min_lift_m) & ~support
    if not complete:
        if not ok.any():
            return []
        first_up = int(np.flatnonzero(ok)[0])
        down = np.flatnonzero(~ok[first_up:])
        if not down.size:
            return []
        td = float(t[first_up + int(down[0])])
        return [Failure("dropped", td, f"dropped at t = {td:.2f} s")]
    if ok[hover].all():
        return []
    peak = float(lift.max())
    if peak < c.min_lift_m:
        return [Failure("never lifted", w0, f"object never lifted to {c.min_lift_m * 100:.0f} cm (max "
                                            f"{peak * 100:.1f} cm; {lift[hover].mean() * 100:.1f} cm at "
                                            f"t = {w0:g}-{w1:g} s)")]
    if not ok.any():
        return [Failure("never lifted", w0, f"object never up and off the table (max {peak * 100:.1f} cm, always "
                                            f"touching the table or ground)")]
    first_up = int(np.flatnonzero(ok)[0])
    down = np.flatnonzero(~ok[first_up:])
    if down.size:
        i = first_up + int(down[0])
        td = float(t[i])
        if hover[i] or td < w0:
            where = "on the table or ground" if support[i:].any() else f"{lift[-1] * 100:.1f} cm up"
            return [Failure("dropped", td, f"dropped at t = {td:.2f} s (the object ends {where})")]
    tl = float(t[first_up])
    return [Failure("never lifted", tl, f"object reached {c.min_lift_m * 100:.0f} cm only at t = {tl:.2f} s, "
                                        f"after the hover window began ({w0:g} s)")]


def _slip(o: RunOutcome, c: SuccessCriteria) -> list[Failure]:
    worst = None
    for s, a in o.ams.items():
        if a.slip_max > c.max_slip_m:
            i = next(i for i, x in enumerate(a.slip_series) if x > c.max_slip_m)
            t = o.slip_t_series[i] if i < len(o.slip_t_series) else o.t_last
            if worst is None or a.slip_max > worst[0]:
                worst = (a.slip_max, s, t)
    if worst is None:
        return []
    slip, s, t = worst
    return [Failure("slipped", t, f"slip {slip * 1e3:.0f} mm > {c.max_slip_m * 1e3:g} mm (am{s}'s pad, "
                                  f"beyond the limit from t = {t:.2f} s)")]


def _failsafe(sysids: Iterable[int]) -> list[Failure]:
    s = sorted(sysids)
    if not s:
        return []
    return [Failure("failsafe", None, f"sysid {', '.join(map(str, s))} in failsafe at the end")]


def _rejected(rejected: Iterable[tuple[float, int, str]]) -> list[Failure]:
    r = list(rejected)
    if not r:
        return []
    t, s, why = r[0]
    return [Failure("rejected setpoints", t, f"{len(r)} setpoint(s) rejected as implausible (first: am{s} at "
                                             f"t = {t:.3f} s: {why})")]


def _saturation(o: RunOutcome, c: SuccessCriteria, n_steps: int) -> list[Failure]:
    if n_steps <= 0:
        return []
    worst = max(o.ams.items(), key=lambda sa: sa[1].saturated_steps)
    s, a = worst
    frac = a.saturated_steps / n_steps
    if frac <= c.max_saturated_fraction:
        return []
    return [Failure("saturated", a.first_saturation_s, f"am{s}'s actuators saturated on {frac * 100:.1f} % of the "
                                                       f"steps > {c.max_saturated_fraction * 100:g} % (first at "
                                                       f"t = {a.first_saturation_s:.2f} s)")]


def summary_figures(result: Mapping, share_n: float) -> dict:
    """The key figures of a finished run's outcome dict (`SitlCore.finish`) for one table
    row: lift, slip, saturation and the worst force-share error of the wrist sensors."""
    obj, ams = result["object"], result["ams"]
    up = [-a["hover_mean_ft_force_W_n"][2] for a in ams.values()]
    return {
        "hover_min_lift_m": obj["hover_min_lift_m"],
        "max_lift_m": obj["max_lift_m"],
        "final_lift_m": obj["final_lift_m"],
        "max_slip_m": max(a["slip_max_m"] for a in ams.values()),
        "saturated_steps": sum(a["saturated_steps"] for a in ams.values()),
        "rotor_saturated_steps": sum(a.get("rotor_saturated_steps", 0) for a in ams.values()),
        "joint_saturated_steps": sum(a.get("joint_saturated_steps", 0) for a in ams.values()),
        "force_share_error": max(abs(u - share_n) / share_n for u in up) if share_n > 0 else None,
    }


@dataclass(frozen=True)
class CriterionRow:
    """One [success] criterion beside the run's figure, for the end-of-run summary: what is
    measured, the limit and the figure as text with their units, and whether it was met (None
    when the outcome holds no figure for it)."""

    what: str
    limit: str
    figure: str
    met: bool | None


def criteria_rows(result: Mapping, criteria: SuccessCriteria) -> list[CriterionRow]:
    """Each success criterion of `criteria` beside its figure in a finished run's outcome dict
    (outcome.json: `SitlCore.finish` with the simulator's "steps"), judged here from the figure
    itself. A base leaving the arena has no figure in the outcome dict; its row is judged from the
    verdict's failure classes."""
    obj, ams = result.get("object", {}), result.get("ams", {})
    rows = []
    hl = obj.get("hover_min_lift_m")
    touching = obj.get("touching_in_hover") or []
    lift_fig = "-" if hl is None else f"{hl * 100:.1f} cm" + (f", touching {', '.join(touching)}" if touching else "")
    rows.append(CriterionRow("object lift, lowest in the hover window", f">= {criteria.min_lift_m * 100:g} cm, "
                             "off the table", lift_fig, None if hl is None else hl >= criteria.min_lift_m and not touching))
    slip = max((a["slip_max_m"] for a in ams.values()), default=None)
    rows.append(CriterionRow("pad slip, worst pad", f"<= {criteria.max_slip_m * 1e3:g} mm",
                             "-" if slip is None else f"{slip * 1e3:.2f} mm",
                             None if slip is None else slip <= criteria.max_slip_m))
    steps = result.get("steps") or 0
    if steps and ams:
        frac = max(a["saturated_steps"] for a in ams.values()) / steps
        rows.append(CriterionRow("actuator saturation, worst AM", f"<= {criteria.max_saturated_fraction * 100:g} % "
                                 "of steps", f"{frac * 100:.2f} %", frac <= criteria.max_saturated_fraction))
    hits = sorted(f"am{s}" for s, a in ams.items() if a.get("base_contacts"))
    rows.append(CriterionRow("base contact", "none", ", ".join(hits) or "none", None if not ams else not hits))
    classes = {f["class"] for f in result.get("verdict", {}).get("failures", [])}
    rows.append(CriterionRow("bases near the object, states finite", f"<= {criteria.max_distance_m:g} m away",
                             "diverged" if "diverged" in classes else "yes",
                             None if "verdict" not in result else "diverged" not in classes))
    fs = result.get("failsafe_at_end")
    rows.append(CriterionRow("vehicles in failsafe at the end", "none",
                             "-" if fs is None else (", ".join(f"sysid {s}" for s in fs) or "none"),
                             None if fs is None else not fs))
    rej = result.get("rejected_setpoints")
    rows.append(CriterionRow("setpoints rejected as implausible", "0", "-" if rej is None else str(rej),
                             None if rej is None else rej == 0))
    return rows


def format_criteria(rows: list[CriterionRow]) -> str:
    """`criteria_rows` as aligned text lines: criterion, limit, figure, ok / MISSED."""
    mark = {True: "ok", False: "MISSED", None: "-"}
    table = [("criterion", "limit", "this run", ""), *((r.what, r.limit, r.figure, mark[r.met]) for r in rows)]
    w = [max(len(t[i]) for t in table) for i in range(3)]
    return "\n".join(f"  {a:<{w[0]}}  {b:<{w[1]}}  {c:<{w[2]}}  {d}".rstrip() for a, b, c, d in table)
