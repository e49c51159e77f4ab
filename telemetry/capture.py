"""Binary samples built in two steps: a copy on the caller's thread, the rest on the sender's (pure).

The caller (a control step, a physics step) must copy the values before it goes on, as it
cannot know whether the arrays it was handed are reused by the next step. It copies them as
they are: `b"".join` takes each float64 array's bytes in one C call, with no Python call per
array, into the sample's ROS 1 layout (telemetry.binary), header and counts packed around
them. What is left, the quaternions of the rotation matrices, is done by `finish` on the
publisher's sender thread. Measured in a control loop, right after a controller step (the
caches are cold then: every figure is ~3x its back-to-back microbenchmark), the caller's
part of a controller sample takes ~5 us this way, where packing the whole sample with one
struct from `tolist()`s took ~10 us and building the JSON dict ~12 us. The quaternions cost
about as much CPU on the sender's thread (~4 us); what this saves is the control thread's time.

    pending = capture.controller(t, phase, diag, cmd, sysid=4)   # (finish, pre) or the sample's bytes
    publisher.publish(key, pending)                               # the sender calls finish(pre)
    capture.finished(pending)                                     # the sample's bytes, now

A pre-sample is the sample's layout with the two quaternion fields (float64[4]) replaced by
the 18 numbers of their rotation matrices, row by row (for AmTruth, after p_WE). Arrays that
are not C-contiguous float64 of the expected lengths (a list, float32, y_d longer than y)
take the literal path, which gives the same bytes: telemetry.binary.from_dict of the JSON
builder's payload. (An integer array of the right length would pass the length check: the
arrays are taken to be float64, as numpy computes them.)
"""
from __future__ import annotations

import struct
import sys
from typing import Callable, Iterator, Union

from . import schema
from .binary import AM_TRUTH, CONTACT, CONTROLLER, OBJECT, from_dict
from .ros1 import string_array
from .schema import Channel, Keys, quat_wxyz

Pending = Union[bytes, tuple[Callable[[bytes], bytes], bytes]]

_U32 = struct.Struct("<I")
_F64 = struct.Struct("<d")
_RR = struct.Struct("<18d")  # two rotation matrices, row by row
_QQ = struct.Struct("<8d")
_QUAT_BYTES, _R_BYTES = 4 * 8, 9 * 8
_LITTLE = sys.byteorder == "little"  # arrays are copied in native order; ROS 1 is little-endian


def finished(pending: Pending) -> bytes:
    """The sample's bytes of what a capture function returned."""
    return pending[0](pending[1]) if type(pending) is tuple else pending


def _quats(pre: bytes, at: int) -> bytes:
    """The quaternions of the two row-major rotation matrices one after the other at `at`."""
    r = _RR.unpack_from(pre, at)
    return _QQ.pack(*quat_wxyz((r[0:3], r[3:6], r[6:9])), *quat_wxyz((r[9:12], r[12:15], r[15:18])))


# ----------------------------------------------------------------------------- controller
_controller_layouts: dict[tuple[int, int, str], tuple] = {}
_CONTROLLER_TAIL = struct.Struct("<dd??")  # sigma_min_J3, damping, com_err_saturated, y_err_saturated


def _controller_layout(n_y: int, n_q: int, phase: str) -> tuple:
    ph = phase.encode("utf-8")
    lengths = {"phase": len(ph), "y": n_y, "y_d": n_y, "y_err": n_y, "F_y": n_y, "tau_q_nm": n_q}
    size = CONTROLLER.struct(lengths).size + 2 * (_R_BYTES - _QUAT_BYTES)
    return struct.Struct(f"<dQII{len(ph)}s"), ph, _U32.pack(n_y), _U32.pack(n_q), size


def _finish_controller(pre: bytes) -> bytes:
    at = 24 + _U32.unpack_from(pre, 20)[0] + 5 * 3 * 8  # after t, seq, sysid, phase, r_c .. e_w
    return pre[:at] + _quats(pre, at) + pre[at + 2 * _R_BYTES:]


def controller(t_s: float, phase: str, diag, cmd, sysid: int = 0) -> Pending:
    """The <p>/am/<sysid>/controller sample of amcore.control's Diagnostics and Command (the
    fields schema.controller_sample reads), as (finish, pre-sample); seq is left at 0 (the
    publisher stamps it)."""
    n_y, n_q = len(diag.y), len(cmd.tau_q_nm)
    layout = _controller_layouts.get((n_y, n_q, phase))
    if layout is None:
        layout = _controller_layouts.setdefault((n_y, n_q, phase), _controller_layout(n_y, n_q, phase))
    head, ph, c_y, c_q, size = layout
    try:
        pre = b"".join((
            head.pack(t_s, 0, sysid, len(ph), ph),
            diag.r_c, diag.r_c_d, diag.r_c_err, diag.e_R, diag.e_w, diag.R_WB, diag.R_d,
            c_y, diag.y, c_y, diag.y_d, c_y, diag.y_err, c_y, diag.F_y,
            diag.F_rc, diag.wrench_W_filtered, diag.wrench_E_filtered, _F64.pack(cmd.thrust_n), cmd.tau_B_nm,
            c_q, cmd.tau_q_nm,
            _CONTROLLER_TAIL.pack(diag.sigma_min_J3, diag.damping, diag.com_err_saturated, diag.y_err_saturated)))
        if len(pre) == size and _LITTLE:
            return _finish_controller, pre
    except (TypeError, ValueError, BufferError, struct.error):  # not arrays, not contiguous, not numbers
        pass
    return from_dict(Channel.CONTROLLER, schema.controller_sample(t_s, phase, diag, cmd, sysid=sysid))


# ----------------------------------------------------------------------------- ground truth
_TRUTH_HEAD = struct.Struct("<dQI")
_COUNTERS = struct.Struct("<QQ")
_truth_sizes: dict[int, int] = {}


def _finish_truth(pre: bytes) -> bytes:
    # pre-sample: t, seq, sysid (20 bytes), p_WB, p_WE (24 each), R_WB, R_WE (72 each), the rest as in the sample
    q = _quats(pre, 68)
    return pre[:44] + q[:_QUAT_BYTES] + pre[44:68] + q[_QUAT_BYTES:] + pre[68 + 2 * _R_BYTES:]


def am_truth(t_s: float, sysid: int, am) -> Pending:
    """The <p>/sim/am/<sysid>/truth sample of a simulator AmTruth (duck-typed as for
    schema.am_truth_sample), as (finish, pre-sample)."""
    joints = getattr(am, "p_W_joints", ())
    n = len(joints)
    size = _truth_sizes.get(n)
    if size is None:
        size = _truth_sizes.setdefault(n, AM_TRUTH.struct({"p_W_joints": 3 * n}).size + 2 * (_R_BYTES - _QUAT_BYTES))
    try:
        pre = b"".join((_TRUTH_HEAD.pack(t_s, 0, sysid), am.p_WB, am.p_WE, am.R_WB, am.R_WE, _U32.pack(3 * n), *joints,
                        _COUNTERS.pack(getattr(am, "rotor_saturated_steps", 0),
                                       getattr(am, "joint_saturated_steps", 0))))
        if len(pre) == size and _LITTLE:
            return _finish_truth, pre
    except (TypeError, ValueError, BufferError, struct.error):
        pass
    return from_dict(Channel.AM_TRUTH, schema.am_truth_sample(t_s, sysid, am))


_CONTACT_HEAD = struct.Struct("<dQId")  # t, seq, sysid, normal_force_n
_CONTACT_SIZE = CONTACT.struct(stop="pad_other_contacts").size
_OBJECT_HEAD = struct.Struct("<dQ")
_OBJECT_SIZE = OBJECT.struct(stop="touching").size
_strings_cache: dict[tuple, bytes] = {}


def _strings(items) -> bytes:
    """string[] of body names (a handful of distinct tuples per run, hence the cache)."""
    try:
        out = _strings_cache.get(items)
    except TypeError:  # a list: not hashable
        return string_array(items)
    if out is None:
        if len(_strings_cache) > 1024:
            _strings_cache.clear()
        out = _strings_cache[items] = string_array(items)
    return out


def contact(t_s: float, sysid: int, am) -> bytes:
    """The <p>/sim/am/<sysid>/contact sample of a simulator AmTruth (no quaternion: done now)."""
    c = am.pad_object_contact
    try:
        head = b"".join((_CONTACT_HEAD.pack(t_s, 0, sysid, c.normal_force_n), c.normal_W, c.tangential_force_W,
                         c.point_W, _U32.pack(c.n_points)))
        if len(head) == _CONTACT_SIZE and _LITTLE:
            return head + _strings(am.pad_other_contacts) + _strings(am.base_contacts)
    except (TypeError, ValueError, BufferError, struct.error):
        pass
    return from_dict(Channel.CONTACT, schema.contact_sample(t_s, sysid, am))


def object_truth(t_s: float, obj) -> bytes:
    """The <p>/sim/object sample of a simulator ObjectTruth (its quaternion is given: done now)."""
    try:
        head = b"".join((_OBJECT_HEAD.pack(t_s, 0), obj.p_WO, obj.quat_WO_wxyz, obj.v_WO, obj.w_WO))
        if len(head) == _OBJECT_SIZE and _LITTLE:
            return head + _strings(obj.touching)
    except (TypeError, ValueError, BufferError, struct.error):
        pass
    return from_dict(Channel.OBJECT, schema.object_sample(t_s, obj))


def ground_truth(gt, keys: Keys) -> Iterator[tuple[str, Pending]]:
    """(key, sample) for one simulator GroundTruth, in schema.ground_truth_samples' order."""
    t = gt.time_s
    for sysid, am in gt.ams.items():
        yield keys.am_truth(sysid), am_truth(t, sysid, am)
        yield keys.contact(sysid), contact(t, sysid, am)
    yield keys.object, object_truth(t, gt.object)
