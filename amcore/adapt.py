"""Heading admittance: an AM whose pad meets the object's face at an angle turns to face it,
from its own wrist sensor alone (decentralized; pure: numpy only).

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
(`turn_reference`), so that the pad stays where it touches. The CoM path's own
derivatives are turned with it, and dpsi's rates are left out of them (dpsi moves slowly,
omega ~ 2 rad/s; the CoM law's PD takes up the difference).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .so3 import Rz


@dataclass(frozen=True)
class HeadingAdmittance:
    omega_rad_s: float
    zeta: float
    crown_radius_m: float
    min_normal_n: float = 2.0
    max_turn_rad: float = 0.35  # |dpsi| is held within this (20 deg)


@dataclass(frozen=True)
class HeadingState:
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


def turn_reference(ref, s: HeadingState, pivot_W: np.ndarray):
    """`ref` (amcore.control.Reference) turned by the heading correction about the vertical
    through pivot_W: CoM path and its derivatives turned, heading and its rates corrected;
    y_d is unchanged (it lives in the task frame, which turns with it: `turn_frame`)."""
    if s.dpsi == 0.0 and s.dpsi_d1 == 0.0:
        return ref
    R = Rz(s.dpsi)
    return type(ref)(pivot_W + R @ (ref.r_c - pivot_W), R @ ref.r_c_d1, R @ ref.r_c_d2, R @ ref.r_c_d3,
                     R @ ref.r_c_d4, ref.psi + s.dpsi, ref.psi_d1 + s.dpsi_d1, ref.psi_d2 + s.dpsi_d2,
                     ref.y, ref.y_d1, ref.y_d2)


def turn_frame(frame, s: HeadingState, pivot_W: np.ndarray):
    """The task frame (amcore.task.TaskFrame) turned by the correction about pivot_W."""
    if s.dpsi == 0.0:
        return frame
    R = Rz(s.dpsi)
    return type(frame)(R_WT=R @ frame.R_WT, p_WT=pivot_W + R @ (frame.p_WT - pivot_W))
