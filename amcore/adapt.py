"""Heading admittance: an AM whose pad meets the object's face at an angle turns to face it,
from its own wrist sensor alone (decentralized; pure math: numpy and the compiled
`amcore.law.adapted_reference`, no I/O).

Beyond the paper, whose AMs are aligned with the faces by construction. With a crowned pad
(`amcore.config.PadSpec`, a vertical cylinder of radius R through the face centre {e}), a
pad turned by delta from the face touches it at y_c = R sin(delta) along e_y, so the
filtered wrench on {e} shows the angle through its moment about the pad's vertical axis:

    y_c = m_z / N,  N = -f_x (the normal force),  delta_hat = asin(y_c / R)

(friction at the contact adds R (1 - cos delta) f_y to m_z: 0.2 mm of lever at 5 deg).
The heading reference follows it through a critically damped second-order admittance,

    dpsi'' = omega^2 delta_hat - 2 zeta omega dpsi',

which, as the AM turns (delta_hat -> delta - dpsi), settles on dpsi = delta with natural
frequency omega; outside contact (N below min_normal_n) only the damping acts. The
companion (`companion.pilot`) feeds it the wrench in the grasp phase only, while the object
stands on the table: once it hangs between the pads, two crowned pads leave it free to
turn about the vertical, and its turning would drive the heading. dpsi and its
two derivatives enter eq. Rd as the heading's (psi_d1, psi_d2); the AM's task frame and
CoM path turn with it about the vertical through the pad's contact point on the face
(`adapted`), so that the pad stays where it touches. The CoM path's own
derivatives are turned with it, and dpsi's rates are left out of them (dpsi moves slowly,
omega ~ 2 rad/s; the CoM law's PD takes up the difference).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import law


@dataclass(frozen=True)
class HeadingAdmittance:
    omega_rad_s: float
    zeta: float
    crown_radius_m: float
    min_normal_n: float = 2.0
    max_turn_rad: float = 0.35  # |dpsi| is held within this (20 deg)


class HeadingState(NamedTuple):  # a named tuple: one is made every control step
    dpsi: float = 0.0  # heading correction [rad]
    dpsi_d1: float = 0.0  # its rate [rad/s]
    dpsi_d2: float = 0.0  # its acceleration [rad/s^2], as last computed
    delta_hat: float = 0.0  # the misalignment last measured [rad]


def misalignment(adm: HeadingAdmittance, wrench_E) -> float | None:
    """delta_hat [rad] from a wrench on {e} ([f; m], N and N m), or None out of contact."""
    normal = -float(wrench_E[0])
    if normal < adm.min_normal_n:
        return None
    y_c = float(wrench_E[5]) / normal
    return math.asin(max(-1.0, min(1.0, y_c / adm.crown_radius_m)))


def heading_update(adm: HeadingAdmittance, s: HeadingState, wrench_E, dt: float) -> HeadingState:
    """One step of the admittance (semi-implicit Euler) with the filtered wrench on {e}."""
    w = adm.omega_rad_s
    delta = misalignment(adm, wrench_E)
    drive = 0.0 if delta is None else w * w * delta
    acc = drive - 2.0 * adm.zeta * w * s.dpsi_d1
    rate = s.dpsi_d1 + dt * acc
    dpsi = s.dpsi + dt * rate
    if abs(dpsi) > adm.max_turn_rad:  # held at the bound, at rest there
        dpsi, rate, acc = math.copysign(adm.max_turn_rad, dpsi), 0.0, 0.0
    return HeadingState(dpsi, rate, acc, s.delta_hat if delta is None else delta)


# --- Lateral admittance -----------------------------------------------------------------
#
# Two AMs that hold one object each keep their CoM where their own estimate puts it
# (eq. Com_controller's K_t). With the motion capture's fixed biases their ideas of where the
# object is differ by a few millimetres along the face, and the pads, held by friction,
# turn that disagreement into an internal force: each pushes the object along its face with
# about K_t times its share of the disagreement. Two such pushes on opposite faces are a
# couple about the vertical, which on crowned pads rolls the object between them; each roll
# re-seats the contacts and lets the load creep down the faces (docs/sensing.md).
# The paper's AMs agree exactly on the object, so its law has no such force.
#
# The admittance lets each AM give way to the lateral force its own wrist sensor measures
# (decentralized): with f_y the force the AM pushes the object with along its task frame's
# y axis (-f_y of the wrench on the pad, {e}'s y axis being the face's horizontal), the CoM
# reference moves along that axis by dy,
#
#     dy'' = -omega^2 f_y / K - 2 zeta omega dy',
#
# K the CoM stiffness along that axis (K_t). While the pad sticks, f_y = K (e + dy) for the
# AM's share e of the disagreement, and dy settles on -e with natural frequency omega: the
# internal force goes to zero. Out of contact (normal below min_normal_n) only the damping
# acts, and |dy| stays within max_shift_m.


@dataclass(frozen=True)
class LateralAdmittance:
    omega_rad_s: float
    zeta: float
    stiffness_n_per_m: float  # K_t along the task frame's y axis
    min_normal_n: float = 2.0
    max_shift_m: float = 0.02


class LateralState(NamedTuple):  # a named tuple: one is made every control step
    dy: float = 0.0  # CoM reference shift along the task frame's y axis [m]
    dy_d1: float = 0.0
    dy_d2: float = 0.0
    push_n: float = 0.0  # the lateral force last measured [N]


def lateral_update(adm: LateralAdmittance, s: LateralState, wrench_E, dt: float) -> LateralState:
    """One step (semi-implicit Euler) with the filtered wrench on the pad in {e} ([f; m])."""
    w = adm.omega_rad_s
    in_contact = -float(wrench_E[0]) >= adm.min_normal_n
    push = -float(wrench_E[1]) if in_contact else 0.0
    acc = -w * w * push / adm.stiffness_n_per_m - 2.0 * adm.zeta * w * s.dy_d1
    rate = s.dy_d1 + dt * acc
    dy = s.dy + dt * rate
    if abs(dy) > adm.max_shift_m:  # held at the bound, at rest there
        dy, rate, acc = math.copysign(adm.max_shift_m, dy), 0.0, 0.0
    return LateralState(dy, rate, acc, push if in_contact else s.push_n)


# ----------------------------------------------------------------------------- hover trim
# Beyond the paper (option [options].trim_hz): the motion capture's fixed attitude bias tilts
# the thrust the AM believes level, so in free flight a steady horizontal force of about
# T * (roll, pitch bias) pushes its CoM off the reference, by that force over K_t. Two AMs facing
# each other whose biases tilt them to opposite sides of the formation make a couple about the
# vertical, which in the lift turns the formation and the object between the pads
# (docs/sensing.md). A pilot trims that out in hover; the trim does it from the CoM error: while
# the AM hovers in the approach (its CoM reference still), the CoM reference moves by dr,
#
#     dr' = -omega P_h (r~_c + dr),
#
# r~_c = r_c - r_c,d the law's CoM error against the moved reference, so r~_c + dr is the error
# against the planned one, and P_h keeps the horizontal components. dr settles on -F / K_t
# for a steady force F, which K_t dr then cancels; from the grasp on dr is held.


@dataclass(frozen=True)
class Trim:
    omega_rad_s: float
    max_speed_mps: float = 0.01  # the CoM reference counts as still below this speed
    max_shift_m: float = 0.03


def trim_update(trim: Trim, dr: np.ndarray, r_c_err_W: np.ndarray, ref_speed_mps: float, dt: float) -> np.ndarray:
    """The trim's shift after one step of dt [s] (explicit Euler) in the approach phase; it
    integrates only while the reference moves slower than max_speed_mps."""
    if ref_speed_mps >= trim.max_speed_mps:
        return dr
    e = np.asarray(r_c_err_W, dtype=float) + dr
    e[2] = 0.0
    new = dr - trim.omega_rad_s * dt * e
    n = float(np.hypot(new[0], new[1]))
    return new * (trim.max_shift_m / n) if n > trim.max_shift_m else new


def trim_reference(ref, dr: np.ndarray):
    """`ref` with its CoM path moved by the (constant) trim dr."""
    return ref if not dr.any() else ref._replace(r_c=ref.r_c + dr)


# ------------------------------------------------------------------ the three together
def adapted(ref, frame, dr: np.ndarray, heading: HeadingState | None, pivot_W: np.ndarray,
            lateral: LateralState | None):
    """(ref, task_frame): the mission's reference `ref` and task frame `frame` (amcore.task.TaskFrame)
    with the options applied in the companion's order: the trim's shift dr (`trim_reference`),
    the heading's turn about the vertical through pivot_W (the CoM path and its derivatives
    turned, the heading and its rates corrected, y_d unchanged since it lives in the task
    frame, which turns with it; heading: its state, None: the admittance is off) and the
    lateral shift by dy along the turned frame's y axis, dy's two rates added to the path's
    (lateral: None: off). task_frame is None with the heading
    off (the law then takes the mission's frame).

    The arithmetic is one call of `amcore.law.adapted_reference` (with every option acting,
    ~8 us a step against ~25 us for numpy's small operations, benchmarks/bench_controller.py).
    Its readable reference, each step in numpy, is tests/amcore/reference_adapt.py."""
    turn, shift = heading is not None, lateral is not None
    h = heading if turn else _AT_REST
    s = lateral if shift else _NOT_SHIFTED
    if h.dpsi == 0.0 and h.dpsi_d1 == 0.0 and s.dy == 0.0 and s.dy_d1 == 0.0:  # at rest (before contact): the trim alone
        return trim_reference(ref, dr), (frame if turn else None)
    r, R_WT, p_WT, H_TW, e_y_W = law.adapted_reference(
        np.array(ref[:5]), dr, turn, h.dpsi, h.dpsi_d1, pivot_W, shift, s.dy, s.dy_d1, s.dy_d2, frame.R_WT, frame.p_WT)
    psi = ref[5:8]
    if turn and not (h.dpsi == 0.0 and h.dpsi_d1 == 0.0):  # the heading and its rates corrected
        psi = (ref.psi + h.dpsi, ref.psi_d1 + h.dpsi_d1, ref.psi_d2 + h.dpsi_d2)
    ref = type(ref)(r[0], r[1], r[2], r[3], r[4], *psi, ref.y, ref.y_d1, ref.y_d2)
    if not turn:
        return ref, None
    if h.dpsi == 0.0:  # not turned: the mission's frame itself
        return ref, frame
    return ref, type(frame).with_transform(R_WT, p_WT, H_TW, e_y_W)


_AT_REST = HeadingState()
_NOT_SHIFTED = LateralState()
