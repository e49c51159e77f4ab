"""Encode/decode amlink value types to/from MAVLink 2 frames of the amstack dialect.

Batches (each one UDP datagram, frames concatenated, the marker frame LAST):

* sensor batch, simulator -> companion:
  ``ODOMETRY, AM_JOINT_STATE, AM_WRENCH, [ATTITUDE_TARGET,] AM_SIM_STEP``; in attitude mode
  AM_JOINT_STATE carries the servos' measured joint torques (extension fields ``effort_nm``,
  ``effort_valid``) and ATTITUDE_TARGET the target the autopilot flies (as PX4 reports it;
  NED/FRD, float32, for the batch's step: the message carries no step)
* setpoint batch, companion -> simulator:
  ``[SET_ATTITUDE_TARGET,] AM_TORQUE_SETPOINT`` (torque mode), or
  ``SET_ATTITUDE_TARGET, AM_JOINT_TORQUE_SETPOINT`` (attitude mode: :class:`AttitudeSetpoint`)

ODOMETRY conventions (documented choice): ``frame_id = MAV_FRAME_LOCAL_ENU`` (4),
the only earth-fixed z-up frame in common.xml with fixed axes (the simulator's
world x/y are read as east/north); ``child_frame_id = MAV_FRAME_RESERVED_13`` (13),
which common.xml documents as the former ``MAV_FRAME_BODY_FLU`` (x forward,
y left, z up) -- deprecated, but the only value whose definition is a FLU body
frame (``MAV_FRAME_LOCAL_FLU`` is earth-fixed; ``MAV_FRAME_BODY_FRD`` is z down).
Pose = p_WB [m] and q_WB (w, x, y, z); twist = v_B [m/s], w_B [rad/s], both in B.
``time_usec`` = simulation time.  The decoder rejects other frame ids.

SET_ATTITUDE_TARGET is defined by MAVLink as NED <- FRD; :class:`AttitudeTarget`
is ENU <- FLU, so the codec converts at this edge (a fixed quaternion map).

Floats: ODOMETRY and SET_ATTITUDE_TARGET force float32; amstack messages carry
float64.  Decoding rejects non-finite values with :class:`NonFiniteValueError`.

How: encoding packs each payload with a ``struct.Struct`` derived from the generated dialect
(:class:`MessageLayout`, below) and frames it with :meth:`amlink.wire.Encoder.pack_payloads`; decoding
takes the records of :meth:`amlink.wire.Decoder.feed_records` (built with :data:`READERS`) and
assembles value types from plain tuples. The messages sent once a run (AM_SCENARIO,
AM_OBJECT_POSE, the SHUTDOWN step) are pymavlink message objects, framed with
:meth:`amlink.wire.Encoder.encode`. The readable twin of the batch codec, on pymavlink's message
objects, is in the tests (``tests/amlink/codec_reference.py``): they check that both write the
same bytes and read them into the same values with the same errors, and that pymavlink reads
what this writes.

Usage::

    enc = wire.Encoder(1, 1, signing_key=key, link_id=2)
    data = enc.pack_payloads(codec.sensor_frame_payloads(frame, scenario_id))
    dec = wire.Decoder(keys, readers=codec.READERS)
    asm = codec.SensorFrameAssembler()
    for msgid, sysid, compid, body in dec.feed_records(data):
        item = asm.push(msgid, body)        # SensorFrame | codec.Shutdown | None

Errors: ``EncodeError``, ``NonFiniteValueError``, ``BatchMismatchError``,
``FrameConventionError``, all ``CodecError``.
"""

from __future__ import annotations

import math
import re
import struct
from collections.abc import Callable
from dataclasses import dataclass

from amlink import wire
from amlink.px4 import q_enu_flu_to_ned_frd, q_ned_frd_to_enu_flu
from amlink.types import (
    MAX_JOINTS,
    AttitudeSetpoint,
    AttitudeTarget,
    ScenarioInfo,
    SensorFrame,
    StepFlag,
    TorqueSetpoint,
    attitude_setpoint_from_wire,
    attitude_target_from_wire,
    sensor_frame_from_wire,
    torque_setpoint_from_wire,
)
from amlink.wire import CodecError, Decoder, EncodeError, Encoder  # noqa: F401  (re-exported)

# ------------------------------------------------------------------ payload layouts
# pymavlink's generated class of every message carries what the wire needs: the payload
# `struct` format (`unpacker.format`, the fmtstr, fields sorted by MAVLink 2 rules), the field
# order it follows (`ordered_fieldnames`), `crc_extra` and the id. `MessageLayout` turns that
# into per-field offsets and builds precompiled `struct.Struct` objects that pack or read just
# the fields a caller names, so that no layout is copied by hand. A caller names fields in wire
# order; if a dialect change reorders them, building the packer or reader raises `LayoutError`
# at import instead of corrupting frames.
_TOKEN = re.compile(r"(\d*)([a-zA-Z?])")


class LayoutError(ValueError):
    """A requested field does not exist or is not in wire order, or the dialect's format is odd."""


@dataclass(frozen=True)
class Field:
    """One payload field: ``token`` is its struct code (``"d"``, ``"8d"``, ``"32s"``), ``offset`` in bytes."""

    name: str
    token: str
    offset: int
    size: int

    @property
    def values(self) -> int:
        """How many values ``struct`` yields for it (a char array is one ``bytes``)."""
        count, code = _TOKEN.fullmatch(self.token).groups()
        return 1 if code == "s" or not count else int(count)


@dataclass(frozen=True)
class MessageLayout:
    """Wire layout of one message: id, CRC_EXTRA, payload size and fields in wire order."""

    msgid: int
    name: str
    crc_extra: int
    size: int
    fields: tuple[Field, ...]

    @classmethod
    def of(cls, msg_class) -> MessageLayout:
        """Layout of a generated ``MAVLink_*_message`` class (its ``unpacker.format`` and field order)."""
        fmt = msg_class.unpacker.format
        if not fmt.startswith("<"):
            raise LayoutError(f"{msg_class.msgname}: format {fmt!r} is not little-endian standard")
        tokens = [count + code for count, code in _TOKEN.findall(fmt[1:])]
        names = list(msg_class.ordered_fieldnames)
        if len(tokens) != len(names) or "".join(tokens) != fmt[1:]:
            raise LayoutError(f"{msg_class.msgname}: cannot match format {fmt!r} to fields {names}")
        fields, offset = [], 0
        for name, token in zip(names, tokens):
            size = struct.calcsize("<" + token)
            fields.append(Field(name, token, offset, size))
            offset += size
        if offset != msg_class.unpacker.size:  # pragma: no cover - struct and calcsize disagree
            raise LayoutError(f"{msg_class.msgname}: derived size {offset} != {msg_class.unpacker.size}")
        return cls(msg_class.id, msg_class.msgname, msg_class.crc_extra, offset, tuple(fields))

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise LayoutError(f"{self.name} has no field {name!r}")

    def _indices(self, names: tuple[str, ...]) -> list[int]:
        order = [f.name for f in self.fields]
        idx = []
        for name in names:
            if name not in order:
                raise LayoutError(f"{self.name} has no field {name!r}")
            idx.append(order.index(name))
        if idx != sorted(set(idx)):
            raise LayoutError(f"{self.name}: fields {names} are not in wire order {tuple(order)}")
        return idx

    def packer(self, *names: str, **fixed) -> Packer:
        """Pack ``names`` (leading fields, wire order); every later field is ``fixed[name]`` or zero.

        The trailing fixed fields are packed once here.  Their values must be what
        ``struct`` takes for them (a sequence for an array).
        """
        idx = self._indices(names)
        if idx != list(range(len(names))):
            raise LayoutError(f"{self.name}: packed fields {names} must lead the wire order "
                              f"{tuple(f.name for f in self.fields)}")  # fmt: skip
        rest = self.fields[len(names) :]
        unknown = set(fixed) - {f.name for f in rest}
        if unknown:
            raise LayoutError(f"{self.name}: fixed fields {sorted(unknown)} are not trailing fields")
        tail_values = []
        for f in rest:
            zero = b"" if f.token.endswith("s") else (0,) * f.values if f.values > 1 else 0
            v = fixed.get(f.name, zero)
            tail_values.extend(v if f.values > 1 else (v,))
        tail = struct.pack("<" + "".join(f.token for f in rest), *tail_values)
        head = struct.Struct("<" + "".join(self.fields[i].token for i in idx))
        return Packer(self.msgid, self.name, head, tail)

    def reader(self, *names: str) -> Reader:
        """Read ``names`` (wire order) from a payload, other bytes skipped; values flattened."""
        idx = self._indices(names)
        fmt, at = "<", 0
        for i in idx:
            f = self.fields[i]
            if f.offset > at:
                fmt += f"{f.offset - at}x"
            fmt += f.token
            at = f.offset + f.size
        return Reader(self.msgid, self.name, struct.Struct(fmt))


class Packer:
    """``pack(*values) -> payload`` (full length, trailing zeros kept: the framer drops them)."""

    __slots__ = ("msgid", "name", "head", "tail", "pack")

    def __init__(self, msgid: int, name: str, head: struct.Struct, tail: bytes) -> None:
        self.msgid, self.name, self.head, self.tail = msgid, name, head, tail
        if not tail:
            self.pack: Callable[..., bytes] = head.pack
        else:
            head_pack = head.pack

            def pack(*values) -> bytes:
                return head_pack(*values) + tail

            self.pack = pack


class Reader:
    """``read(buf, at, plen) -> tuple``: the named fields of the payload ``buf[at : at + plen]``.

    MAVLink 2 drops trailing zero bytes, so a short payload is read as if zero-padded;
    a longer one's extra bytes are ignored (both as pymavlink's ``decode``).
    """

    __slots__ = ("msgid", "name", "struct", "read")

    def __init__(self, msgid: int, name: str, s: struct.Struct) -> None:
        self.msgid, self.name, self.struct = msgid, name, s
        size, unpack_from, unpack = s.size, s.unpack_from, s.unpack

        def read(buf, at: int, plen: int) -> tuple:
            if plen >= size:
                return unpack_from(buf, at)
            return unpack(bytes(buf[at : at + plen]) + bytes(size - plen))

        self.read: Callable[[bytes, int, int], tuple] = read


# ------------------------------------------------------------------ the batches
mav = wire.mav

ODOM_FRAME_ID = mav.MAV_FRAME_LOCAL_ENU
ODOM_CHILD_FRAME_ID = mav.MAV_FRAME_RESERVED_13  # formerly MAV_FRAME_BODY_FLU


class NonFiniteValueError(CodecError):
    """A decoded float is NaN or infinite; ``field`` names the message field."""

    def __init__(self, message: str, field: str):
        super().__init__(f"non-finite value in {message}.{field}")
        self.message = message
        self.field = field


class BatchMismatchError(CodecError):
    """The frames of one batch disagree (step/time) or a part is missing."""


class FrameConventionError(CodecError):
    """ODOMETRY carries frame ids other than LOCAL_ENU / BODY_FLU."""


def all_finite(values) -> bool:
    """True if every float in ``values`` is finite (fast path: one sum)."""
    if math.isfinite(sum(values)):
        return True
    return all(map(math.isfinite, values))  # a finite sum can only overflow, recheck


def _usec(time_s: float) -> int:
    if not (math.isfinite(time_s) and time_s >= 0.0):
        raise EncodeError(f"time_s must be finite and >= 0, got {time_s}")
    return round(time_s * 1e6)


def attitude_setpoint_values(sp: AttitudeSetpoint) -> tuple[list[float], list[float], list[float]]:
    """(quaternion wxyz, body rates, joint torques) of an attitude-mode setpoint as floats;
    EncodeError if any value (or the normalized thrust) is not finite."""
    att = sp.attitude
    quat, r, tau_q = att.quat_wxyz.tolist(), att.rates_rad_s.tolist(), sp.tau_q_nm.tolist()
    if not all_finite([*quat, *r, att.thrust_normalized]):
        raise EncodeError(f"non-finite value in AttitudeTarget step {att.step}")
    if not all_finite(tau_q):
        raise EncodeError(f"non-finite value in AttitudeSetpoint step {sp.step}")
    return quat, r, tau_q


# -- the messages sent once a run (pymavlink message objects) ---------------------


def shutdown_message(step: int, time_s: float, scenario_id: int = 0) -> object:
    """A bare AM_SIM_STEP with the SHUTDOWN flag (the last message of a run)."""
    return mav.MAVLink_am_sim_step_message(step, _usec(time_s), scenario_id, int(StepFlag.SHUTDOWN))


def scenario_message(info: ScenarioInfo) -> object:
    return mav.MAVLink_am_scenario_message(
        info.scenario_id, info.n_am, info.name.encode("ascii"), info.seed, info.rate_hz
    )


def object_pose_message(position_m, yaw_rad: float) -> object:
    """AM_OBJECT_POSE: the measured object's centre [m, W] and yaw [rad]."""
    return mav.MAVLink_am_object_pose_message([float(x) for x in position_m], float(yaw_rad))


def scenario_from_message(msg) -> ScenarioInfo:
    name = msg.name.decode("ascii", errors="replace") if isinstance(msg.name, bytes) else msg.name
    if not math.isfinite(msg.rate_hz):
        raise NonFiniteValueError("AM_SCENARIO", "rate_hz")
    return ScenarioInfo(msg.scenario_id, msg.n_am, name.rstrip("\x00"), msg.seed, msg.rate_hz)


def object_pose_from_message(msg) -> tuple[tuple[float, float, float], float]:
    """AM_OBJECT_POSE as ((x, y, z) [m, W], yaw [rad]); NonFiniteValueError on NaN/inf."""
    values = [*msg.position_m, msg.yaw_rad]
    if not all(math.isfinite(v) for v in values):
        raise NonFiniteValueError("AM_OBJECT_POSE", "position_m or yaw_rad")
    return (tuple(float(x) for x in msg.position_m), float(msg.yaw_rad))


@dataclass(frozen=True)
class Shutdown:
    """The simulator announced the end of the run (AM_SIM_STEP with SHUTDOWN)."""

    step: int
    time_s: float
    flags: StepFlag


# -- the lockstep batches --------------------------------------------------------
ODOMETRY = MessageLayout.of(mav.MAVLink_odometry_message)
JOINT_STATE = MessageLayout.of(mav.MAVLink_am_joint_state_message)
WRENCH = MessageLayout.of(mav.MAVLink_am_wrench_message)
SIM_STEP = MessageLayout.of(mav.MAVLink_am_sim_step_message)
TORQUE_SETPOINT = MessageLayout.of(mav.MAVLink_am_torque_setpoint_message)
ATTITUDE_TARGET = MessageLayout.of(mav.MAVLink_set_attitude_target_message)
ATTITUDE_REPORT = MessageLayout.of(mav.MAVLink_attitude_target_message)  # ATTITUDE_TARGET: what the autopilot flies
JOINT_TORQUE_SETPOINT = MessageLayout.of(mav.MAVLink_am_joint_torque_setpoint_message)
_ODOMETRY_ID, _JOINT_STATE_ID, _WRENCH_ID = ODOMETRY.msgid, JOINT_STATE.msgid, WRENCH.msgid
_SIM_STEP_ID, _TORQUE_SETPOINT_ID, _ATTITUDE_TARGET_ID = SIM_STEP.msgid, TORQUE_SETPOINT.msgid, ATTITUDE_TARGET.msgid
_JOINT_TORQUE_SETPOINT_ID = JOINT_TORQUE_SETPOINT.msgid
_ATTITUDE_REPORT_ID = ATTITUDE_REPORT.msgid

_BASE = ("x", "y", "z", "q", "vx", "vy", "vz", "rollspeed", "pitchspeed", "yawspeed")  # 13 floats
_UNKNOWN_COV = [math.nan] + [0.0] * 20  # MAVLink: NaN first element = unknown

# -- packers: the fields we set, in wire order; the rest fixed ------------------------
_pack_odometry = ODOMETRY.packer(
    "time_usec", *_BASE, pose_covariance=_UNKNOWN_COV, velocity_covariance=_UNKNOWN_COV,
    frame_id=ODOM_FRAME_ID, child_frame_id=ODOM_CHILD_FRAME_ID, reset_counter=0,
    estimator_type=mav.MAV_ESTIMATOR_TYPE_NAIVE, quality=100,
).pack  # fmt: skip
_pack_joints = JOINT_STATE.packer("step", "position_rad", "velocity_rad_s", "n_joints").pack
_pack_joints_effort = JOINT_STATE.packer("step", "position_rad", "velocity_rad_s", "n_joints", "effort_nm",
                                         "effort_valid").pack
_pack_report = ATTITUDE_REPORT.packer("time_boot_ms", "q", "body_roll_rate", "body_pitch_rate", "body_yaw_rate",
                                      "thrust", "type_mask").pack
_pack_wrench = WRENCH.packer("step", "force_n", "torque_nm").pack
_pack_step = SIM_STEP.packer("step", "time_usec", "scenario_id", "flags").pack
_pack_setpoint = TORQUE_SETPOINT.packer("step", "thrust_n", "body_torque_nm", "joint_torque_nm", "n_joints",
                                        "flags").pack  # fmt: skip
_pack_joint_setpoint = JOINT_TORQUE_SETPOINT.packer("step", "joint_torque_nm", "n_joints", "flags").pack
_pack_attitude = ATTITUDE_TARGET.packer("time_boot_ms", "q", "body_roll_rate", "body_pitch_rate", "body_yaw_rate",
                                        "thrust", "target_system", "target_component", type_mask=0).pack  # fmt: skip

# -- readers: the fields we use, in wire order; values flattened -----------------------
READERS = {
    ODOMETRY.msgid: ODOMETRY.reader("time_usec", *_BASE, "frame_id", "child_frame_id").read,
    JOINT_STATE.msgid: JOINT_STATE.reader("step", "position_rad", "velocity_rad_s", "n_joints", "effort_nm",
                                          "effort_valid").read,
    ATTITUDE_REPORT.msgid: ATTITUDE_REPORT.reader("q", "body_roll_rate", "body_pitch_rate", "body_yaw_rate",
                                                  "thrust").read,
    WRENCH.msgid: WRENCH.reader("step", "force_n", "torque_nm").read,
    SIM_STEP.msgid: SIM_STEP.reader("step", "time_usec", "scenario_id", "flags").read,
    TORQUE_SETPOINT.msgid: TORQUE_SETPOINT.reader(
        "step", "thrust_n", "body_torque_nm", "joint_torque_nm", "n_joints", "flags"
    ).read,
    ATTITUDE_TARGET.msgid: ATTITUDE_TARGET.reader(
        "q", "body_roll_rate", "body_pitch_rate", "body_yaw_rate", "thrust"
    ).read,
    JOINT_TORQUE_SETPOINT.msgid: JOINT_TORQUE_SETPOINT.reader("step", "joint_torque_nm", "n_joints", "flags").read,
}
"""``msgid -> read`` for :class:`amlink.wire.Decoder`; body tuples as documented on each assembler."""

_ZEROS = (0.0,) * MAX_JOINTS
_SHUTDOWN = int(StepFlag.SHUTDOWN)


# -- encoders ---------------------------------------------------------------------------


def sensor_frame_payloads(frame: SensorFrame, scenario_id: int = 0) -> tuple[tuple[int, bytes], ...]:
    """``(msgid, payload)`` of a sensor batch."""
    t_us = _usec(frame.time_s)
    p, qt = frame.p_WB.tolist(), frame.quat_WB_wxyz.tolist()
    v, w = frame.v_B.tolist(), frame.w_B.tolist()
    q, qdot, wr = frame.q.tolist(), frame.qdot.tolist(), frame.wrench_E.tolist()
    if not all_finite(p + qt + v + w + q + qdot + wr):
        raise EncodeError(f"non-finite value in SensorFrame step {frame.step}")
    n, step = len(q), frame.step
    pad = _ZEROS[n:]
    name = "ODOMETRY"  # the messages that can fail to pack (float32 range, uint32 scenario id)
    try:
        odom = _pack_odometry(t_us, *p, *qt, *v, *w)
        name = "AM_SIM_STEP"
        sim_step = _pack_step(step, t_us, scenario_id, int(frame.flags))
    except (struct.error, OverflowError) as exc:  # worded as amlink.wire.Encoder.pack does
        raise EncodeError(f"cannot pack {name}: {exc}") from exc
    if frame.joint_effort_nm is None:
        joints = _pack_joints(step, *q, *pad, *qdot, *pad, n)
    else:
        e = frame.joint_effort_nm.tolist()
        if not all_finite(e):
            raise EncodeError(f"non-finite value in SensorFrame step {frame.step}")
        joints = _pack_joints_effort(step, *q, *pad, *qdot, *pad, n, *e, *pad, 1)
    if frame.attitude_target is None:
        return (
            (_ODOMETRY_ID, odom),
            (_JOINT_STATE_ID, joints),
            (_WRENCH_ID, _pack_wrench(step, *wr)),
            (_SIM_STEP_ID, sim_step),
        )
    return (
        (_ODOMETRY_ID, odom),
        (_JOINT_STATE_ID, joints),
        (_WRENCH_ID, _pack_wrench(step, *wr)),
        attitude_report_payload(frame.attitude_target, t_us // 1000),
        (_SIM_STEP_ID, sim_step),
    )


def attitude_report_payload(att: AttitudeTarget, time_boot_ms: int = 0) -> tuple[int, bytes]:
    """``(msgid, payload)`` of ATTITUDE_TARGET."""
    quat, r = att.quat_wxyz.tolist(), att.rates_rad_s.tolist()
    if not all_finite([*quat, *r, att.thrust_normalized]):
        raise EncodeError(f"non-finite value in AttitudeTarget step {att.step}")
    try:  # FLU -> FRD body rates: (p, q, r) -> (p, -q, -r)
        return _ATTITUDE_REPORT_ID, _pack_report(time_boot_ms & 0xFFFFFFFF, *q_enu_flu_to_ned_frd(quat), r[0], -r[1],
                                                 -r[2], att.thrust_normalized, 0)  # fmt: skip
    except (struct.error, OverflowError) as exc:
        raise EncodeError(f"cannot pack ATTITUDE_TARGET: {exc}") from exc


def attitude_report_from_fields(fields: tuple, step: int) -> AttitudeTarget:
    """``fields`` = (q[4], roll, pitch, yaw rates, thrust)."""
    if not all_finite(fields):
        raise NonFiniteValueError("ATTITUDE_TARGET", "q/rates/thrust")
    return attitude_target_from_wire(step, (*q_ned_frd_to_enu_flu(fields[0:4]), fields[4], -fields[5], -fields[6],
                                            fields[7]))  # fmt: skip


def setpoint_payloads(
    sp: TorqueSetpoint, attitude: AttitudeTarget | None = None, time_boot_ms: int = 0,
    target_system: int = 1, target_component: int = 1,
) -> tuple[tuple[int, bytes], ...]:  # fmt: skip
    """``(msgid, payload)`` of a setpoint batch."""
    tau_B, tau_q = sp.tau_B_nm.tolist(), sp.tau_q_nm.tolist()
    if not all_finite([sp.thrust_n, *tau_B, *tau_q]):
        raise EncodeError(f"non-finite value in TorqueSetpoint step {sp.step}")
    n = len(tau_q)
    setpoint = (_TORQUE_SETPOINT_ID, _pack_setpoint(sp.step, sp.thrust_n, *tau_B, *tau_q, *_ZEROS[n:], n,
                                                      int(sp.flags)))  # fmt: skip
    if attitude is None:
        return (setpoint,)
    quat, r = attitude.quat_wxyz.tolist(), attitude.rates_rad_s.tolist()
    if not all_finite([*quat, *r, attitude.thrust_normalized]):
        raise EncodeError(f"non-finite value in AttitudeTarget step {attitude.step}")
    # FLU -> FRD body rates: (p, q, r) -> (p, -q, -r)
    try:
        att = _pack_attitude(time_boot_ms & 0xFFFFFFFF, *q_enu_flu_to_ned_frd(quat), r[0], -r[1], -r[2],
                             attitude.thrust_normalized, target_system, target_component)  # fmt: skip
    except (struct.error, OverflowError) as exc:
        raise EncodeError(f"cannot pack SET_ATTITUDE_TARGET: {exc}") from exc
    return (_ATTITUDE_TARGET_ID, att), setpoint


def attitude_setpoint_payloads(
    sp: AttitudeSetpoint, time_boot_ms: int = 0, target_system: int = 1, target_component: int = 1,
) -> tuple[tuple[int, bytes], ...]:  # fmt: skip
    """``(msgid, payload)`` of an attitude-mode batch."""
    att = sp.attitude
    quat, r, tau_q = attitude_setpoint_values(sp)
    try:  # FLU -> FRD body rates: (p, q, r) -> (p, -q, -r)
        payload = _pack_attitude(time_boot_ms & 0xFFFFFFFF, *q_enu_flu_to_ned_frd(quat), r[0], -r[1], -r[2],
                                 att.thrust_normalized, target_system, target_component)  # fmt: skip
    except (struct.error, OverflowError) as exc:
        raise EncodeError(f"cannot pack SET_ATTITUDE_TARGET: {exc}") from exc
    n = len(tau_q)
    return ((_ATTITUDE_TARGET_ID, payload),
            (_JOINT_TORQUE_SETPOINT_ID, _pack_joint_setpoint(sp.step, *tau_q, *_ZEROS[n:], n, int(sp.flags))))


# -- decoders (bodies are READERS tuples) --------------------------------------------------


def sensor_frame_from_fields(odom: tuple, joints: tuple, wrench: tuple, step_fields: tuple,
                             target: tuple | None = None) -> SensorFrame:
    """A :class:`SensorFrame` from the reader tuples of one batch (and its ATTITUDE_TARGET in attitude mode,
    ``target``); BatchMismatchError if the steps (or ODOMETRY/AM_SIM_STEP times) disagree,
    FrameConventionError on other ODOMETRY frames, NonFiniteValueError on NaN/inf.

    ``odom`` = (time_usec, x, y, z, q[4], vx, vy, vz, rollspeed, pitchspeed, yawspeed,
    frame_id, child_frame_id); ``joints`` = (step, position[8], velocity[8], n_joints, effort[8],
    effort_valid); ``target``: an ATTITUDE_TARGET's reader tuple, or None;
    ``wrench`` = (step, force[3], torque[3]); ``step_fields`` = (step, time_usec, scenario_id, flags).
    """
    step, time_usec, _, flags = step_fields
    if joints[0] != step or wrench[0] != step:
        raise BatchMismatchError(
            f"batch steps disagree: AM_SIM_STEP {step}, AM_JOINT_STATE {joints[0]}, AM_WRENCH {wrench[0]}"
        )
    if odom[0] != time_usec:
        raise BatchMismatchError(f"step {step}: ODOMETRY time_usec {odom[0]} != AM_SIM_STEP time_usec {time_usec}")
    frame_id, child_frame_id = odom[14], odom[15]
    if frame_id != ODOM_FRAME_ID or child_frame_id != ODOM_CHILD_FRAME_ID:
        raise FrameConventionError(
            f"ODOMETRY frames ({frame_id}, {child_frame_id}) != (LOCAL_ENU, BODY_FLU)"
            f" = ({ODOM_FRAME_ID}, {ODOM_CHILD_FRAME_ID})"
        )
    n = joints[17]
    if n > MAX_JOINTS:
        raise CodecError(f"AM_JOINT_STATE.n_joints={n} > {MAX_JOINTS}")
    base = odom[1:14]
    if not all_finite(base):
        raise NonFiniteValueError("ODOMETRY", "pose/twist")
    q, qdot = joints[1 : 1 + n], joints[9 : 9 + n]
    if not all_finite(q):
        raise NonFiniteValueError("AM_JOINT_STATE", "position_rad")
    if not all_finite(qdot):
        raise NonFiniteValueError("AM_JOINT_STATE", "velocity_rad_s")
    wr = wrench[1:7]
    if not all_finite(wr):
        raise NonFiniteValueError("AM_WRENCH", "force_n/torque_nm")
    effort = None
    if joints[26]:
        effort = joints[18 : 18 + n]
        if not all_finite(effort):
            raise NonFiniteValueError("AM_JOINT_STATE", "effort_nm")
    return sensor_frame_from_wire(step, time_usec / 1e6, base + q + qdot + wr, n, flags, effort,
                                  None if target is None else attitude_report_from_fields(target, step))


def setpoint_from_fields(fields: tuple) -> TorqueSetpoint:
    """``fields`` = (step, thrust, tau_B[3], tau_q[8], n, flags)."""
    n = fields[13]
    if n > MAX_JOINTS:
        raise CodecError(f"AM_TORQUE_SETPOINT.n_joints={n} > {MAX_JOINTS}")
    thrust = fields[1]
    if not math.isfinite(thrust):
        raise NonFiniteValueError("AM_TORQUE_SETPOINT", "thrust_n")
    if not all_finite(fields[2:5]):
        raise NonFiniteValueError("AM_TORQUE_SETPOINT", "body_torque_nm")
    if not all_finite(fields[5 : 5 + n]):
        raise NonFiniteValueError("AM_TORQUE_SETPOINT", "joint_torque_nm")
    return torque_setpoint_from_wire(fields[0], thrust, fields[2 : 5 + n], n, fields[14])


def attitude_from_fields(fields: tuple, step: int) -> AttitudeTarget:
    """``fields`` = (q[4], roll, pitch, yaw rates, thrust), NED/FRD."""
    if not all_finite(fields):
        raise NonFiniteValueError("SET_ATTITUDE_TARGET", "q/rates/thrust")
    # FRD -> FLU rates; the quaternion map is an involution
    return attitude_target_from_wire(step, (*q_ned_frd_to_enu_flu(fields[0:4]), fields[4], -fields[5], -fields[6],
                                            fields[7]))  # fmt: skip


def attitude_setpoint_from_fields(att_fields: tuple, joint_fields: tuple) -> AttitudeSetpoint:
    """``joint_fields`` = (step, tau_q[8], n, flags)."""
    n = joint_fields[9]
    if n > MAX_JOINTS:
        raise CodecError(f"AM_JOINT_TORQUE_SETPOINT.n_joints={n} > {MAX_JOINTS}")
    if not all_finite(joint_fields[1 : 1 + n]):
        raise NonFiniteValueError("AM_JOINT_TORQUE_SETPOINT", "joint_torque_nm")
    step = joint_fields[0]
    return attitude_setpoint_from_wire(step, attitude_from_fields(att_fields, step), joint_fields[1:9], n,
                                       joint_fields[10])  # fmt: skip


class SensorFrameAssembler:
    """Collects the parts of a sensor batch, fed ``(msgid, body)`` of reader records; emits when
    its AM_SIM_STEP arrives.

    Parts may arrive across several datagrams. A batch with missing parts raises
    BatchMismatchError; a SHUTDOWN step emits :class:`Shutdown` whatever came before.
    """

    def __init__(self) -> None:
        self._odom = self._joints = self._wrench = self._target = None

    def reset(self) -> None:
        """Forget parts received so far (a new datagram starts a new batch)."""
        self._odom = self._joints = self._wrench = self._target = None

    def push(self, msgid: int, body) -> SensorFrame | Shutdown | None:
        if msgid == _ODOMETRY_ID:
            self._odom = body
        elif msgid == _ATTITUDE_REPORT_ID:
            self._target = body
        elif msgid == _JOINT_STATE_ID:
            self._joints = body
        elif msgid == _WRENCH_ID:
            self._wrench = body
        elif msgid == _SIM_STEP_ID:
            odom, joints, wrench, target = self._odom, self._joints, self._wrench, self._target
            self._odom = self._joints = self._wrench = self._target = None
            step, time_usec, _, flags = body
            if flags & _SHUTDOWN:
                return Shutdown(step, time_usec / 1e6, StepFlag(flags))
            if odom is None or joints is None or wrench is None:
                missing = [n for n, m in (("ODOMETRY", odom), ("AM_JOINT_STATE", joints), ("AM_WRENCH", wrench))
                           if m is None]  # fmt: skip
                raise BatchMismatchError(f"step {step}: batch incomplete, missing {', '.join(missing)}")
            return sensor_frame_from_fields(odom, joints, wrench, body, target)
        return None


class SetpointAssembler:
    """Pairs a SET_ATTITUDE_TARGET with the setpoint message that follows it, fed ``(msgid, body)``
    of reader records: optional before AM_TORQUE_SETPOINT, required before
    AM_JOINT_TORQUE_SETPOINT (BatchMismatchError without)."""

    def __init__(self) -> None:
        self._attitude = None

    def reset(self) -> None:
        self._attitude = None

    def push(self, msgid: int, body) -> tuple[TorqueSetpoint | AttitudeSetpoint, AttitudeTarget | None] | None:
        if msgid == _ATTITUDE_TARGET_ID:
            self._attitude = body
        elif msgid == _TORQUE_SETPOINT_ID:
            att, self._attitude = self._attitude, None
            sp = setpoint_from_fields(body)
            return sp, (attitude_from_fields(att, sp.step) if att is not None else None)
        elif msgid == _JOINT_TORQUE_SETPOINT_ID:
            att, self._attitude = self._attitude, None
            if att is None:
                raise BatchMismatchError(f"step {body[0]}: AM_JOINT_TORQUE_SETPOINT without SET_ATTITUDE_TARGET")
            asp = attitude_setpoint_from_fields(att, body)
            return asp, asp.attitude
        return None

