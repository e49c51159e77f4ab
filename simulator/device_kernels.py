"""The devices' per-step arithmetic (numba, as amcore.law): the base's truth as the IMU sees
it, the IMU's biases and noise, the F/T sensor's drift, noise and tare, the encoders'
quantization. Their readable reference, in plain Python and numpy, is
tests/simulator/reference_devices.py (compared in tests/simulator/test_device_kernels.py).

The truth's two 3x3 products (R_WB v_B and R_WB^T (a_W + g e_3)) are made with fused
multiply-adds in the order OpenBLAS's dgemv kernels use (`mat_vec`, `mat_t_vec`), so that
they round as numpy's products do on a machine whose numpy calls OpenBLAS; everywhere, the
kernels give the same numbers, whatever BLAS numpy has.

What stays in Python: the random draws (`NoiseBlock`: a block of a device's stream at once,
the same numbers in the same order); the motion capture (one frame in ten steps) and the
estimator's call (`amcore.estimator`, compiled there).

State and constants travel in small arrays, named by the `IMU_*`, `FT_*`, `TRUTH_*`, `C_*`
and `S_*` offsets. The quaternion helpers are amcore.quat_kernels'.
"""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from amcore.jit import kernel
from amcore.quat_kernels import rotation

from .noise import NoiseBlock  # noqa: F401 (DeviceSuite's draws)

# IMU constants: Gauss-Markov factors and step deviations of both biases, white noise
# deviations, then the turn-on biases
IMU_PHI_G, IMU_SIGMA_BG, IMU_PHI_A, IMU_SIGMA_BA, IMU_SIGMA_G, IMU_SIGMA_A, IMU_TURN_ON_G, IMU_TURN_ON_A = 0, 1, 2, 3, 4, 5, 6, 9
N_IMU = 12
# F/T state: the drifting offset, the tare, the tare window's sum and count, whether tared;
# constants: drift and noise deviations, the tare window [lo, hi)
FT_OFFSET, FT_TARE, FT_SUM, FT_COUNT, FT_TARED = 0, 6, 12, 18, 19
N_FT_STATE = 20
FT_DRIFT, FT_SIGMA, FT_LO, FT_HI = 0, 6, 12, 13
N_FT = 14
# the truth's state: the base's world velocity at the last step, whether there was one
TRUTH_V_W, TRUTH_STARTED = 0, 3
N_TRUTH = 4
# `suite_step`'s constants and state, one array each (a call's cost grows with its arguments):
# constants: the IMU's, the F/T sensor's, the physics step [s], g [m/s^2], the encoders' steps;
# state: the truth's, the IMU's biases (the Gauss-Markov parts), its last sample, the F/T sensor's
C_IMU, C_FT, C_DT, C_G, C_DQ, C_DQDOT = 0, N_IMU, N_IMU + N_FT, N_IMU + N_FT + 1, N_IMU + N_FT + 2, N_IMU + N_FT + 3
N_C = N_IMU + N_FT + 4
S_TRUTH, S_B_G, S_B_A, S_OMEGA_M, S_F_M, S_FT = 0, N_TRUTH, N_TRUTH + 3, N_TRUTH + 6, N_TRUTH + 9, N_TRUTH + 12
N_S = N_TRUTH + 12 + N_FT_STATE


# ----------------------------------------------------------------------------- the truth
@intrinsic
def _fma(typingctx, a, b, c):
    """a b + c rounded once (LLVM's llvm.fma.f64, in hardware or not): the fused
    multiply-add of OpenBLAS's kernels."""
    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fma = cgutils.get_or_insert_function(builder.module, ir.FunctionType(d, [d, d, d]), "llvm.fma.f64")
        return builder.call(fma, args)
    return types.float64(types.float64, types.float64, types.float64), codegen


@kernel
def mat_vec(R, v, out):
    """numpy's R @ v for a C-ordered (3, 3) R, rounded as OpenBLAS's dgemv_t computes it (a
    row's three products summed by its compiler's fused multiply-adds, added to y = 0)."""
    for i in range(3):
        out[i] = 0.0 + _fma(R[i, 2], v[2], _fma(R[i, 0], v[0], R[i, 1] * v[1]))


@kernel
def mat_t_vec(R, u, out):
    """numpy's R.T @ u for a C-ordered (3, 3) R (R.T Fortran-ordered), rounded as OpenBLAS's
    dgemv_n computes it: y = 0, then y += R[j] u_j row after row by fused multiply-adds."""
    for i in range(3):
        out[i] = _fma(R[2, i], u[2], _fma(R[1, i], u[1], _fma(R[0, i], u[0], 0.0)))


@kernel
def specific_force(x, dt, g, s, f_B):
    """`DeviceSuite._truth` and `Imu.sample`'s f_B = R_WB^T (a_W + g e_3) [m/s^2] from the
    base's exact values x (p_WB, quat_WB, v_B, w_B, ...): v_W = R_WB v_B, a_W = (v_W - v_W,prev)
    / dt (0 at the first step); s: the truth's state (`TRUTH_*`), updated."""
    R = rotation(x[3:7])
    v_W = np.empty(3)
    mat_vec(R, x[7:10], v_W)
    u = np.empty(3)
    for i in range(3):
        a_W = 0.0 if s[TRUTH_STARTED] == 0.0 else (v_W[i] - s[TRUTH_V_W + i]) / dt
        u[i] = a_W + (g if i == 2 else 0.0)
        s[TRUTH_V_W + i] = v_W[i]
    s[TRUTH_STARTED] = 1.0
    mat_t_vec(R, u, f_B)


@kernel
def imu_sample(c, b_g, b_a, f_B, w_B, n, omega_m, f_m):
    """`Imu.sample` after f_B = R_WB^T (a_W + g e_3): the biases' Gauss-Markov step (b_g, b_a
    updated), then omega_m = w_B + b_g,on + b_g + sigma_g n and f_m = f_B + b_a,on + b_a +
    sigma_a n [rad/s, m/s^2]; n: the step's 12 standard normal draws."""
    for i in range(3):
        b_g[i] = c[IMU_PHI_G] * b_g[i] + c[IMU_SIGMA_BG] * n[i]
        b_a[i] = c[IMU_PHI_A] * b_a[i] + c[IMU_SIGMA_BA] * n[3 + i]
    for i in range(3):
        omega_m[i] = w_B[i] + c[IMU_TURN_ON_G + i] + b_g[i] + c[IMU_SIGMA_G] * n[6 + i]
        f_m[i] = f_B[i] + c[IMU_TURN_ON_A + i] + b_a[i] + c[IMU_SIGMA_A] * n[9 + i]


@kernel
def ft_sample(c, s, wrench_E, t, n, out):
    """`ForceTorque.sample`: the offset's random-walk step, the raw reading with white noise,
    the tare's window average once t passes it; the reading less the tare into out (6,)."""
    raw = np.empty(6)
    for i in range(6):
        s[FT_OFFSET + i] = s[FT_OFFSET + i] + c[FT_DRIFT + i] * n[i]
        raw[i] = wrench_E[i] + s[FT_OFFSET + i] + c[FT_SIGMA + i] * n[6 + i]
    if s[FT_TARED] == 0.0:
        if c[FT_LO] <= t < c[FT_HI]:
            for i in range(6):
                s[FT_SUM + i] += raw[i]
            s[FT_COUNT] += 1.0
        elif t >= c[FT_HI]:
            for i in range(6):
                s[FT_TARE + i] = s[FT_SUM + i] / s[FT_COUNT] if s[FT_COUNT] > 0.0 else raw[i]
            s[FT_TARED] = 1.0
    for i in range(6):
        out[i] = raw[i] - s[FT_TARE + i]


@kernel
def quantize(x, step, out):
    """`Encoders._quantize`: x rounded to whole steps (half to even, as numpy's round); x if step is 0."""
    for i in range(x.shape[0]):
        out[i] = np.rint(x[i] / step) * step if step > 0.0 else x[i]


@kernel
def devices_sample(values, n_joints, f_B, imu_c, b_g, b_a, imu_n, omega_m, f_m, dq, dqdot, ft_c, ft_s, t, ft_n, out):
    """One physics step of the IMU (omega_m, f_m), the encoders and the F/T sensor from the
    AM's exact values (the order of `World.sensor_values`); out (2 n_joints + 6,) = the
    quantized q, qdot and the F/T reading, the tail of the frame's values."""
    n = n_joints
    imu_sample(imu_c, b_g, b_a, f_B, values[10:13], imu_n, omega_m, f_m)
    quantize(values[13:13 + n], dq, out[0:n])
    quantize(values[13 + n:13 + 2 * n], dqdot, out[n:2 * n])
    ft_sample(ft_c, ft_s, values[13 + 2 * n:19 + 2 * n], t, ft_n, out[2 * n:2 * n + 6])


@kernel
def ft_drift(c, s, n):
    """`ForceTorque.sample`'s random-walk step of the offset alone (a step whose reading
    nobody reads, outside the tare's window: `DeviceSuite.needs_reading`)."""
    for i in range(6):
        s[FT_OFFSET + i] = s[FT_OFFSET + i] + c[FT_DRIFT + i] * n[i]


@kernel
def devices_advance(values, f_B, imu_c, b_g, b_a, imu_n, omega_m, f_m, ft_c, ft_s, ft_n):
    """`devices_sample` for a step without a frame: the IMU from the base's values (p_WB,
    quat_WB, v_B, w_B) and the F/T sensor's drift; nothing read of the arm or the wrist."""
    imu_sample(imu_c, b_g, b_a, f_B, values[10:13], imu_n, omega_m, f_m)
    ft_drift(ft_c, ft_s, ft_n)


@kernel
def suite_step(x, t, c, s, imu_n, ft_n, out):
    """One physics step of `DeviceSuite`'s devices from the AM's exact values x: the truth
    (`specific_force`), then `devices_sample` if x holds the arm's and the wrist's values
    (the order of `World.sensor_values`; out (2 n_joints + 6,) the frame's tail), else
    `devices_advance` (the base's 13 alone). c, s: the `C_*` constants and `S_*` state; the
    IMU's sample (omega_m, f_m) is left in s; imu_n, ft_n: the step's draws of each."""
    f_B = np.empty(3)
    specific_force(x, c[C_DT], c[C_G], s[S_TRUTH:S_TRUTH + N_TRUTH], f_B)
    imu_c, ft_c, ft_s = c[C_IMU:C_IMU + N_IMU], c[C_FT:C_FT + N_FT], s[S_FT:S_FT + N_FT_STATE]
    b_g, b_a, omega_m, f_m = s[S_B_G:S_B_G + 3], s[S_B_A:S_B_A + 3], s[S_OMEGA_M:S_OMEGA_M + 3], s[S_F_M:S_F_M + 3]
    if x.shape[0] > 13:
        devices_sample(x, (out.shape[0] - 6) // 2, f_B, imu_c, b_g, b_a, imu_n, omega_m, f_m, c[C_DQ], c[C_DQDOT],
                       ft_c, ft_s, t, ft_n, out)
    else:
        devices_advance(x, f_B, imu_c, b_g, b_a, imu_n, omega_m, f_m, ft_c, ft_s, ft_n)
