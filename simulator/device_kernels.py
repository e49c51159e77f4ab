"""The devices' per-step arithmetic (numba, as amcore.law): the base's truth as the IMU sees
it, the IMU's biases and noise, the F/T sensor's drift, noise and tare, the encoders'
quantization, the motion capture's frames (noise, biases, drops, latency). Their readable
reference, in plain Python and numpy, is tests/simulator/reference_devices.py (compared in
tests/simulator/test_device_kernels.py).

What stays in Python: the random draws (`simulator.devices.NoiseBlock`: a block of a device's stream at
once, the same numbers in the same order). `simulator.fleet_kernels.sense` calls `suite_step`,
`mocap_step` and the estimator for every AM at once.

State and constants travel in numpy records, their fields named (`STATE`, `CONSTANTS`; the
motion capture's `MOCAP_CONSTANTS`, `MOCAP_STATE` and its frames in flight, `MOCAP_PENDING`).
The quaternion helpers are amcore.quat_kernels'.
"""
from __future__ import annotations

import numpy as np

from amcore.jit import kernel
from amcore.quat_kernels import quat_exp, quat_mul, rotation

_F8 = np.float64
# `suite_step`'s constants and state, each a numpy record that numba reads and writes by field
# name, passed as an array of one (a call's cost grows with its arguments, and numba takes an
# array at a third of a bare record's cost).
# constants: the IMU's Gauss-Markov factors and step deviations of both biases, its white-noise
# deviations and turn-on biases; the F/T sensor's drift and noise deviations and its tare
# window [lo, hi); the physics step [s], g [m/s^2], the encoders' steps
CONSTANTS = np.dtype([("phi_g", _F8), ("sigma_bg", _F8), ("phi_a", _F8), ("sigma_ba", _F8), ("sigma_g", _F8),
                      ("sigma_a", _F8), ("turn_on_g", _F8, 3), ("turn_on_a", _F8, 3),
                      ("ft_drift", _F8, 6), ("ft_sigma", _F8, 6), ("ft_lo", _F8), ("ft_hi", _F8),
                      ("dt", _F8), ("g", _F8), ("dq", _F8), ("dqdot", _F8)])
# state: the truth's (the base's world velocity at the last step, whether there was one), the
# IMU's biases (the Gauss-Markov parts) and its last sample, the F/T sensor's drifting offset,
# tare, the tare window's sum and count, whether tared
STATE = np.dtype([("v_W", _F8, 3), ("started", _F8), ("b_g", _F8, 3), ("b_a", _F8, 3), ("omega_m", _F8, 3),
                  ("f_m", _F8, 3), ("ft_offset", _F8, 6), ("ft_tare", _F8, 6), ("ft_sum", _F8, 6),
                  ("ft_count", _F8), ("ft_tared", _F8)])
# `mocap_step`'s: the constants (a frame every `every` steps, `lag` steps late; the white-noise
# deviations sigma_p [m] and sigma_R [rad]; the drop probability; the fixed position bias [m]
# and body-frame attitude bias [rad]), the state (the last step, frames captured and dropped so
# far), and a frame in flight (its pose, the step it arrives at, -1 if lost), one per capture
# in a ring indexed by capture number
_I8 = np.int64
MOCAP_CONSTANTS = np.dtype([("every", _I8), ("lag", _I8), ("sigma_p", _F8), ("sigma_R", _F8), ("drop", _F8),
                            ("bias_p", _F8, 3), ("bias_R", _F8, 3)])
MOCAP_STATE = np.dtype([("k", _I8), ("captured", _I8), ("dropped", _I8)])
MOCAP_PENDING = np.dtype([("p", _F8, 3), ("q", _F8, 4), ("arrives", _I8)])
MOCAP_DRAWS = 7  # a capture's draws: 6 standard normals (position, attitude), then a uniform (the drop)


# ----------------------------------------------------------------------------- the truth
@kernel
def mat_vec(R, v, out):
    """out = R v for a (3, 3) R."""
    for i in range(3):
        out[i] = R[i, 0] * v[0] + R[i, 1] * v[1] + R[i, 2] * v[2]


@kernel
def mat_t_vec(R, u, out):
    """out = R^T u for a (3, 3) R."""
    for i in range(3):
        out[i] = R[0, i] * u[0] + R[1, i] * u[1] + R[2, i] * u[2]


@kernel
def specific_force(x, dt, g, s, f_B):
    """`DeviceSuite._truth` and `Imu.sample`'s f_B = R_WB^T (a_W + g e_3) [m/s^2] from the
    base's exact values x (p_WB, quat_WB, v_B, w_B, ...): v_W = R_WB v_B, a_W = (v_W - v_W,prev)
    / dt (0 at the first step); s: the state record (`STATE`), its truth's part updated."""
    R = rotation(x[3:7])
    v_W = np.empty(3)
    mat_vec(R, x[7:10], v_W)
    u = np.empty(3)
    for i in range(3):
        a_W = 0.0 if s.started == 0.0 else (v_W[i] - s.v_W[i]) / dt
        u[i] = a_W + (g if i == 2 else 0.0)
        s.v_W[i] = v_W[i]
    s.started = 1.0
    mat_t_vec(R, u, f_B)


@kernel
def imu_sample(c, s, f_B, w_B, n):
    """`Imu.sample` after f_B = R_WB^T (a_W + g e_3): the biases' Gauss-Markov step (s.b_g,
    s.b_a updated), then s.omega_m = w_B + b_g,on + b_g + sigma_g n and s.f_m = f_B + b_a,on +
    b_a + sigma_a n [rad/s, m/s^2]; c, s: the `CONSTANTS` and `STATE` records; n: the step's
    12 standard normal draws."""
    b_g, b_a = s.b_g, s.b_a
    for i in range(3):
        b_g[i] = c.phi_g * b_g[i] + c.sigma_bg * n[i]
        b_a[i] = c.phi_a * b_a[i] + c.sigma_ba * n[3 + i]
    for i in range(3):
        s.omega_m[i] = w_B[i] + c.turn_on_g[i] + b_g[i] + c.sigma_g * n[6 + i]
        s.f_m[i] = f_B[i] + c.turn_on_a[i] + b_a[i] + c.sigma_a * n[9 + i]


@kernel
def ft_sample(c, s, wrench_E, t, n, out):
    """`ForceTorque.sample`: the offset's random-walk step, the raw reading with white noise,
    the tare's window average once t passes it; the reading less the tare into out (6,)."""
    raw = np.empty(6)
    for i in range(6):
        s.ft_offset[i] = s.ft_offset[i] + c.ft_drift[i] * n[i]
        raw[i] = wrench_E[i] + s.ft_offset[i] + c.ft_sigma[i] * n[6 + i]
    if s.ft_tared == 0.0:
        if c.ft_lo <= t < c.ft_hi:
            for i in range(6):
                s.ft_sum[i] += raw[i]
            s.ft_count += 1.0
        elif t >= c.ft_hi:
            for i in range(6):
                s.ft_tare[i] = s.ft_sum[i] / s.ft_count if s.ft_count > 0.0 else raw[i]
            s.ft_tared = 1.0
    for i in range(6):
        out[i] = raw[i] - s.ft_tare[i]


@kernel
def quantize(x, step, out):
    """`Encoders._quantize`: x rounded to whole steps (half to even, as numpy's round); x if step is 0."""
    for i in range(x.shape[0]):
        out[i] = np.rint(x[i] / step) * step if step > 0.0 else x[i]


@kernel
def devices_sample(values, n_joints, f_B, c, s, imu_n, t, ft_n, out):
    """One physics step of the IMU (s.omega_m, s.f_m), the encoders and the F/T sensor from the
    AM's exact values (the order of `World.sensor_values`); out (2 n_joints + 6,) = the
    quantized q, qdot and the F/T reading, the tail of the frame's values."""
    n = n_joints
    imu_sample(c, s, f_B, values[10:13], imu_n)
    quantize(values[13:13 + n], c.dq, out[0:n])
    quantize(values[13 + n:13 + 2 * n], c.dqdot, out[n:2 * n])
    ft_sample(c, s, values[13 + 2 * n:19 + 2 * n], t, ft_n, out[2 * n:2 * n + 6])


@kernel
def ft_drift(c, s, n):
    """`ForceTorque.sample`'s random-walk step of the offset alone (a step whose reading
    nobody reads, outside the tare's window: `DeviceSuite.needs_reading`)."""
    for i in range(6):
        s.ft_offset[i] = s.ft_offset[i] + c.ft_drift[i] * n[i]


@kernel
def devices_advance(values, f_B, c, s, imu_n, ft_n):
    """`devices_sample` for a step without a frame: the IMU from the base's values (p_WB,
    quat_WB, v_B, w_B) and the F/T sensor's drift; nothing read of the arm or the wrist."""
    imu_sample(c, s, f_B, values[10:13], imu_n)
    ft_drift(c, s, ft_n)


@kernel
def suite_step(x, t, constants, state, imu_n, ft_n, out):
    """One physics step of `DeviceSuite`'s devices from the AM's exact values x: the truth
    (`specific_force`), then `devices_sample` if x holds the arm's and the wrist's values
    (the order of `World.sensor_values`; out (2 n_joints + 6,) the frame's tail), else
    `devices_advance` (the base's 13 alone). constants, state: the `CONSTANTS` and `STATE`
    records, each in an array of one; the IMU's sample (omega_m, f_m) is left in the state;
    imu_n, ft_n: the step's draws of each."""
    c, s = constants[0], state[0]
    f_B = np.empty(3)
    specific_force(x, c.dt, c.g, s, f_B)
    if x.shape[0] > 13:
        devices_sample(x, (out.shape[0] - 6) // 2, f_B, c, s, imu_n, t, ft_n, out)
    else:
        devices_advance(x, f_B, c, s, imu_n, ft_n)


# ----------------------------------------------------------------------------- the motion capture
@kernel
def mocap_capture(c, x, n, e):
    """One frame of the base's pose x (p_WB, quat_WB first) into e (a `MOCAP_PENDING`):
    p_m = p_WB + b_p + sigma_p n[0:3], q_m = quat_WB (x) exp(b_R + sigma_R n[3:6])."""
    for i in range(3):
        e.p[i] = x[i] + c.bias_p[i] + c.sigma_p * n[i]
    dq = quat_exp((c.bias_R[0] + c.sigma_R * n[3], c.bias_R[1] + c.sigma_R * n[4], c.bias_R[2] + c.sigma_R * n[5]))
    q = quat_mul((x[3], x[4], x[5], x[6]), dq)
    for i in range(4):
        e.q[i] = q[i]


@kernel
def mocap_step(constants, state, pending, x, draws, draw_row, p_m, q_m):
    """One physics step of the motion capture from the base's exact values x (p_WB, quat_WB
    first: all it sees): on every `every`-th step (from the first) a frame is captured, taking
    the next row of `draws` (`draw_row`, an array of one; `MOCAP_DRAWS` a row) and lost if its
    uniform is below the drop probability (> 0), else in flight in `pending` (a ring of
    `MOCAP_PENDING`, at least lag // every + 1 long) until `lag` steps later. Whether a frame
    arrives this step; if so, its pose into p_m and q_m (w, x, y, z). constants, state: the
    `MOCAP_CONSTANTS` and `MOCAP_STATE` records, each in an array of one."""
    c, s = constants[0], state[0]
    s.k += 1
    k = s.k
    ring = pending.shape[0]
    if k % c.every == 0:
        j = draw_row[0]
        if j >= draws.shape[0]:
            raise IndexError("a motion capture without draws left: its next block is drawn before the step")
        n = draws[j]
        draw_row[0] = j + 1
        e = pending[(k // c.every) % ring]
        s.captured += 1
        if c.drop > 0.0 and n[6] < c.drop:
            s.dropped += 1
            e.arrives = -1
        else:
            mocap_capture(c, x, n, e)
            e.arrives = k + c.lag
    taken = k - c.lag
    if taken < 0 or taken % c.every != 0:
        return False
    e = pending[(taken // c.every) % ring]
    if e.arrives != k:
        return False
    for i in range(3):
        p_m[i] = e.p[i]
    for i in range(4):
        q_m[i] = e.q[i]
    return True
