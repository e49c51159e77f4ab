"""Binary samples built in two steps: a copy on the caller's thread, the rest on the sender's (pure).

The caller (a control step, a physics step) must copy the values before it goes on, as it
cannot know whether the arrays it was handed are reused by the next step. It copies them as
they are, in as few pieces as it can: `b"".join` takes each float64 array's bytes in one C
call. A controller step's Diagnostics from the compiled law are views of one array
(amcore.control.PACKED): its prefix up to the guard flags is one piece, and with what the
law does not return (r_c_d, R_WB, y_d, the command) the pre-sample is 8 pieces, where the
fields one by one are some 25. What is left, the ROS 1 layout (telemetry.binary) with the
quaternions of the rotation matrices, is done on the publisher's sender thread by the
layout's `Finisher`, one compiled call (telemetry.kernels) for all the pre-samples of a
wake-up. Measured in a 1 kHz control loop after each controller step (caches cold: every
figure is ~3x its back-to-back microbenchmark), docs/telemetry.md "Measured".

    pending = capture.controller(t, phase, diag, cmd, sysid=4)   # (finisher, pre) or the sample's bytes
    publisher.publish(key, pending)                               # the sender calls finisher.many([pre, ...])
    capture.finished(pending)                                     # the sample's bytes, now

A pre-sample starts with the sample's header (t, seq = 0, and for the controller and truth
samples sysid and the phase string), padded to 8 bytes, then float64 numbers in an order of
its layout's (the Finisher's program says where each goes). The packed path reads the
fields the sample needs from the array only while they are the array's: a Diagnostics field
reassigned to another array or value takes the field-by-field path (writing into a field's
view writes into the array: the same bytes). Arrays that are not C-contiguous float64 of the
expected lengths (a list, float32, y_d longer than y) take the literal path, which gives the
same bytes: telemetry.binary.from_dict of the JSON builder's payload. (An integer array of
the right length would pass the length check: the arrays are taken to be float64, as numpy
computes them.)
"""
from __future__ import annotations

import struct
import sys
from typing import Callable, Iterator, Sequence, Union

import numpy as np

from . import kernels, schema
from .binary import CONTACT, OBJECT, from_dict
from .ros1 import string_array
from .schema import Channel, Keys

Pending = Union[bytes, tuple[Callable[[bytes], bytes], bytes]]

_U32 = struct.Struct("<I")
_F64 = struct.Struct("<d")
_LITTLE = sys.byteorder == "little"  # arrays are copied in native order; ROS 1 is little-endian


def finished(pending: Pending) -> bytes:
    """The sample's bytes of what a capture function returned."""
    return pending[0](pending[1]) if type(pending) is tuple else pending


class Finisher:
    """The samples of one pre-sample layout: a program of byte copies, quaternions and flags
    (telemetry.kernels) into a template holding what every sample of the layout has in
    common (the lengths of its variable-length fields)."""

    def __init__(self, pre_size: int):
        self.pre_size = pre_size
        self._ops: list[list[int]] = []
        self._template = bytearray()
        self.program = np.zeros((0, 4), np.int64)
        self.template = np.zeros(0, np.uint8)

    # building the program, field after field of the sample (`at` is the sample's end so far)
    def copy(self, src: int, n: int) -> None:
        """n bytes from the pre-sample's byte src."""
        at, last = len(self._template), self._ops[-1] if self._ops else None
        if last and last[0] == kernels.COPY and last[1] + last[3] == at and last[2] + last[3] == src:
            last[3] += n  # contiguous in both: one copy
        else:
            self._ops.append([kernels.COPY, at, src, n])
        self._template += bytes(n)

    def quaternion(self, src: int) -> None:
        """float64[4] (w, x, y, z) of the row-major float64 3x3 at the pre-sample's byte src."""
        self._ops.append([kernels.QUATERNION, len(self._template), src, 72])
        self._template += bytes(32)

    def flag(self, src: int) -> None:
        """bool: the float64 at the pre-sample's byte src is not zero."""
        self._ops.append([kernels.FLAG, len(self._template), src, 8])
        self._template += bytes(1)

    def constant(self, data: bytes) -> None:
        self._template += data

    def done(self) -> "Finisher":
        self.program = np.array(self._ops, np.int64).reshape(-1, 4)
        self.template = np.frombuffer(bytes(self._template), np.uint8)
        return self

    # finishing
    def many(self, pres: Sequence[bytes]) -> list[bytes]:
        """The samples of pre-samples of this layout, in one compiled call. ValueError if their
        sizes are not the layout's."""
        k, size = len(pres), self.template.size
        pre = np.frombuffer(b"".join(pres), np.uint8).reshape(k, self.pre_size)
        out = np.empty((k, size), np.uint8)
        out[:] = self.template
        kernels.assemble(pre, out, self.program)
        data = out.tobytes()
        return [data[i:i + size] for i in range(0, k * size, size)]

    def __call__(self, pre: bytes) -> bytes:
        return self.many((pre,))[0]


def _padded_head(fmt: str) -> struct.Struct:
    """A pre-sample's header: the sample's own, padded so that the numbers after it are aligned."""
    size = struct.calcsize(fmt)
    return struct.Struct(f"{fmt}{-size % 8}x")


# ----------------------------------------------------------------------------- controller
class _ControllerLayout:
    """A controller pre-sample's layout: its header, size and finisher, for one source (the
    law's packed array, or the fields one by one), task dimension n_y, n_q joints and phase.
    columns: where each number the sample needs starts in the pre-sample's float64 block."""

    def __init__(self, phase: str, n_y: int, n_q: int, columns: dict[str, int], n_numbers: int):
        self.ph = phase.encode("utf-8")
        self.head = _padded_head(f"<dQII{len(self.ph)}s")
        h = self.head.size
        f = Finisher(h + 8 * n_numbers)
        f.copy(0, 24 + len(self.ph))  # t, seq, sysid, phase

        def floats(name: str, k: int) -> None:
            f.copy(h + 8 * columns[name], 8 * k)

        for name in ("r_c", "r_c_d", "r_c_err", "e_R", "e_w"):
            floats(name, 3)
        f.quaternion(h + 8 * columns["R_WB"])  # q_WB
        f.quaternion(h + 8 * columns["R_d"])  # q_WB_d
        for name in ("y", "y_d", "y_err", "F_y"):
            f.constant(_U32.pack(n_y))
            floats(name, n_y)
        for name, k in (("F_rc", 3), ("wrench_W", 6), ("wrench_E", 6), ("thrust_n", 1), ("tau_B_nm", 3)):
            floats(name, k)
        f.constant(_U32.pack(n_q))
        for name, k in (("tau_q_nm", n_q), ("sigma_min_J3", 1), ("damping", 1)):
            floats(name, k)
        f.flag(h + 8 * columns["com_err_saturated"])
        f.flag(h + 8 * columns["y_err_saturated"])
        self.finisher = f.done()
        self.size = f.pre_size


def _columns(order: Sequence[tuple[str, int]], start: int = 0) -> tuple[dict[str, int], int]:
    """Column of each (name, count) laid out one after the other from `start`; and the end."""
    out, at = {}, start
    for name, k in order:
        out[name] = at
        at += k
    return out, at


# the field-by-field source: Diagnostics built by keyword (the baseline controller, amcore.offboard's tests)
def _fields_order(n_y: int, n_q: int) -> list[tuple[str, int]]:
    return [("r_c", 3), ("r_c_d", 3), ("r_c_err", 3), ("e_R", 3), ("e_w", 3), ("R_WB", 9), ("R_d", 9),
            ("y", n_y), ("y_d", n_y), ("y_err", n_y), ("F_y", n_y), ("F_rc", 3), ("wrench_W", 6), ("wrench_E", 6),
            ("thrust_n", 1), ("tau_B_nm", 3), ("tau_q_nm", n_q), ("sigma_min_J3", 1), ("damping", 1),
            ("com_err_saturated", 1), ("y_err_saturated", 1)]


_FLAGS = struct.Struct("<4d")  # sigma_min_J3, damping, and the two flags as 1.0 / 0.0
_field_layouts: dict[tuple[int, int, str], _ControllerLayout] = {}


def _field_layout(n_y: int, n_q: int, phase: str) -> _ControllerLayout:
    layout = _field_layouts.get((n_y, n_q, phase))
    if layout is None:
        layout = _field_layouts.setdefault((n_y, n_q, phase),
                                           _ControllerLayout(phase, n_y, n_q, *_columns(_fields_order(n_y, n_q))))
    return layout


def _controller_of_fields(t_s: float, phase: str, diag, cmd, sysid: int) -> Pending | None:
    n_y, n_q = len(diag.y), len(cmd.tau_q_nm)
    layout = _field_layout(n_y, n_q, phase)
    pre = b"".join((
        layout.head.pack(t_s, 0, sysid, len(layout.ph), layout.ph),
        diag.r_c, diag.r_c_d, diag.r_c_err, diag.e_R, diag.e_w, diag.R_WB, diag.R_d,
        diag.y, diag.y_d, diag.y_err, diag.F_y, diag.F_rc, diag.wrench_W_filtered, diag.wrench_E_filtered,
        _F64.pack(cmd.thrust_n), cmd.tau_B_nm, cmd.tau_q_nm,
        _FLAGS.pack(diag.sigma_min_J3, diag.damping, 1.0 if diag.com_err_saturated else 0.0,
                    1.0 if diag.y_err_saturated else 0.0)))
    return (layout.finisher, pre) if len(pre) == layout.size else None


# the packed source: Diagnostics of amcore.control.step, views of the compiled law's one array
_FROM_PACKED_ARRAYS = frozenset(("r_c", "r_c_err", "e_R", "e_w", "R_d", "y", "y_err", "F_y", "F_rc",
                                 "wrench_W_filtered", "wrench_E_filtered"))
_FROM_PACKED_SCALARS = ("sigma_min_J3", "damping", "com_err_saturated", "y_err_saturated")  # guard[0..3]
_FROM_PACKED = _FROM_PACKED_ARRAYS | frozenset(_FROM_PACKED_SCALARS)


class _PackedLayout(_ControllerLayout):
    def __init__(self, phase: str, n: int, n_q: int):
        from amcore.control import packed_slices  # imported already where such Diagnostics come from

        at = {name: sl.start for name, (sl, _) in packed_slices(n).items()}
        self.end = packed_slices(n)["guard"][0].stop  # what the sample needs ends with the guard
        self.guard = at["guard"]
        columns, n_numbers = _columns((("r_c_d", 3), ("R_WB", 9), ("y_d", n), ("thrust_n", 1), ("tau_B_nm", 3),
                                       ("tau_q_nm", n_q)), start=self.end)
        columns.update({k: at[k] for k in ("r_c", "r_c_err", "e_R", "e_w", "R_d", "y", "y_err", "F_y")},
                       F_rc=at["wrench_W_filtered"], wrench_W=at["wrench_W_filtered"],
                       wrench_E=at["wrench_E_filtered"],
                       **{k: at["guard"] + i for i, k in enumerate(_FROM_PACKED_SCALARS)})
        super().__init__(phase, n, n_q, columns, n_numbers)


_packed_layouts: dict[tuple[int, int, int, str], _PackedLayout] = {}
_task_dimension: dict[int, int] = {}


def _n_of_packed(size: int) -> int:
    """The task dimension n of a packed array of `size` numbers (-1 if none fits)."""
    n = _task_dimension.get(size)
    if n is None:
        from amcore.control import packed_slices

        fits = [k for k in range(64) if packed_slices(k)["J_e_xi"][0].stop == size]
        n = _task_dimension[size] = fits[0] if fits else -1
    return n


def _intact(diag, packed: np.ndarray, guard: int) -> bool:
    """Whether the fields the sample reads from `packed` still are the array's: a field read
    before is a view of it (an array) or equal to it (a number); one reassigned is not."""
    own = diag.__dict__
    for name in _FROM_PACKED.intersection(own):
        v = own[name]
        if name in _FROM_PACKED_ARRAYS:
            if type(v) is not np.ndarray or v.base is not packed:
                return False
        elif v != (packed[guard + _FROM_PACKED_SCALARS.index(name)] if name in ("sigma_min_J3", "damping")
                   else bool(packed[guard + _FROM_PACKED_SCALARS.index(name)])):
            return False
    return True


def _controller_of_packed(t_s: float, phase: str, diag, cmd, sysid: int, packed: np.ndarray) -> Pending | None:
    n, n_q = _n_of_packed(packed.size), len(cmd.tau_q_nm)
    layout = _packed_layouts.get((packed.size, n, n_q, phase))
    if layout is None:
        if n < 0:
            return None
        layout = _packed_layouts.setdefault((packed.size, n, n_q, phase), _PackedLayout(phase, n, n_q))
    if not _intact(diag, packed, layout.guard):
        return None
    pre = b"".join((layout.head.pack(t_s, 0, sysid, len(layout.ph), layout.ph), packed[:layout.end],
                    diag.r_c_d, diag.R_WB, diag.y_d, _F64.pack(cmd.thrust_n), cmd.tau_B_nm, cmd.tau_q_nm))
    return (layout.finisher, pre) if len(pre) == layout.size else None


def controller(t_s: float, phase: str, diag, cmd, sysid: int = 0) -> Pending:
    """The <p>/am/<sysid>/controller sample of amcore.control's Diagnostics and Command (the
    fields schema.controller_sample reads), as (finisher, pre-sample); seq is left at 0 (the
    publisher stamps it)."""
    if _LITTLE:
        try:
            packed = diag._packed
        except AttributeError:  # built by keyword
            packed = None
        try:
            pending = None
            if packed is not None:
                pending = _controller_of_packed(t_s, phase, diag, cmd, sysid, packed)
            if pending is None:
                pending = _controller_of_fields(t_s, phase, diag, cmd, sysid)
            if pending is not None:
                return pending
        except (TypeError, ValueError, BufferError, struct.error):  # not arrays, not contiguous, not numbers
            pass
    return from_dict(Channel.CONTROLLER, schema.controller_sample(t_s, phase, diag, cmd, sysid=sysid))


# ----------------------------------------------------------------------------- ground truth
_TRUTH_HEAD = _padded_head("<dQI")
_COUNTERS = struct.Struct("<QQ4Qdd")  # rotor, joint, per-axis saturation counts; rotor fractions
_ESTIMATE = struct.Struct("<13d")  # p_WB_est, q_WB_est, v_B_est, w_B_est
_NO_ESTIMATE = (0.0,) * 13
_truth_finishers: dict[int, Finisher] = {}


def _truth_finisher(n: int) -> Finisher:
    """Pre-sample: the header (t, seq, sysid, padded), p_WB, p_WE, R_WB, R_WE, the n joint
    origins, the two counters (uint64), the reported base state (13 doubles)."""
    h = _TRUTH_HEAD.size
    f = Finisher(h + 8 * (24 + 3 * n) + _COUNTERS.size + 8 * 13)
    f.copy(0, 20)  # t, seq, sysid
    f.copy(h, 24)  # p_WB
    f.quaternion(h + 48)  # q_WB
    f.copy(h + 24, 24)  # p_WE
    f.quaternion(h + 120)  # q_WE
    f.constant(_U32.pack(3 * n))
    f.copy(h + 192, 24 * n + _COUNTERS.size + 8 * 13)  # p_W_joints, the counters, the estimate
    return f.done()


def am_truth(t_s: float, sysid: int, am) -> Pending:
    """The <p>/sim/am/<sysid>/truth sample of a simulator AmTruth (duck-typed as for
    schema.am_truth_sample), as (finisher, pre-sample)."""
    joints = getattr(am, "p_W_joints", ())
    n = len(joints)
    finisher = _truth_finishers.get(n)
    if finisher is None:
        finisher = _truth_finishers.setdefault(n, _truth_finisher(n))
    try:
        est = getattr(am, "estimate", ()) or _NO_ESTIMATE
        pre = b"".join((_TRUTH_HEAD.pack(t_s, 0, sysid), am.p_WB, am.p_WE, am.R_WB, am.R_WE, *joints,
                        _COUNTERS.pack(getattr(am, "rotor_saturated_steps", 0),
                                       getattr(am, "joint_saturated_steps", 0),
                                       *getattr(am, "axis_saturated_steps", (0, 0, 0, 0)),
                                       getattr(am, "rotor_fraction_max", 0.0),
                                       getattr(am, "rotor_fraction_min", 0.0)), _ESTIMATE.pack(*est)))
        if len(pre) == finisher.pre_size and _LITTLE:
            return finisher, pre
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
