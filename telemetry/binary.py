"""The hot telemetry channels as ROS 1 messages: layouts, fast builders, the JSON view (pure).

Which channels: a companion's controller state (every control step) and the simulator's
per-step ground truth (AmTruth, PadContact, ObjectTruth). Each is a flat ROS 1 message
(telemetry.ros1) whose .msg text below is the wire layout and the MCAP schema (encoding
`ros1msg`, message encoding `ros1`), so Foxglove decodes the log without help. The fields,
names and meanings are those of the JSON payloads (telemetry.schema), in the same order, so
`to_dict(channel, data)` gives exactly the dict the JSON builder gives, with three
representation rules:

- quaternions (w, x, y, z) as float64[4], vectors as float64[k], booleans as bool;
- arrays whose length depends on the run (task variables, one entry per arm joint) are
  variable-length (`float64[]`): one schema for any number of joints n;
- AmTruth.p_W_joints (a list of 3-vectors in JSON) is one flat float64[] (x0, y0, z0, x1, ...),
  omitted from the dict when empty as in JSON; its two counters are always sent (0 when the
  simulator does not count).

Every message starts with `float64 t` and `uint64 seq` (bytes 0-7 and 8-15): the header the
recorder reads without decoding the rest (`header`), and where the publisher stamps seq.
NaN and infinity travel as IEEE 754 values (JSON has to send null instead).

The builders pack with one precompiled struct.Struct per layout (per number of task
variables, joints and phase name): ~3 us for a controller sample, where building the JSON
dict took ~5 us and json.dumps ~27 us. The literal path, `from_dict` (Ros1Message.encode of
the JSON builder's dict, one field at a time), is what the tests check them against.
"""
from __future__ import annotations

import struct
from typing import Any, Iterator, Mapping

from . import schema
from .ros1 import Ros1Message, string_array
from .schema import Channel, Keys, quat_wxyz

CONTROLLER_MSG = """\
# amstack.ControllerState: one control step of one AM (amcore.control.step); docs/telemetry.md
float64 t                # simulation time [s]
uint64 seq               # per-key counter stamped by the publisher; a gap is a lost sample
uint32 sysid
string phase             # approach, grasp or hover
float64[3] r_c           # CoM position in W [m]
float64[3] r_c_d         # desired CoM position in W [m]
float64[3] r_c_err       # r~_c = r_c - r_c,d [m]
float64[3] e_R           # attitude error (eq. ori_error) [rad]
float64[3] e_w           # angular velocity error (eq. ori_vel_error) [rad/s]
float64[4] q_WB          # base attitude R_WB, quaternion (w, x, y, z)
float64[4] q_WB_d        # desired attitude R_d (eq. Rd), quaternion (w, x, y, z)
float64[] y              # task variable y in the task frame
float64[] y_d            # desired task variable
float64[] y_err          # task error y~ = y - y_d
float64[] F_y            # external force in task space
float64[3] f_W           # filtered end-effector force F_rc in W [N]
float64[6] wrench_W      # filtered measured wrench [f; m] in W axes, moment about the end-effector [N, N m]
float64[6] wrench_E      # filtered F/T reading [f; m] in the end-effector frame E [N, N m]
float64 thrust_n         # thrust along body z [N]
float64[3] tau_B_nm      # body torque [N m]
float64[] tau_q_nm       # joint torques, one per arm joint [N m]
float64 sigma_min_J3
float64 damping
bool com_err_saturated
bool y_err_saturated
"""

AM_TRUTH_MSG = """\
# amstack.AmTruth: ground-truth base and end-effector poses of one AM (simulator); docs/telemetry.md
float64 t                # simulation time [s]
uint64 seq               # per-key counter stamped by the publisher; a gap is a lost sample
uint32 sysid
float64[3] p_WB          # base (quadrotor CoM) position in W [m]
float64[4] q_WB          # base attitude (w, x, y, z)
float64[3] p_WE          # end-effector (pad face centre) position in W [m]
float64[4] q_WE          # end-effector attitude (w, x, y, z); x = pad outward normal
float64[] p_W_joints     # arm joint origins, base to wrist, 3 numbers each (x0, y0, z0, x1, ...) [m]
uint64 rotor_saturated_steps  # commands so far whose rotor mix saturated (cumulative)
uint64 joint_saturated_steps  # commands so far with a joint torque clipped (cumulative)
"""

CONTACT_MSG = """\
# amstack.PadContact: force the object applies on one AM's pad, ground truth (simulator); docs/telemetry.md
float64 t                # simulation time [s]
uint64 seq               # per-key counter stamped by the publisher; a gap is a lost sample
uint32 sysid
float64 normal_force_n   # >= 0 [N]
float64[3] normal_W      # unit normal from the object into the pad (zero if no contact)
float64[3] tangential_force_W  # friction force on the pad [N]
float64[3] point_W       # normal-force-weighted contact point [m]
uint32 n_points          # 0: no contact
string[] pad_other_contacts
string[] base_contacts
"""

OBJECT_MSG = """\
# amstack.ObjectTruth: ground-truth pose and twist of the grasped object (simulator); docs/telemetry.md
float64 t                # simulation time [s]
uint64 seq               # per-key counter stamped by the publisher; a gap is a lost sample
float64[3] p_WO          # object CoM position in W [m]
float64[4] q_WO          # object attitude (w, x, y, z)
float64[3] v_WO          # linear velocity in W [m/s]
float64[3] w_WO          # angular velocity in W [rad/s]
string[] touching        # bodies in contact with the object
"""

CONTROLLER = Ros1Message.parse("amstack/ControllerState", CONTROLLER_MSG)
AM_TRUTH = Ros1Message.parse("amstack/AmTruth", AM_TRUTH_MSG)
CONTACT = Ros1Message.parse("amstack/PadContact", CONTACT_MSG)
OBJECT = Ros1Message.parse("amstack/ObjectTruth", OBJECT_MSG)

MESSAGES: Mapping[Channel, Ros1Message] = {Channel.CONTROLLER: CONTROLLER, Channel.AM_TRUTH: AM_TRUTH,
                                          Channel.CONTACT: CONTACT, Channel.OBJECT: OBJECT}
BY_NAME: Mapping[str, Ros1Message] = {m.name: m for m in MESSAGES.values()}
JSON_TITLE: Mapping[str, str] = {m.name: schema.SCHEMAS[ch]["title"] for ch, m in MESSAGES.items()}

HEADER = struct.Struct("<dQ")  # t, seq: the first two fields of every binary sample
SEQ_OFFSET = 8
_SEQ = struct.Struct("<Q")


def header(data: bytes) -> tuple[float, int]:
    """(t, seq) of a binary sample. ValueError if it is shorter than the header."""
    if len(data) < HEADER.size:
        raise ValueError(f"a binary sample of {len(data)} bytes has no t/seq header")
    return HEADER.unpack_from(data)


def with_seq(data: bytes, seq: int) -> bytes:
    """A copy of a binary sample with its seq field set (the publisher stamps in place instead)."""
    return data[:SEQ_OFFSET] + _SEQ.pack(seq) + data[SEQ_OFFSET + 8:]


# ----------------------------------------------------------------------------- the JSON view
def json_shape(name: str, fields: dict[str, Any]) -> dict[str, Any]:
    """The JSON payload of decoded fields of message type `name` (see the module docstring);
    other message types as they are. ValueError for a flat p_W_joints not of 3-vectors."""
    if name == AM_TRUTH.name and "p_W_joints" in fields:
        flat = fields["p_W_joints"]
        if len(flat) % 3:
            raise ValueError(f"{name}.p_W_joints: {len(flat)} numbers are not 3-vectors")
        if flat:
            fields["p_W_joints"] = [flat[i:i + 3] for i in range(0, len(flat), 3)]
        else:
            del fields["p_W_joints"]
    return fields


def to_dict(channel: Channel, data: bytes) -> dict[str, Any]:
    """The JSON payload (telemetry.schema's dict) of a binary sample of `channel`.
    ValueError if `data` is not one whole message of the channel's type."""
    msg = MESSAGES[channel]
    return json_shape(msg.name, msg.decode(data))


def from_dict(channel: Channel, payload: Mapping[str, Any]) -> bytes:
    """The binary sample of a JSON payload, field by field (the literal path). KeyError for a
    missing field, ValueError or struct.error for values that do not fit the layout."""
    if channel is Channel.AM_TRUTH:
        payload = {**payload, "p_W_joints": [v for p in payload.get("p_W_joints", ()) for v in p],
                   "rotor_saturated_steps": payload.get("rotor_saturated_steps", 0),
                   "joint_saturated_steps": payload.get("joint_saturated_steps", 0)}
    return MESSAGES[channel].encode(payload)


# ----------------------------------------------------------------------------- builders
_controller_structs: dict[tuple[int, int, str], tuple[struct.Struct, bytes]] = {}


def _controller_struct(n_y: int, n_q: int, phase: str) -> tuple[struct.Struct, bytes]:
    ph = phase.encode("utf-8")
    lengths = {"phase": len(ph), "y": n_y, "y_d": n_y, "y_err": n_y, "F_y": n_y, "tau_q_nm": n_q}
    return CONTROLLER.struct(lengths), ph


def controller_sample(t_s: float, phase: str, diag, cmd, seq: int = 0, sysid: int = 0) -> bytes:
    """Binary <p>/am/<sysid>/controller sample from amcore.control's Diagnostics and Command
    (their public fields, as schema.controller_sample reads them). `seq` is stamped by the
    publisher. Arrays of unexpected lengths or types take the literal path."""
    n_y, n_q = len(diag.y), len(cmd.tau_q_nm)
    layout = _controller_structs.get((n_y, n_q, phase))
    if layout is None:
        layout = _controller_structs.setdefault((n_y, n_q, phase), _controller_struct(n_y, n_q, phase))
    st, ph = layout
    try:
        return st.pack(
            t_s, seq, sysid, len(ph), ph,
            *diag.r_c.tolist(), *diag.r_c_d.tolist(), *diag.r_c_err.tolist(), *diag.e_R.tolist(), *diag.e_w.tolist(),
            *quat_wxyz(diag.R_WB), *quat_wxyz(diag.R_d),
            n_y, *diag.y.tolist(), n_y, *diag.y_d.tolist(), n_y, *diag.y_err.tolist(), n_y, *diag.F_y.tolist(),
            *diag.F_rc.tolist(), *diag.wrench_W_filtered.tolist(), *diag.wrench_E_filtered.tolist(),
            cmd.thrust_n, *cmd.tau_B_nm.tolist(), n_q, *cmd.tau_q_nm.tolist(),
            diag.sigma_min_J3, diag.damping, diag.com_err_saturated, diag.y_err_saturated)
    except (struct.error, AttributeError, TypeError):  # e.g. y_d not as long as y, a list for an array
        return from_dict(Channel.CONTROLLER, schema.controller_sample(t_s, phase, diag, cmd, seq=seq, sysid=sysid))


_truth_structs: dict[int, struct.Struct] = {}
_CONTACT_HEAD = CONTACT.struct(stop="pad_other_contacts")
_OBJECT_HEAD = OBJECT.struct(stop="touching")
_strings_cache: dict[tuple, bytes] = {}


def _strings(items) -> bytes:
    """string[] of names (contacts: a handful of distinct tuples per run, hence the cache)."""
    try:
        out = _strings_cache.get(items)
    except TypeError:  # a list: not hashable
        return string_array(items)
    if out is None:
        if len(_strings_cache) > 1024:
            _strings_cache.clear()
        out = _strings_cache[items] = string_array(items)
    return out


def am_truth_sample(t_s: float, sysid: int, am, seq: int = 0) -> bytes:
    """Binary <p>/sim/am/<sysid>/truth sample from a simulator AmTruth (duck-typed as for
    schema.am_truth_sample)."""
    joints = getattr(am, "p_W_joints", ())
    n = len(joints)
    st = _truth_structs.get(n)
    if st is None:
        st = _truth_structs.setdefault(n, AM_TRUTH.struct({"p_W_joints": 3 * n}))
    try:
        return st.pack(t_s, seq, sysid, *am.p_WB.tolist(), *quat_wxyz(am.R_WB), *am.p_WE.tolist(), *quat_wxyz(am.R_WE),
                       3 * n, *[v for p in joints for v in p.tolist()],
                       getattr(am, "rotor_saturated_steps", 0), getattr(am, "joint_saturated_steps", 0))
    except (struct.error, AttributeError, TypeError):  # sequences that are not numpy arrays, odd lengths
        return from_dict(Channel.AM_TRUTH, schema.am_truth_sample(t_s, sysid, am, seq=seq))


def contact_sample(t_s: float, sysid: int, am, seq: int = 0) -> bytes:
    """Binary <p>/sim/am/<sysid>/contact sample from a simulator AmTruth (duck-typed)."""
    c = am.pad_object_contact
    try:
        return (_CONTACT_HEAD.pack(t_s, seq, sysid, c.normal_force_n, *c.normal_W.tolist(),
                                   *c.tangential_force_W.tolist(), *c.point_W.tolist(), c.n_points)
                + _strings(am.pad_other_contacts) + _strings(am.base_contacts))
    except (struct.error, AttributeError, TypeError):
        return from_dict(Channel.CONTACT, schema.contact_sample(t_s, sysid, am, seq=seq))


def object_sample(t_s: float, obj, seq: int = 0) -> bytes:
    """Binary <p>/sim/object sample from a simulator ObjectTruth (duck-typed)."""
    try:
        return (_OBJECT_HEAD.pack(t_s, seq, *obj.p_WO.tolist(), *obj.quat_WO_wxyz.tolist(), *obj.v_WO.tolist(),
                                  *obj.w_WO.tolist())
                + _strings(obj.touching))
    except (struct.error, AttributeError, TypeError):
        return from_dict(Channel.OBJECT, schema.object_sample(t_s, obj, seq=seq))


def ground_truth_samples(gt, keys: Keys) -> Iterator[tuple[str, bytes]]:
    """(key, binary sample) for one simulator GroundTruth, in schema.ground_truth_samples' order."""
    t = gt.time_s
    for sysid, am in gt.ams.items():
        yield keys.am_truth(sysid), am_truth_sample(t, sysid, am)
        yield keys.contact(sysid), contact_sample(t, sysid, am)
    yield keys.object, object_sample(t, gt.object)
