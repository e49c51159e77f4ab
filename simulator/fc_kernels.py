"""The emulated autopilot's attitude and rate loops (numba, as amcore.law), one small kernel
per step of `simulator.flight_controller`'s module doc. Their readable reference, the same
equations in plain Python, is tests/simulator/reference_flight_controller.py, which
tests/simulator/test_fc_kernels.py compares them with.

`FlightController` keeps its loops' state in one array (`S_*` offsets) and its constants in
another (`P_*`); `rate_loops` runs steps 1 and 2 of the module doc of
`simulator.flight_controller` (attitude P loop, rate PID with the gyro filters); the
allocation (step 3) stays in `amcore.allocation`, shared with torque mode.

`_min` and `_max` keep their first argument on ties and NaNs, as Python's min and max do, and
`_square` is C's pow(x, 2.0), as Python's `x ** 2`: the reference and the kernels take the same
steps. The quaternion helpers are amcore.quat_kernels'.
"""
from __future__ import annotations

import math

import numpy as np

from amcore.jit import kernel
from amcore.quat_kernels import quat_canonical, quat_conj, quat_mul, quat_normalized, quat_z_axis

I_ATTENUATION_RAD_S = math.radians(400.0)  # RateControl::updateIntegral's i_factor scale

# the loops' state: each filter's two delays per axis, the rate integral, the last gyro
# sample, the allocation's saturation per axis and direction, whether the loops have started
S_GYRO_D1, S_GYRO_D2, S_DGYRO_D1, S_DGYRO_D2 = 0, 3, 6, 9
S_RATE_INT, S_W_PREV, S_SAT_POS, S_SAT_NEG, S_STARTED = 12, 15, 18, 21, 24
N_S = 25
# the constants: each filter's (active, b0, b1, b2, a1, a2), then per axis the gains and limits
P_GYRO, P_DGYRO = 0, 6
P_ATT_P, P_RATE_MAX, P_GAIN_P, P_GAIN_I, P_GAIN_D, P_GAIN_FF, P_INT_LIM = 12, 15, 18, 21, 24, 27, 30
P_YAW_WEIGHT, P_DT, P_FEEDFORWARD, P_TWO = 33, 34, 35, 36
N_P = 37


# ----------------------------------------------------------------------------- Python's min, max, **
@kernel
def _max(a, b):
    return b if b > a else a


@kernel
def _min(a, b):
    return b if b < a else a


@kernel
def _square(x, two):
    """x ** 2 as Python computes it for a float: C's pow(x, 2.0), which can differ from x * x in
    the last bit. The exponent comes in at run time (`P_TWO`), else the compiler makes it x * x."""
    return math.pow(x, two)


@kernel
def quat_between(src, dst, eps=1e-5):
    """Shortest rotation taking unit vector src onto dst (matrix::Quaternion(src, dst))."""
    s0, s1, s2 = src
    d0, d1, d2 = dst
    c = (s1 * d2 - s2 * d1, s2 * d0 - s0 * d2, s0 * d1 - s1 * d0)
    dot = s0 * d0 + s1 * d1 + s2 * d2
    if math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) < eps and dot < 0.0:  # opposite: any normal axis
        a = (abs(s0), abs(s1), abs(s2))
        if a[0] < a[1] and a[0] < a[2]:
            axis = (1.0, 0.0, 0.0)
        elif a[1] < a[2]:
            axis = (0.0, 1.0, 0.0)
        else:
            axis = (0.0, 0.0, 1.0)
        c = (s1 * axis[2] - s2 * axis[1], s2 * axis[0] - s0 * axis[2], s0 * axis[1] - s1 * axis[0])
        w = 0.0
    else:
        w = dot + math.sqrt((s0 * s0 + s1 * s1 + s2 * s2) * (d0 * d0 + d1 * d1 + d2 * d2))
    return quat_normalized((w, c[0], c[1], c[2]))


@kernel
def attitude_error(q, q_d, yaw_weight):
    """2 vec(q_e) of AttitudeControl::update (simulator.flight_controller.attitude_error)."""
    e_z, e_z_d = quat_z_axis(q), quat_z_axis(q_d)
    q_red = quat_between(e_z, e_z_d)
    if abs(q_red[1]) > 1.0 - 1e-5 or abs(q_red[2]) > 1.0 - 1e-5:  # thrust axes opposite: full attitude
        q_red = q_d
    else:
        q_red = quat_mul(q_red, q)
    w, _, _, z = quat_canonical(quat_mul(quat_conj(q_red), q_d))  # the yaw left about e_z,d
    w, z = _min(_max(w, -1.0), 1.0), _min(_max(z, -1.0), 1.0)
    q_target = quat_mul(q_red, (math.cos(yaw_weight * math.acos(w)), 0.0, 0.0, math.sin(yaw_weight * math.asin(z))))
    _, ex, ey, ez = quat_canonical(quat_mul(quat_conj(q), q_target))
    return (2.0 * ex, 2.0 * ey, 2.0 * ez)


# ----------------------------------------------------------------------------- filters
@kernel
def lowpass2p_apply(p, at, s, d1, d2, i, x):
    """One sample x through PX4's LowPass2p of axis i: coefficients p[at:at + 6] (active, b0,
    b1, b2, a1, a2), delays s[d1 + i], s[d2 + i] (reset to x's steady state when `started` is 0)."""
    if p[at] == 0.0:
        return x
    b0, b1, b2, a1, a2 = p[at + 1], p[at + 2], p[at + 3], p[at + 4], p[at + 5]
    if s[S_STARTED] == 0.0:
        s[d1 + i] = s[d2 + i] = x / (b0 + b1 + b2)
    d0 = x - s[d1 + i] * a1 - s[d2 + i] * a2
    y = d0 * b0 + s[d1 + i] * b1 + s[d2 + i] * b2
    s[d2 + i], s[d1 + i] = s[d1 + i], d0
    return y


# ----------------------------------------------------------------------------- the loops
@kernel
def allocator_status(s, unallocated, saturated):
    """The saturation per axis and direction that the last allocation left (PX4's
    control_allocator_status), into s: an axis whose unallocated command is above (below)
    +-1.2e-7 in an allocation that fell short may not integrate further up (down)."""
    for ax in range(3):
        s[S_SAT_POS + ax] = 1.0 if saturated and unallocated[ax] > 1.2e-7 else 0.0
        s[S_SAT_NEG + ax] = 1.0 if saturated and unallocated[ax] < -1.2e-7 else 0.0


@kernel
def rate_loops(p, s, quat_WB, w, quat_d, ff, thrust, unallocated, saturated, out):
    """Steps 1 and 2 (attitude P loop, rate PID) of one loop period: quat_WB the vehicle's
    attitude and quat_d the target's ((w, x, y, z), normalized here), w the body rates
    [rad/s], ff the target's body rates [rad/s], thrust its normalized thrust. Writes
    (rates_sp [rad/s], torque [normalized], the thrust within [0, 1] for step 3) into out (7,);
    updates the integral with the saturation of the last allocation (its unallocated control
    (4,) and whether it fell short: `allocator_status`)."""
    allocator_status(s, unallocated, saturated)
    out[6] = _min(_max(thrust, 0.0), 1.0)  # `_update`'s min(max(thrust, 0), 1)
    dt = p[P_DT]
    q = quat_normalized(quat_WB)
    q_d = quat_normalized((quat_d[0], quat_d[1], quat_d[2], quat_d[3]))
    w_prev = (s[S_W_PREV], s[S_W_PREV + 1], s[S_W_PREV + 2]) if s[S_STARTED] != 0.0 else w
    s[S_W_PREV], s[S_W_PREV + 1], s[S_W_PREV + 2] = w
    rate = (lowpass2p_apply(p, P_GYRO, s, S_GYRO_D1, S_GYRO_D2, 0, w[0]),
            lowpass2p_apply(p, P_GYRO, s, S_GYRO_D1, S_GYRO_D2, 1, w[1]),
            lowpass2p_apply(p, P_GYRO, s, S_GYRO_D1, S_GYRO_D2, 2, w[2]))
    accel = (lowpass2p_apply(p, P_DGYRO, s, S_DGYRO_D1, S_DGYRO_D2, 0, (w[0] - w_prev[0]) / dt),
             lowpass2p_apply(p, P_DGYRO, s, S_DGYRO_D1, S_DGYRO_D2, 1, (w[1] - w_prev[1]) / dt),
             lowpass2p_apply(p, P_DGYRO, s, S_DGYRO_D1, S_DGYRO_D2, 2, (w[2] - w_prev[2]) / dt))
    s[S_STARTED] = 1.0

    # 1. attitude P loop
    e = attitude_error(q, q_d, p[P_YAW_WEIGHT])
    for ax in range(3):
        f = ff[ax] if p[P_FEEDFORWARD] != 0.0 else 0.0
        m = p[P_RATE_MAX + ax]
        out[ax] = _min(_max(p[P_ATT_P + ax] * e[ax] + f, -m), m)

    # 2. rate PID, the integral updated after the output (RateControl::update)
    for ax in range(3):
        err = out[ax] - rate[ax]
        out[3 + ax] = (p[P_GAIN_P + ax] * err + s[S_RATE_INT + ax] - p[P_GAIN_D + ax] * accel[ax]
                       + p[P_GAIN_FF + ax] * out[ax])
        ei = err
        if s[S_SAT_POS + ax] != 0.0:
            ei = _min(ei, 0.0)
        if s[S_SAT_NEG + ax] != 0.0:
            ei = _max(ei, 0.0)
        i_factor = _max(0.0, 1.0 - _square(ei / I_ATTENUATION_RAD_S, p[P_TWO]))
        r_i = s[S_RATE_INT + ax] + i_factor * p[P_GAIN_I + ax] * ei * dt
        if math.isfinite(r_i):
            lim = p[P_INT_LIM + ax]
            s[S_RATE_INT + ax] = _min(_max(r_i, -lim), lim)


def constants(fc) -> np.ndarray:
    """The P_* array of a `simulator.flight_controller.FlightController`."""
    p = np.zeros(N_P)
    p[P_GYRO:P_GYRO + 6] = fc.gyro_filter
    p[P_DGYRO:P_DGYRO + 6] = fc.dgyro_filter
    for at, v in ((P_ATT_P, fc.att_p), (P_RATE_MAX, fc.rate_max), (P_GAIN_P, fc.gain_p), (P_GAIN_I, fc.gain_i),
                  (P_GAIN_D, fc.gain_d), (P_GAIN_FF, fc.gain_ff), (P_INT_LIM, fc.int_lim)):
        p[at:at + 3] = v
    p[P_YAW_WEIGHT], p[P_DT], p[P_FEEDFORWARD] = fc.yaw_weight, fc.dt_s, 1.0 if fc.feedforward else 0.0
    p[P_TWO] = 2.0
    return p
