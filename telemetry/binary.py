"""The hot telemetry channels as ROS 1 messages: their layouts and their JSON view (pure).

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

The builders (telemetry.capture) copy a sample's arrays on the caller's thread and leave
the quaternions to the publisher's sender thread; the literal path, `from_dict` (Ros1Message.encode
of the JSON builder's dict, one field at a time), is what the tests check them against.
"""
from __future__ import annotations

import struct
from typing import Any, Mapping

from . import schema
from .ros1 import Ros1Message
from .schema import Channel

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
uint64[4] axis_saturated_steps  # commands so far whose roll, pitch, yaw torque, thrust fell short (cumulative)
float64 rotor_fraction_max  # the busiest rotor's thrust as a fraction of its range, now
float64 rotor_fraction_min  # the idlest rotor's
float64[3] p_WB_est      # the base position the flight controller reports (its estimate) [m]; all 4 zero: none yet
float64[4] q_WB_est      # its base attitude (w, x, y, z)
float64[3] v_B_est       # its base velocity in B [m/s]
float64[3] w_B_est       # its body rate [rad/s]
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
TRUTH_POSES = AM_TRUTH.struct(stop="p_W_joints")  # t, seq, sysid, p_WB, q_WB, p_WE, q_WE: what /tf needs
OBJECT_POSE = OBJECT.struct(stop="v_WO")  # t, seq, p_WO, q_WO
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
                   "joint_saturated_steps": payload.get("joint_saturated_steps", 0),
                   "axis_saturated_steps": payload.get("axis_saturated_steps", [0, 0, 0, 0]),
                   "rotor_fraction_max": payload.get("rotor_fraction_max", 0.0),
                   "rotor_fraction_min": payload.get("rotor_fraction_min", 0.0),
                   **{k: payload.get(k, [0.0] * n) for k, n in schema.ESTIMATE_FIELDS.items()}}
    return MESSAGES[channel].encode(payload)
