"""The robust options' shaping of the reference in numpy, one function per step: the readable
reference of amcore.law.adapted_reference, which amcore.adapt.adapted calls (the trim's shift,
the heading's turn about the vertical through the contact, the lateral shift along the turned
frame's y axis)."""
from __future__ import annotations

import numpy as np

from amcore.adapt import HeadingState, LateralState, trim_reference
from amcore.so3 import Rz


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


def shift_reference(ref, s: LateralState, axis_W: np.ndarray):
    """`ref` with its CoM path moved by dy along axis_W (unit, horizontal), dy's two rates
    added to the path's; the higher derivatives are left as they are (dy moves slowly)."""
    if s.dy == 0.0 and s.dy_d1 == 0.0:
        return ref
    return ref._replace(r_c=ref.r_c + s.dy * axis_W, r_c_d1=ref.r_c_d1 + s.dy_d1 * axis_W,
                        r_c_d2=ref.r_c_d2 + s.dy_d2 * axis_W)


def adapted(ref, frame, dr: np.ndarray, heading: HeadingState | None, pivot_W: np.ndarray,
            lateral: LateralState | None):
    """amcore.adapt.adapted, step by step."""
    ref = trim_reference(ref, dr)
    task_frame = None
    if heading is not None:
        ref = turn_reference(ref, heading, pivot_W)
        task_frame = turn_frame(frame, heading, pivot_W)
    if lateral is not None:
        ref = shift_reference(ref, lateral, (frame if task_frame is None else task_frame).R_WT[:, 1])
    return ref, task_frame
