"""Review of a recorded run: per-phase summary of the paper's quantities (pure, numpy).

    log = mcap_io.read_log(path); run = load_run(log); summary = summarize(log)

Phases (approach, grasp, hover) come from the simulator's run_start event (the scenario's
phase ends); without it, from the phase labels of the controller samples. Per phase and
AM: final and max CoM error |r~_c| [m], attitude error |e_R| [rad], task error y~
(per component), pad-object contact force (ground truth) and the F/T force in E. Per
phase: object lift above its first recorded height [m]. In hover: each end-effector's
slip relative to the object, |p_OE(t) - p_OE(t_hover_start)| with p_OE = R_WO^T (p_WE - p_WO).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np

from amcore.so3 import quats_wxyz_to_R

from . import contract as c
from .mcap_io import LogData


class NoDataError(ValueError):
    """The log holds nothing to review."""


@dataclass
class AmSeries:
    sysid: int
    t: np.ndarray = field(default_factory=lambda: np.zeros(0))  # controller samples [s]
    phase: list[str] = field(default_factory=list)
    r_c_err: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    e_R: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    y_err: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    q_WB: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    q_WB_d: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    wrench_E: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    t_contact: np.ndarray = field(default_factory=lambda: np.zeros(0))
    normal_n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    tangential_W: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    t_tf: np.ndarray = field(default_factory=lambda: np.zeros(0))
    p_WE: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass
class RunData:
    ams: dict[int, AmSeries]
    t_obj: np.ndarray
    p_WO: np.ndarray
    q_WO: np.ndarray
    phase_ends_s: tuple[float, float, float] | None
    phase_source: str
    run_start: dict | None
    t_first: float
    t_last: float


def _arr(rows: list, width: int | None = None) -> np.ndarray:
    if not rows:
        return np.zeros((0, width or 0))
    return np.array(rows, dtype=float)


def load_run(log: LogData) -> RunData:
    """Arrays of everything the review and the plots use."""
    ams: dict[int, AmSeries] = {}

    def am(sysid: int) -> AmSeries:
        return ams.setdefault(sysid, AmSeries(sysid))

    for topic in log.topics("/am/", "/controller"):
        msgs = [p for _, p in log.decoded(topic)]
        s = am(int(topic.split("/")[2]))
        s.t = _arr([p["t"] for p in msgs])
        s.phase = [p["phase"] for p in msgs]
        for name in ("r_c_err", "e_R", "y_err", "q_WB", "q_WB_d", "wrench_E"):
            setattr(s, name, _arr([p[name] for p in msgs], len(msgs[0][name]) if msgs else 0))
    for topic in log.topics("/sim/am/", "/contact"):
        msgs = [p for _, p in log.decoded(topic)]
        s = am(int(topic.split("/")[3]))
        s.t_contact = _arr([p["t"] for p in msgs])
        s.normal_n = _arr([p["normal_force_n"] for p in msgs])
        s.tangential_W = _arr([p["tangential_force_W"] for p in msgs], 3)
    tf: dict[int, list] = {}
    for t, m in log.protobuf(c.TF_TOPIC):  # foxglove.FrameTransforms
        for tr in m.transforms:
            child = tr.child_frame_id
            if child.endswith("/ee") and child.startswith("am"):
                v = tr.translation
                tf.setdefault(int(child[2:-3]), []).append((t, v.x, v.y, v.z))
    for sysid, rows in tf.items():
        a = np.array(rows)
        am(sysid).t_tf, am(sysid).p_WE = a[:, 0], a[:, 1:4]
    obj = log.protobuf(c.OBJECT_POSE_TOPIC)  # foxglove.PoseInFrame
    t_obj = _arr([t for t, _ in obj])
    p_WO = _arr([[m.pose.position.x, m.pose.position.y, m.pose.position.z] for _, m in obj], 3)
    q_WO = _arr([[m.pose.orientation.w, m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z]
                 for _, m in obj], 4)

    run_start = None
    for _, e in log.decoded(c.SIM_EVENT_TOPIC):
        if e.get("kind") == "run_start":
            run_start = e.get("data")
    if run_start is None and "run_start" in log.metadata:
        run_start = json.loads(log.metadata["run_start"]["json"]).get("data")
    ends, source = None, "none"
    if run_start and "phase_ends_s" in run_start:
        ends, source = tuple(float(x) for x in run_start["phase_ends_s"]), "run_start"
    else:
        ends, source = _phase_ends_from_labels(ams.values())
    times = [x for s in ams.values() for x in (s.t, s.t_contact, s.t_tf) if len(x)] + ([t_obj] if len(t_obj) else [])
    if not times:
        raise NoDataError(f"{log.path}: no controller, contact, pose or object messages"
                          + (" (truncated before the first complete chunk)" if log.truncated else ""))
    return RunData(ams=dict(sorted(ams.items())), t_obj=t_obj, p_WO=p_WO, q_WO=q_WO, phase_ends_s=ends,
                   phase_source=source, run_start=run_start, t_first=min(float(x[0]) for x in times),
                   t_last=max(float(x[-1]) for x in times))


def _phase_ends_from_labels(series) -> tuple[tuple[float, float, float] | None, str]:
    first: dict[str, float] = {}
    last = 0.0
    for s in series:
        for t, ph in zip(s.t, s.phase):
            first[ph] = min(first.get(ph, np.inf), float(t))
            last = max(last, float(t))
    if not first:
        return None, "none"
    a = first.get("grasp", first.get("hover", np.inf))
    g = first.get("hover", np.inf)
    return (a, g, max(last, g) if np.isfinite(g) else np.inf), "controller"


def phase_windows(run: RunData) -> dict[str, tuple[float, float]]:
    """[start, end) of each phase that the log covers, in simulation time [s]."""
    if run.phase_ends_s is None:
        return {"all": (run.t_first, np.inf)}
    a, g, _ = run.phase_ends_s
    bounds = {"approach": (0.0, a), "grasp": (a, g), "hover": (g, np.inf)}
    return {k: v for k, v in bounds.items() if v[0] <= run.t_last and v[1] > run.t_first}


def _mask(t: np.ndarray, w: tuple[float, float]) -> np.ndarray:
    return (t >= w[0]) & (t < w[1])


def _final_max(x: np.ndarray) -> dict | None:
    if len(x) == 0:
        return None
    return {"final": float(x[-1]), "max": float(np.max(x))}


def nearest_index(t_ref: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index into the sorted t_ref of the sample nearest to each t."""
    j = np.clip(np.searchsorted(t_ref, t), 0, len(t_ref) - 1)
    prev = np.maximum(j - 1, 0)
    return np.where(np.abs(t_ref[prev] - t) < np.abs(t_ref[j] - t), prev, j)


def ee_in_object(run: RunData, s: AmSeries) -> tuple[np.ndarray, np.ndarray]:
    """(t, p_OE (N,3)): end-effector position in the object frame, at the /tf times,
    using the object sample of the same (nearest) simulation time."""
    if len(s.t_tf) == 0 or len(run.t_obj) == 0:
        return np.zeros(0), np.zeros((0, 3))
    i = nearest_index(run.t_obj, s.t_tf)
    R = quats_wxyz_to_R(run.q_WO[i])
    return s.t_tf, np.einsum("nji,nj->ni", R, s.p_WE - run.p_WO[i])


def summarize(log: LogData, run: RunData | None = None) -> dict:
    """The review as a JSON-ready dict (see the module docstring)."""
    run = run if run is not None else load_run(log)
    windows = phase_windows(run)
    z0 = float(run.p_WO[0, 2]) if len(run.p_WO) else None
    phases = {}
    for name, w in windows.items():
        ams = {}
        for sysid, s in run.ams.items():
            m, mc = _mask(s.t, w), _mask(s.t_contact, w)
            y = s.y_err[m]
            ams[str(sysid)] = {
                "samples": int(m.sum()),
                "com_err_m": _final_max(np.linalg.norm(s.r_c_err[m], axis=1)),
                "e_R_rad": _final_max(np.linalg.norm(s.e_R[m], axis=1)),
                "task_err": None if len(y) == 0 else {"final": y[-1].tolist(), "max_abs": np.abs(y).max(0).tolist()},
                "ft_force_E_n": None if not m.any() else {"final": s.wrench_E[m][-1, :3].tolist()},
                "contact_normal_n": None if not mc.any() else {
                    "final": float(s.normal_n[mc][-1]), "mean": float(s.normal_n[mc].mean()),
                    "max": float(s.normal_n[mc].max())},
                "contact_tangential_n": _final_max(np.linalg.norm(s.tangential_W[mc], axis=1)),
            }
        entry = {"window_s": [w[0], min(w[1], run.t_last)], "ams": ams}
        mo = _mask(run.t_obj, w)
        entry["object_lift_m"] = _final_max(run.p_WO[mo, 2] - z0) if z0 is not None else None
        if name == "hover":
            slip = {}
            for sysid, s in run.ams.items():
                t, p = ee_in_object(run, s)
                mh = _mask(t, w)
                if mh.any():
                    slip[str(sysid)] = _final_max(np.linalg.norm(p[mh] - p[mh][0], axis=1))
            entry["ee_slip_m"] = slip
        phases[name] = entry
    stats = log.decoded(c.STATS_TOPIC)
    last_stats = stats[-1][1] if stats else None
    return {
        "log": {"path": str(log.path), "salvaged": log.truncated, "truncated_reason": log.error if log.truncated else "",
                "complete_chunks": log.chunks, "messages": log.message_count, "topics": len(log.messages),
                "sim_time_s": [run.t_first, run.t_last]},
        "scenario": run.run_start,
        "phase_ends_s": list(run.phase_ends_s) if run.phase_ends_s else None,
        "phase_source": run.phase_source,
        "ams": sorted(run.ams),
        "object_start_z_m": z0,
        "loss": None if last_stats is None else {
            "missing": sum(k["missing"] for k in last_stats["keys"].values()),
            "inbox_overflow": last_stats["inbox_overflow"], "malformed": last_stats["malformed"],
            "rejected": last_stats.get("rejected", 0),  # unauthenticated samples, dropped (telemetry.auth)
            "per_key_missing": {k: v["missing"] for k, v in last_stats["keys"].items() if v["missing"]},
            "as_of_sim_time_s": last_stats["t"]},
        "phases": phases,
    }


def _f(x, unit: str = "", scale: float = 1.0, fmt: str = "{:.3g}") -> str:
    if x is None:
        return "-"
    if isinstance(x, list):
        return "[" + ", ".join(fmt.format(v * scale) for v in x) + "]" + unit
    return fmt.format(x * scale) + unit


def format_summary(s: dict) -> str:
    lg = s["log"]
    lines = [f"log {lg['path']}: {lg['messages']} messages on {lg['topics']} topics, "
             f"sim time {lg['sim_time_s'][0]:.3f}..{lg['sim_time_s'][1]:.3f} s"]
    if lg["salvaged"]:
        lines.append(f"SALVAGED: the file was not finished ({lg['truncated_reason']}); "
                     f"read {lg['complete_chunks']} complete chunks, the rest is lost")
    if s["loss"] is not None:
        lines.append(f"lost in transit: {s['loss']['missing']} (seq gaps and publishers' final counts), "
                     f"inbox overflow {s['loss']['inbox_overflow']}")
        if s["loss"]["rejected"]:
            lines.append(f"REJECTED: {s['loss']['rejected']} unauthenticated samples (forged, or not of this run) "
                         f"were dropped, not recorded")
    lines.append(f"phases from {s['phase_source']}: ends {s['phase_ends_s']}")
    for name, p in s["phases"].items():
        lines.append(f"\n== {name} {p['window_s'][0]:.2f}..{p['window_s'][1]:.2f} s: object lift "
                     f"final {_f((p['object_lift_m'] or {}).get('final'), ' mm', 1e3)}, "
                     f"max {_f((p['object_lift_m'] or {}).get('max'), ' mm', 1e3)}")
        lines.append(f"  {'AM':>4} {'|r~c| fin/max [mm]':>20} {'|e_R| fin/max [mrad]':>22} {'y~ final':>28} "
                     f"{'N fin/mean/max [N]':>22} {'|T| fin/max [N]':>16} {'F/T f_E final [N]':>24}")
        for sysid, a in p["ams"].items():
            ce, er = a["com_err_m"] or {}, a["e_R_rad"] or {}
            cn, ct = a["contact_normal_n"] or {}, a["contact_tangential_n"] or {}
            lines.append(
                f"  {sysid:>4} {_f(ce.get('final'), '', 1e3)+' / '+_f(ce.get('max'), '', 1e3):>20} "
                f"{_f(er.get('final'), '', 1e3)+' / '+_f(er.get('max'), '', 1e3):>22} "
                f"{_f((a['task_err'] or {}).get('final')):>28} "
                f"{_f(cn.get('final'))+' / '+_f(cn.get('mean'))+' / '+_f(cn.get('max')):>22} "
                f"{_f(ct.get('final'))+' / '+_f(ct.get('max')):>16} {_f((a['ft_force_E_n'] or {}).get('final')):>24}")
        if "ee_slip_m" in p:
            slips = [f"am{k} final {_f(v['final'], ' mm', 1e3)} max {_f(v['max'], ' mm', 1e3)}"
                     for k, v in p["ee_slip_m"].items()]
            lines.append("  ee slip on the object: " + ", ".join(slips))
    return "\n".join(lines)
