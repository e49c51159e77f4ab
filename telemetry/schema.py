"""The telemetry wire contract: Zenoh key expressions and JSON payloads, defined once.

Pure: imports no zenoh, no simulator. Every process that publishes or records imports it.

Keys (prefix configurable, default "amstack"):

    <p>/am/<sysid>/controller      companion, every control step     CONTROLLER_SCHEMA
    <p>/am/<sysid>/event           companion: faults, notes           EVENT_SCHEMA
    <p>/sim/am/<sysid>/truth       simulator: base and ee poses       AM_TRUTH_SCHEMA
    <p>/sim/am/<sysid>/contact     simulator: pad-object contact      CONTACT_SCHEMA
    <p>/sim/object                 simulator: object pose, twist      OBJECT_SCHEMA
    <p>/sim/event                  simulator: run start/end, phases   EVENT_SCHEMA
    <p>/telemetry/<name>           every publisher, 1 Hz and at close PUBLISHER_SCHEMA
    <p>/batch/<name>               binary samples of several keys of publisher <name> in one
                                   message (telemetry.wire; the simulator's interleaved truth)

Every payload is one compact JSON object whose first two members are, in this order,
"t" (simulation time [s]) and "seq" (per-key counter, 0, 1, 2, ... assigned by the
publishing process: a gap is a lost message). Frames as in Drake's notation: p_WB is
B's origin in the world frame W (z up) [m]; quaternions are (w, x, y, z), unit, of the
rotation R_WX. Forces [N], torques [N m].
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from enum import Enum
from typing import Any, Iterator, Mapping

from amcore.so3 import R_to_quat_wxyz_shepperd

DEFAULT_PREFIX = "amstack"
PHASES = ("approach", "grasp", "hover")
EVENT_KINDS = ("run_start", "run_end", "phase", "fault", "info")
EVENT_LEVELS = ("debug", "info", "warning", "error", "fatal")


# ----------------------------------------------------------------------------- keys
class Channel(Enum):
    """What a key carries (the recorder maps each to MCAP topics)."""

    CONTROLLER = "controller"
    AM_EVENT = "am_event"
    AM_TRUTH = "am_truth"
    CONTACT = "contact"
    OBJECT = "object"
    SIM_EVENT = "sim_event"
    PUBLISHER = "publisher"


@dataclass(frozen=True)
class KeyMatch:
    channel: Channel
    sysid: int | None  # None for the simulator-wide keys
    name: str | None = None  # the publisher's name, for Channel.PUBLISHER


@dataclass(frozen=True)
class Keys:
    """Key expressions under one prefix (one deployment)."""

    prefix: str = DEFAULT_PREFIX

    def __post_init__(self):
        if not re.fullmatch(r"[A-Za-z0-9_\-.]+(/[A-Za-z0-9_\-.]+)*", self.prefix):
            raise ValueError(f"telemetry prefix {self.prefix!r} must be plain key chunks (no wildcards, no slash at the ends)")

    def controller(self, sysid: int) -> str:
        return f"{self.prefix}/am/{int(sysid)}/controller"

    def am_event(self, sysid: int) -> str:
        return f"{self.prefix}/am/{int(sysid)}/event"

    def am_truth(self, sysid: int) -> str:
        return f"{self.prefix}/sim/am/{int(sysid)}/truth"

    def contact(self, sysid: int) -> str:
        return f"{self.prefix}/sim/am/{int(sysid)}/contact"

    @property
    def object(self) -> str:
        return f"{self.prefix}/sim/object"

    @property
    def sim_event(self) -> str:
        return f"{self.prefix}/sim/event"

    def publisher(self, name: str) -> str:
        """A TelemetryPublisher's own accounting (name: one key chunk, e.g. 'am4', 'simulator')."""
        if not is_key_chunk(name):
            raise ValueError(f"publisher name {name!r} must be one plain key chunk")
        return f"{self.prefix}/telemetry/{name}"

    def batch(self, name: str) -> str:
        """Where publisher `name` puts binary samples of several of its keys as one message."""
        if not is_key_chunk(name):
            raise ValueError(f"publisher name {name!r} must be one plain key chunk")
        return f"{self.prefix}/batch/{name}"

    def batch_name(self, key: str) -> str | None:
        """The publisher of a batch key, or None if `key` is not one."""
        p = self.prefix + "/batch/"
        name = key[len(p):] if key.startswith(p) else ""
        return name if is_key_chunk(name) else None

    @property
    def everything(self) -> str:
        """The subscription that the recorder uses."""
        return f"{self.prefix}/**"

    def parse(self, key: str) -> KeyMatch | None:
        """Which channel a concrete key is, or None if it is not part of the contract."""
        p = self.prefix + "/"
        if not key.startswith(p):
            return None
        parts = key[len(p):].split("/")
        try:
            if len(parts) == 3 and parts[0] == "am" and parts[2] in ("controller", "event"):
                ch = Channel.CONTROLLER if parts[2] == "controller" else Channel.AM_EVENT
                return KeyMatch(ch, _sysid(parts[1]))
            if len(parts) == 4 and parts[:2] == ["sim", "am"] and parts[3] in ("truth", "contact"):
                return KeyMatch(Channel.AM_TRUTH if parts[3] == "truth" else Channel.CONTACT, _sysid(parts[2]))
        except ValueError:
            return None
        if parts == ["sim", "object"]:
            return KeyMatch(Channel.OBJECT, None)
        if parts == ["sim", "event"]:
            return KeyMatch(Channel.SIM_EVENT, None)
        if len(parts) == 2 and parts[0] == "telemetry" and is_key_chunk(parts[1]):
            return KeyMatch(Channel.PUBLISHER, None, parts[1])
        return None


def is_key_chunk(text: str) -> bool:
    return re.fullmatch(r"[A-Za-z0-9_\-.]+", text) is not None


def _sysid(text: str) -> int:
    if not text.isdigit():
        raise ValueError(text)
    return int(text)


# ----------------------------------------------------------------------------- JSON schemas
def _num() -> dict:
    return {"type": "number"}


def _vec(n: int | None = None, desc: str = "") -> dict:
    s: dict[str, Any] = {"type": "array", "items": {"type": "number"}}
    if n is not None:
        s["minItems"] = s["maxItems"] = n
    if desc:
        s["description"] = desc
    return s


def _object(title: str, description: str, props: dict, optional: tuple[str, ...] = ()) -> dict:
    head = {"t": {"type": "number", "minimum": 0, "description": "simulation time [s]"},
            "seq": {"type": "integer", "minimum": 0, "description": "per-key counter; gaps are lost messages"}}
    props = {**head, **props}
    return {"title": title, "description": description, "type": "object", "properties": props,
            "required": [k for k in props if k not in optional]}


CONTROLLER_SCHEMA = _object("amstack.ControllerState", "One control step of one AM (amcore.control.step)", {
    "sysid": {"type": "integer"},
    "phase": {"type": "string", "enum": list(PHASES)},
    "r_c": _vec(3, "CoM position in W [m]"),
    "r_c_d": _vec(3, "desired CoM position in W [m]"),
    "r_c_err": _vec(3, "r~_c = r_c - r_c,d [m]"),
    "e_R": _vec(3, "attitude error (eq. ori_error) [rad]"),
    "e_w": _vec(3, "angular velocity error (eq. ori_vel_error) [rad/s]"),
    "q_WB": _vec(4, "base attitude R_WB, quaternion (w, x, y, z)"),
    "q_WB_d": _vec(4, "desired attitude R_d (eq. Rd), quaternion (w, x, y, z)"),
    "y": _vec(None, "task variable y in the task frame"),
    "y_d": _vec(None, "desired task variable"),
    "y_err": _vec(None, "task error y~ = y - y_d"),
    "F_y": _vec(None, "external force in task space"),
    "f_W": _vec(3, "filtered end-effector force (F_rc) in W [N]"),
    "wrench_W": _vec(6, "filtered measured wrench [f; m] in W axes, moment about the end-effector [N, N m]"),
    "wrench_E": _vec(6, "filtered F/T reading [f; m] in the end-effector frame E [N, N m]"),
    "thrust_n": _num(),
    "tau_B_nm": _vec(3, "body torque [N m]"),
    "tau_q_nm": _vec(None, "joint torques [N m]"),
    "sigma_min_J3": _num(),
    "damping": _num(),
    "com_err_saturated": {"type": "boolean"},
    "y_err_saturated": {"type": "boolean"},
})

AM_TRUTH_SCHEMA = _object("amstack.AmTruth", "Ground-truth base and end-effector poses of one AM (simulator)", {
    "sysid": {"type": "integer"},
    "p_WB": _vec(3, "base (quadrotor CoM) position [m]"),
    "q_WB": _vec(4, "base attitude (w, x, y, z)"),
    "p_WE": _vec(3, "end-effector (pad face centre) position [m]"),
    "q_WE": _vec(4, "end-effector attitude (w, x, y, z); x = pad outward normal"),
    "p_W_joints": {"type": "array", "items": _vec(3, "joint origin [m]"),
                   "description": "arm joint origins from the base to the wrist [m] (optional)"},
    "rotor_saturated_steps": {"type": "integer", "minimum": 0,
                              "description": "commands so far whose rotor mix saturated (cumulative; optional)"},
    "joint_saturated_steps": {"type": "integer", "minimum": 0,
                              "description": "commands so far with a joint torque clipped (cumulative; optional)"},
    "axis_saturated_steps": {"type": "array", "items": {"type": "integer", "minimum": 0}, "minItems": 4,
                             "maxItems": 4, "description": "commands so far whose roll, pitch, yaw torque, thrust "
                                                           "fell short (cumulative; optional)"},
    "rotor_fraction_max": {"type": "number", "description": "the busiest rotor's thrust as a fraction of its range "
                                                            "(optional)"},
    "rotor_fraction_min": {"type": "number", "description": "the idlest rotor's (optional)"},
    "p_WB_est": _vec(3, "the base position the flight controller reports (its estimator's, with [devices]) [m]"),
    "q_WB_est": _vec(4, "its base attitude (w, x, y, z)"),
    "v_B_est": _vec(3, "its base velocity in B [m/s]"),
    "w_B_est": _vec(3, "its body rate [rad/s]"),
}, optional=("p_W_joints", "rotor_saturated_steps", "joint_saturated_steps", "axis_saturated_steps",
             "rotor_fraction_max", "rotor_fraction_min", "p_WB_est", "q_WB_est", "v_B_est", "w_B_est"))
ESTIMATE_FIELDS = {"p_WB_est": 3, "q_WB_est": 4, "v_B_est": 3, "w_B_est": 3}  # AmTruth.estimate, in order

CONTACT_SCHEMA = _object("amstack.PadContact", "Force the object applies on one AM's pad, ground truth", {
    "sysid": {"type": "integer"},
    "normal_force_n": {"type": "number", "minimum": 0},
    "normal_W": _vec(3, "unit normal from the object into the pad (zero-length if no contact)"),
    "tangential_force_W": _vec(3, "friction force on the pad [N]"),
    "point_W": _vec(3, "normal-force-weighted contact point [m]"),
    "n_points": {"type": "integer", "minimum": 0},
    "pad_other_contacts": {"type": "array", "items": {"type": "string"}},
    "base_contacts": {"type": "array", "items": {"type": "string"}},
})

OBJECT_SCHEMA = _object("amstack.ObjectTruth", "Ground-truth pose and twist of the grasped object", {
    "p_WO": _vec(3, "object CoM position [m]"),
    "q_WO": _vec(4, "object attitude (w, x, y, z)"),
    "v_WO": _vec(3, "linear velocity in W [m/s]"),
    "w_WO": _vec(3, "angular velocity in W [rad/s]"),
    "touching": {"type": "array", "items": {"type": "string"}},
})

EVENT_SCHEMA = _object("amstack.Event", "Run start/end, phase change, fault or note", {
    "source": {"type": "string", "description": "'simulator' or 'am<sysid>'"},
    "kind": {"type": "string", "enum": list(EVENT_KINDS)},
    "level": {"type": "string", "enum": list(EVENT_LEVELS)},
    "text": {"type": "string"},
    "data": {"type": "object", "description": "kind-specific: run_start carries the scenario"},
}, optional=("data",))

_COUNTER = {"type": "integer", "minimum": 0}
PUBLISHER_SCHEMA = _object("amstack.PublisherStats", "A telemetry publisher's own accounting (telemetry.publisher)", {
    "name": {"type": "string"},
    "final": {"type": "boolean", "description": "sent at close, after the queue was drained"},
    "seq_issued": {"type": "object", "description": "key -> seq numbers issued so far (sent or dropped)"},
    "published": _COUNTER, "sent": _COUNTER, "dropped_queue_full": _COUNTER, "dropped_no_session": _COUNTER,
    "dropped_at_close": _COUNTER, "encode_errors": _COUNTER, "send_errors": _COUNTER,
})

SCHEMAS: Mapping[Channel, dict] = {
    Channel.CONTROLLER: CONTROLLER_SCHEMA, Channel.AM_EVENT: EVENT_SCHEMA, Channel.AM_TRUTH: AM_TRUTH_SCHEMA,
    Channel.CONTACT: CONTACT_SCHEMA, Channel.OBJECT: OBJECT_SCHEMA, Channel.SIM_EVENT: EVENT_SCHEMA,
    Channel.PUBLISHER: PUBLISHER_SCHEMA,
}


# ----------------------------------------------------------------------------- builders
def _l(x) -> list:
    return x.tolist() if hasattr(x, "tolist") else [float(v) for v in x]


def controller_sample(t_s: float, phase: str, diag, cmd, seq: int = 0, sysid: int = 0) -> dict:
    """Payload of <p>/am/<sysid>/controller from amcore.control's Diagnostics and Command.

    `seq` is overwritten by TelemetryPublisher.publish (the publisher owns the counter)."""
    return {
        "t": float(t_s), "seq": int(seq), "sysid": int(sysid), "phase": phase,
        "r_c": _l(diag.r_c), "r_c_d": _l(diag.r_c_d), "r_c_err": _l(diag.r_c_err),
        "e_R": _l(diag.e_R), "e_w": _l(diag.e_w),
        "q_WB": R_to_quat_wxyz_shepperd(diag.R_WB), "q_WB_d": R_to_quat_wxyz_shepperd(diag.R_d),
        "y": _l(diag.y), "y_d": _l(diag.y_d), "y_err": _l(diag.y_err), "F_y": _l(diag.F_y),
        "f_W": _l(diag.F_rc), "wrench_W": _l(diag.wrench_W_filtered), "wrench_E": _l(diag.wrench_E_filtered),
        "thrust_n": float(cmd.thrust_n), "tau_B_nm": _l(cmd.tau_B_nm), "tau_q_nm": _l(cmd.tau_q_nm),
        "sigma_min_J3": float(diag.sigma_min_J3), "damping": float(diag.damping),
        "com_err_saturated": bool(diag.com_err_saturated), "y_err_saturated": bool(diag.y_err_saturated),
    }


def am_truth_sample(t_s: float, sysid: int, am, seq: int = 0) -> dict:
    """Payload of <p>/sim/am/<sysid>/truth from a simulator AmTruth (duck-typed:
    p_WB, R_WB, p_WE, R_WE)."""
    out = {"t": float(t_s), "seq": int(seq), "sysid": int(sysid),
           "p_WB": _l(am.p_WB), "q_WB": R_to_quat_wxyz_shepperd(am.R_WB), "p_WE": _l(am.p_WE), "q_WE": R_to_quat_wxyz_shepperd(am.R_WE)}
    joints = getattr(am, "p_W_joints", ())
    if len(joints):
        out["p_W_joints"] = [_l(p) for p in joints]
    for key in ("rotor_saturated_steps", "joint_saturated_steps"):  # 0 where the simulator does not count
        out[key] = int(getattr(am, key, 0))
    out["axis_saturated_steps"] = [int(x) for x in getattr(am, "axis_saturated_steps", (0, 0, 0, 0))]
    for key in ("rotor_fraction_max", "rotor_fraction_min"):
        out[key] = float(getattr(am, key, 0.0))
    est = [float(x) for x in getattr(am, "estimate", ())] or [0.0] * 13  # zeros: nothing reported yet
    i = 0
    for key, n in ESTIMATE_FIELDS.items():
        out[key] = est[i:i + n]
        i += n
    return out


def contact_sample(t_s: float, sysid: int, am, seq: int = 0) -> dict:
    """Payload of <p>/sim/am/<sysid>/contact from a simulator AmTruth (duck-typed:
    pad_object_contact with normal_force_n, normal_W, tangential_force_W, point_W, n_points;
    pad_other_contacts, base_contacts)."""
    c = am.pad_object_contact
    return {"t": float(t_s), "seq": int(seq), "sysid": int(sysid),
            "normal_force_n": float(c.normal_force_n), "normal_W": _l(c.normal_W),
            "tangential_force_W": _l(c.tangential_force_W), "point_W": _l(c.point_W), "n_points": int(c.n_points),
            "pad_other_contacts": list(am.pad_other_contacts), "base_contacts": list(am.base_contacts)}


def object_sample(t_s: float, obj, seq: int = 0) -> dict:
    """Payload of <p>/sim/object from a simulator ObjectTruth (duck-typed)."""
    return {"t": float(t_s), "seq": int(seq), "p_WO": _l(obj.p_WO), "q_WO": _l(obj.quat_WO_wxyz),
            "v_WO": _l(obj.v_WO), "w_WO": _l(obj.w_WO), "touching": list(obj.touching)}


def ground_truth_samples(gt, keys: Keys) -> Iterator[tuple[str, dict]]:
    """(key, payload) for everything in one simulator GroundTruth (duck-typed: time_s,
    ams {sysid: AmTruth}, object): per AM truth and contact, then the object."""
    t = gt.time_s
    for sysid, am in gt.ams.items():
        yield keys.am_truth(sysid), am_truth_sample(t, sysid, am)
        yield keys.contact(sysid), contact_sample(t, sysid, am)
    yield keys.object, object_sample(t, gt.object)


def event(t_s: float, kind: str, text: str, source: str, level: str = "info", data: dict | None = None,
          seq: int = 0) -> dict:
    if kind not in EVENT_KINDS:
        raise ValueError(f"event kind {kind!r} is not one of {EVENT_KINDS}")
    if level not in EVENT_LEVELS:
        raise ValueError(f"event level {level!r} is not one of {EVENT_LEVELS}")
    out = {"t": float(t_s), "seq": int(seq), "source": source, "kind": kind, "level": level, "text": text}
    if data is not None:
        out["data"] = data
    return out


def run_start_event(t_s: float, spec, source: str = "simulator") -> dict:
    """The simulator's first event: the scenario (duck-typed amcore.config.ScenarioSpec)
    so that a log is self-describing (phase times, object geometry, AM sysids)."""
    o, m = spec.object, spec.mission
    data = {
        "scenario": spec.name, "rate_hz": float(spec.rate_hz), "duration_s": float(spec.duration_s),
        "sysids": [int(a.sysid) for a in spec.ams],
        "phase_ends_s": [float(m.approach_end_s), float(m.grasp_end_s), float(m.hover_end_s)],
        "object": {"shape": o.shape, "mass_kg": float(o.mass_kg), "position_m": [float(v) for v in o.position_m],
                   "size_m": [float(v) for v in o.size_m], "radius_m": float(o.radius_m),
                   "height_m": float(o.height_m)},
    }
    return event(t_s, "run_start", f"run start: scenario {spec.name}, AMs {data['sysids']}", source, data=data)


def run_end_event(t_s: float, reason: str = "completed", source: str = "simulator", level: str = "info") -> dict:
    """The simulator's last event; the recorder stops when it sees it on <p>/sim/event."""
    return event(t_s, "run_end", f"run end: {reason}", source, level=level, data={"reason": reason})


def phase_event(t_s: float, phase: str, source: str) -> dict:
    if phase not in PHASES:
        raise ValueError(f"phase {phase!r} is not one of {PHASES}")
    return event(t_s, "phase", f"phase {phase}", source, data={"phase": phase})


def loop_timing_event(t_s: float, stats: Mapping, source: str) -> dict:
    """A real-time loop's measurements so far (a companion's on the wall clock, the free-running
    simulator's physics loop): an info event, text "loop timing", its figures in data."""
    return event(t_s, "info", "loop timing", source, data=json.loads(json.dumps(stats, default=float)))


def fault_event(t_s: float, text: str, source: str, level: str = "error") -> dict:
    return event(t_s, "fault", text, source, level=level)


def publisher_stats_sample(t_s: float, name: str, final: bool, seq_issued: Mapping[str, int],
                           counters: Mapping[str, int], seq: int = 0) -> dict:
    """Payload of <p>/telemetry/<name>. With final=True the recorder counts, per key, the
    seq numbers issued after the last one it received as missing (drops at the tail of a
    key leave no gap to see)."""
    out = {"t": float(t_s), "seq": int(seq), "name": name, "final": bool(final),
           "seq_issued": {k: int(v) for k, v in seq_issued.items()}}
    for k in ("published", "sent", "dropped_queue_full", "dropped_no_session", "dropped_at_close", "encode_errors",
              "send_errors"):
        out[k] = int(counters[k])
    return out


# ----------------------------------------------------------------------------- encoding
def samples_of(message: bytes) -> list[bytes]:
    """The samples of one zenoh message: its JSON texts, one per line (docs/telemetry.md)."""
    return message.split(b"\n")


def encode(payload: Mapping) -> tuple[bytes, bool]:
    """Compact JSON bytes of a payload, and whether non-finite numbers were replaced by
    null (strict JSON has no NaN; the recorder and Foxglove reject it)."""
    try:
        return json.dumps(payload, separators=(",", ":"), allow_nan=False).encode(), False
    except ValueError:
        return json.dumps(finite_or_null(payload), separators=(",", ":"), allow_nan=False).encode(), True


def finite_or_null(x):
    """x with every non-finite float (in nested dicts and lists) replaced by None."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: finite_or_null(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite_or_null(v) for v in x]
    return x


_HEADER = re.compile(rb'\{"t":(-?[0-9][0-9.eE+\-]*),"seq":([0-9]+)[,}]')


def peek_header(data: bytes) -> tuple[float, int] | None:
    """(t, seq) of an encoded payload without decoding it all, or None if it does not
    start as the contract says (then decode it with json.loads to find out more)."""
    m = _HEADER.match(data)
    if m is None:
        return None
    try:
        return float(m.group(1)), int(m.group(2))
    except ValueError:
        return None
