"""The devices' per-step arithmetic compiled (numba, as amcore.law): the IMU's biases and
noise, the F/T sensor's drift, noise and tare, the encoders' quantization. The same
equations as the Python classes of `simulator.devices`, element by element in the same
order on IEEE doubles, so that `DeviceSuite(compiled=True)` reports bit for bit what the
Python devices report (tests/simulator/test_device_kernels.py).

What stays in numpy, before the kernel: the two 3x3 products of `DeviceSuite` (R_WB v_B and
R_WB^T (a_W + g e_3)), which numpy hands to BLAS, whose fused multiply-adds round otherwise
than a plain loop; the random draws (`NoiseBlock`: a block of a device's stream at once,
the same numbers in the same order); the motion capture (one frame in ten steps) and the
estimator (`amcore.estimator`, compiled there).

State and constants travel in small arrays, named by the `IMU_*` and `FT_*` offsets.
Kernels here call only kernels of this file (numba's cache is keyed per source file; see
amcore.jit).
"""
from __future__ import annotations

import numpy as np

from amcore.jit import kernel

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
