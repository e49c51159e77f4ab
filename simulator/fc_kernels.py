"""The emulated autopilot's attitude and rate loops (numba, as amcore.law), one small kernel
per step of `simulator.flight_controller`'s module doc. Their readable reference, the same
equations in plain Python, is tests/simulator/reference_flight_controller.py, which
tests/simulator/test_fc_kernels.py compares them with.

`FlightController` keeps its loops' state and its constants in two numpy records, their fields
named (`STATE`, `PARAMS`, with a `LOWPASS2P` record per filter; numba reads and writes them by
name), and its output in an `OUTPUT` record; `rate_loops` runs steps 1 and 2 of the module doc of
`simulator.flight_controller` (attitude P loop, rate PID with the gyro filters); the
allocation (step 3) stays in `amcore.allocation`, shared with torque mode.

`pymin` and `pymax` (amcore.allocation_kernels') keep their first argument on ties and NaNs, as
Python's min and max do. The quaternion helpers are amcore.quat_kernels'.
"""
from __future__ import annotations

import math

import numpy as np

from amcore.allocation_kernels import allocate, pymax, pymin
from amcore.jit import kernel
from amcore.quat_kernels import quat_canonical, quat_conj, quat_mul, quat_normalized, quat_z_axis

I_ATTENUATION_RAD_S = math.radians(400.0)  # RateControl::updateIntegral's i_factor scale

_AXES = (np.float64, 3)
# the loops' state (a numpy record, `new_state`): each filter's two delays per axis, the rate
# integral, the last gyro sample, the allocation's saturation per axis and direction (1 or 0),
# whether the loops have started (1 or 0)
STATE = np.dtype([("gyro_d1", *_AXES), ("gyro_d2", *_AXES), ("dgyro_d1", *_AXES), ("dgyro_d2", *_AXES),
                  ("rate_int", *_AXES), ("w_prev", *_AXES), ("sat_pos", *_AXES), ("sat_neg", *_AXES),
                  ("started", np.float64)])
# one LowPass2p's coefficients (`simulator.flight_controller.lowpass2p`): whether it filters
# (1 or 0; 0 passes the input through), the numerator b0, b1, b2 and the denominator a1, a2
LOWPASS2P = np.dtype([("active", np.float64), ("b0", np.float64), ("b1", np.float64), ("b2", np.float64),
                      ("a1", np.float64), ("a2", np.float64)])
# the loops' constants (a numpy record, `constants`): the rate's and its derivative's low-pass
# filters, the gains and limits per axis, the yaw weight, the loop period [s], and whether the
# target's rates feed forward (1 or 0)
PARAMS = np.dtype([("gyro", LOWPASS2P), ("dgyro", LOWPASS2P), ("att_p", *_AXES), ("rate_max", *_AXES),
                   ("gain_p", *_AXES), ("gain_i", *_AXES), ("gain_d", *_AXES), ("gain_ff", *_AXES),
                   ("int_lim", *_AXES), ("yaw_weight", np.float64), ("dt", np.float64),
                   ("feedforward", np.float64)])

# one loop period's output (`rate_loops`): the body-rate setpoint [rad/s], the normalized
# torque per axis and the thrust within [0, 1], the last two what the allocation takes
OUTPUT = np.dtype([("rates_sp", *_AXES), ("torque", *_AXES), ("thrust", np.float64)])
# where one autopilot stands between its loop periods (a numpy record, a row of
# `simulator.flight_controller.AutopilotArrays`): physics steps taken, the loop period in
# physics steps, whether it has an output (1 or 0), how many outputs it has made, the last
# (`OUTPUT`), and the saturation its last allocation left: the unallocated control (0 where the
# allocation met its request), per axis (roll, pitch, yaw, thrust) whether it fell short (1 or
# 0), and whether any did
AUTOPILOT = np.dtype([("k", np.int64), ("every", np.int64), ("has_output", np.float64), ("outputs", np.int64),
                      ("out", OUTPUT),
                      ("unallocated", np.float64, 4), ("saturated_axes", np.float64, 4), ("saturated", np.float64)])


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
    w, z = pymin(pymax(w, -1.0), 1.0), pymin(pymax(z, -1.0), 1.0)
    q_target = quat_mul(q_red, (math.cos(yaw_weight * math.acos(w)), 0.0, 0.0, math.sin(yaw_weight * math.asin(z))))
    _, ex, ey, ez = quat_canonical(quat_mul(quat_conj(q), q_target))
    return (2.0 * ex, 2.0 * ey, 2.0 * ez)


# ----------------------------------------------------------------------------- filters
@kernel
def lowpass2p_apply(c, d1, d2, started, i, x):
    """One sample x through PX4's LowPass2p of axis i: coefficients c (a `LOWPASS2P` record),
    delays d1[i], d2[i] (reset to x's steady state when `started` is 0)."""
    if c.active == 0.0:
        return x
    b0, b1, b2, a1, a2 = c.b0, c.b1, c.b2, c.a1, c.a2
    if started == 0.0:
        d1[i] = d2[i] = x / (b0 + b1 + b2)
    d0 = x - d1[i] * a1 - d2[i] * a2
    y = d0 * b0 + d1[i] * b1 + d2[i] * b2
    d2[i], d1[i] = d1[i], d0
    return y


# ----------------------------------------------------------------------------- the loops
@kernel
def allocator_status(s, unallocated, saturated):
    """The saturation per axis and direction that the last allocation left (PX4's
    control_allocator_status), into the state s: an axis whose unallocated command is above
    (below) +-1.2e-7 in an allocation that fell short may not integrate further up (down)."""
    for ax in range(3):
        s.sat_pos[ax] = 1.0 if saturated and unallocated[ax] > 1.2e-7 else 0.0
        s.sat_neg[ax] = 1.0 if saturated and unallocated[ax] < -1.2e-7 else 0.0


@kernel
def rate_loops(params, state, quat_WB, w, quat_d, ff, thrust, unallocated, saturated, out):
    """Steps 1 and 2 (attitude P loop, rate PID) of one loop period, with the constants
    (`PARAMS`) and the state (`STATE`), each an array of one record (numba takes an array
    from Python at a third of a bare record's cost): quat_WB the vehicle's attitude and quat_d the
    target's ((w, x, y, z), normalized here), w the body rates [rad/s], ff the target's body
    rates [rad/s], thrust its normalized thrust. Writes the rate setpoint, the torque and the
    thrust for step 3 into out (an `OUTPUT` record); updates the integral
    with the saturation of the last allocation (its unallocated control (4,) and whether it
    fell short: `allocator_status`)."""
    p, s = params[0], state[0]
    allocator_status(s, unallocated, saturated)
    out.thrust = pymin(pymax(thrust, 0.0), 1.0)  # `_update`'s min(max(thrust, 0), 1)
    dt = p.dt
    q = quat_normalized(quat_WB)
    q_d = quat_normalized((quat_d[0], quat_d[1], quat_d[2], quat_d[3]))
    started = s.started
    w_prev = (s.w_prev[0], s.w_prev[1], s.w_prev[2]) if started != 0.0 else w
    s.w_prev[0], s.w_prev[1], s.w_prev[2] = w
    g, dg = p.gyro, p.dgyro
    rate = (lowpass2p_apply(g, s.gyro_d1, s.gyro_d2, started, 0, w[0]),
            lowpass2p_apply(g, s.gyro_d1, s.gyro_d2, started, 1, w[1]),
            lowpass2p_apply(g, s.gyro_d1, s.gyro_d2, started, 2, w[2]))
    accel = (lowpass2p_apply(dg, s.dgyro_d1, s.dgyro_d2, started, 0, (w[0] - w_prev[0]) / dt),
             lowpass2p_apply(dg, s.dgyro_d1, s.dgyro_d2, started, 1, (w[1] - w_prev[1]) / dt),
             lowpass2p_apply(dg, s.dgyro_d1, s.dgyro_d2, started, 2, (w[2] - w_prev[2]) / dt))
    s.started = 1.0

    # 1. attitude P loop
    e = attitude_error(q, q_d, p.yaw_weight)
    for ax in range(3):
        f = ff[ax] if p.feedforward != 0.0 else 0.0
        m = p.rate_max[ax]
        out.rates_sp[ax] = pymin(pymax(p.att_p[ax] * e[ax] + f, -m), m)

    # 2. rate PID, the integral updated after the output (RateControl::update)
    for ax in range(3):
        err = out.rates_sp[ax] - rate[ax]
        out.torque[ax] = (p.gain_p[ax] * err + s.rate_int[ax] - p.gain_d[ax] * accel[ax]
                          + p.gain_ff[ax] * out.rates_sp[ax])
        ei = err
        if s.sat_pos[ax] != 0.0:
            ei = pymin(ei, 0.0)
        if s.sat_neg[ax] != 0.0:
            ei = pymax(ei, 0.0)
        i_factor = ei / I_ATTENUATION_RAD_S  # RateControl::updateIntegral: 1 - i_factor * i_factor, at least 0
        i_factor = pymax(0.0, 1.0 - i_factor * i_factor)
        r_i = s.rate_int[ax] + i_factor * p.gain_i[ax] * ei * dt
        if math.isfinite(r_i):
            lim = p.int_lim[ax]
            s.rate_int[ax] = pymin(pymax(r_i, -lim), lim)


@kernel
def autopilot_step(params, state, ap, quat_WB, w, quat_d, ff, thrust, alloc_c, tol, result):
    """One physics step of one autopilot (`FlightController.step`): every `ap`'s `every` steps
    (and at its first) steps 1 and 2 (`rate_loops`, on the saturation the last allocation left)
    and step 3 (`amcore.allocation_kernels.allocate` with its constants record `alloc_c` into
    its result record `result`; `tol`: the unallocated command above which an axis counts as
    saturated); between, the output holds. params, state, ap: arrays of one record (`PARAMS`,
    `STATE`, `AUTOPILOT`), as alloc_c and result. Returns whether the output is new."""
    a = ap[0]
    k = a.k
    a.k = k + 1
    if a.has_output != 0.0 and k % a.every != 0:
        return False
    unallocated = (a.unallocated[0], a.unallocated[1], a.unallocated[2], a.unallocated[3])
    rate_loops(params, state, quat_WB, w, quat_d, ff, thrust, unallocated, a.saturated != 0.0, a.out)
    o = a.out
    allocate(alloc_c, o.torque[0], o.torque[1], o.torque[2], o.thrust, result)
    r = result[0]
    a.saturated = 0.0
    for ax in range(4):
        u = r.unallocated[ax] if r.desaturated != 0.0 else 0.0
        a.unallocated[ax] = u
        a.saturated_axes[ax] = 1.0 if abs(u) > tol else 0.0
        if abs(u) > tol:
            a.saturated = 1.0
    a.has_output = 1.0
    a.outputs += 1
    return True


def new_state() -> np.ndarray:
    """A zero `STATE` record (the loops not started), in an array of one."""
    return np.zeros(1, STATE)


def constants(fc) -> np.ndarray:
    """The `PARAMS` record of a `simulator.flight_controller.FlightController`, in an array of one."""
    a = np.zeros(1, PARAMS)
    p = a[0]
    _set_lowpass2p(p["gyro"], fc.gyro_filter)
    _set_lowpass2p(p["dgyro"], fc.dgyro_filter)
    p["att_p"], p["rate_max"], p["gain_p"], p["gain_i"] = fc.att_p, fc.rate_max, fc.gain_p, fc.gain_i
    p["gain_d"], p["gain_ff"], p["int_lim"] = fc.gain_d, fc.gain_ff, fc.int_lim
    p["yaw_weight"], p["dt"], p["feedforward"] = fc.yaw_weight, fc.dt_s, 1.0 if fc.feedforward else 0.0
    return a


def _set_lowpass2p(c, coefficients) -> None:
    """The `LOWPASS2P` record c (a view) from `simulator.flight_controller.lowpass2p`'s tuple."""
    c["active"], c["b0"], c["b1"], c["b2"], c["a1"], c["a2"] = coefficients
