"""A control step's inputs from the latest samples of each source (pure: no I/O).

On the wall clock the controller's inputs come from sources with their own rates and ages:
the autopilot's estimate (ODOMETRY: position and velocity, at PX4's estimator rate, 30-100 Hz),
its attitude and rates (ATTITUDE_QUATERNION, up to the control rate), the servos (joint
angles, rates and measured torques, read by the step itself), the wrist F/T sensor and the
target the autopilot flies (ATTITUDE_TARGET). Every sample carries its time in one time base
(the autopilot's boot time, through TIMESYNC), so a step knows how old each input is.

`predict_base` carries the estimate forward over its age at constant twist, the standard
zero-order prediction of a delayed state measurement:

    p_WB(t) = p_WB(t_s) + R_WB(t_s) v_B (t - t_s),   R_WB(t) = R_WB(t_s) exp(hat(w_B) (t - t_s)),

so that a 100 Hz estimate read by a 250 Hz loop does not hold still for two or three steps and
then jump. It is a sampling correction, not a change to the law: with ages of zero it returns
the sample. `StalenessLimits` are the ages beyond which a step does not trust a source.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amcore.so3 import R_to_quat_wxyz, exp_so3, quat_wxyz_to_R


@dataclass(frozen=True)
class BaseEstimate:
    """The autopilot's estimate of the base, in this stack's frames: p_WB [m] in W (ENU),
    q_WB (w, x, y, z, ENU <- FLU), v_B [m/s] and w_B [rad/s] in B (FLU), at t_us (autopilot time)."""

    t_us: float
    p_WB: tuple[float, float, float]
    q_WB_wxyz: tuple[float, float, float, float]
    v_B: tuple[float, float, float]
    w_B: tuple[float, float, float]


@dataclass(frozen=True)
class StalenessLimits:
    """Ages [s] beyond which a step does not use a source: `hold_s` the step holds its last
    setpoint (the autopilot keeps flying it); `handback_s` the companion hands the vehicle back
    to the autopilot (HOLD) and yields, as a PX4 companion must before COM_OF_LOSS_T runs out."""

    odometry_hold_s: float = 0.1  # three of PX4's default 30 Hz ODOMETRY periods
    attitude_hold_s: float = 0.05
    joints_hold_s: float = 0.02  # five periods of the 250 Hz loop: the servo bus is read every step
    wrench_hold_s: float = 0.05
    handback_s: float = 0.5  # PX4's COM_OF_LOSS_T default is 1 s: hand back well before it fires

    def hold_limit_s(self, source: str) -> float:
        return getattr(self, f"{source}_hold_s")


def predict_base(est: BaseEstimate, t_us: float, attitude: BaseEstimate | None = None) -> BaseEstimate:
    """The base at autopilot time t_us: position and velocity from `est`, attitude and rates
    from `attitude` (a fresher ATTITUDE_QUATERNION sample) if given, each carried over its own
    age at constant twist (module docstring). A sample from the future (clock noise) is used as is."""
    att = attitude if attitude is not None else est
    R0 = quat_wxyz_to_R(np.asarray(att.q_WB_wxyz, dtype=float))
    w_B = np.asarray(att.w_B, dtype=float)
    a_att = max(0.0, (t_us - att.t_us) * 1e-6)
    R = R0 @ exp_so3(w_B * a_att) if a_att > 0.0 else R0
    a_pos = max(0.0, (t_us - est.t_us) * 1e-6)
    R_pos = quat_wxyz_to_R(np.asarray(est.q_WB_wxyz, dtype=float))
    v_B = np.asarray(est.v_B, dtype=float)
    v_W = R_pos @ v_B
    p = np.asarray(est.p_WB, dtype=float) + v_W * a_pos
    v_B_now = R.T @ v_W  # the same world velocity, in the body frame it is read in now
    q = R_to_quat_wxyz(R)
    return BaseEstimate(t_us, tuple(p.tolist()), tuple(q.tolist()), tuple(v_B_now.tolist()), tuple(w_B.tolist()))


def frame_values(base: BaseEstimate, q, qdot, wrench_E) -> list[float]:
    """The sensor frame's values (amlink.types.sensor_frame_from_wire's layout):
    p_WB, q_WB (w x y z), v_B, w_B, q, qdot, wrench_E (force, torque on {e})."""
    vals = [*base.p_WB, *base.q_WB_wxyz, *base.v_B, *base.w_B, *q, *qdot, *wrench_E]
    if not all(math.isfinite(x) for x in vals):
        raise ValueError("non-finite value among the step's inputs")
    return [float(x) for x in vals]
