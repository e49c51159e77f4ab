"""Sensor realism of the emulated flight controller as white noise on the states, the stress
option (pure: numpy only); sensors as devices with an estimator are `simulator.devices`.

`SensorModel(spec, ...)` turns one AM's exact sensor values (the order of
`World.sensor_values`: p_WB, quat_WB (w, x, y, z), v_B, w_B, q, qdot, wrench_E) into what its
sensors report, as `[sensors]` (`amcore.config.SensorSpec`) describes:

- latency: the values handed out at step k are those of step k - L, L = round(latency_s / dt)
  (before step L, the first values);
- bias: a constant offset per axis, drawn once from the AM's own random stream;
- noise: white Gaussian noise per axis, drawn every frame from the same stream.

Attitude errors are rotation vectors d applied on the body side, R = R_true exp(hat(d)).
Joint encoders stay exact. Each AM's stream is seeded by (scenario seed, sysid), so a run
is reproducible and the multi-process and in-process SITL see the same frames.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from amcore.config import SensorSpec
from amcore.so3 import quat_wxyz_boxplus

_STREAM = 0x5E45  # distinguishes the sensor stream from other seeded streams of an AM


class SensorModel:
    def __init__(self, spec: SensorSpec, n_joints: int, dt_s: float, seed: int, sysid: int) -> None:
        self.spec, self.n = spec, n_joints
        self.rng = np.random.default_rng([seed, sysid, _STREAM])
        s = spec
        bias_std = np.repeat([s.position_bias_m, s.attitude_bias_rad, s.velocity_bias_mps,
                              s.angular_velocity_bias_radps, s.force_bias_n, s.torque_bias_nm], 3)
        self.bias = bias_std * self.rng.standard_normal(18)  # p, attitude, v, w, f, tau
        self.noise_std = np.repeat([s.position_noise_m, s.attitude_noise_rad, s.velocity_noise_mps,
                                    s.angular_velocity_noise_radps, s.force_noise_n, s.torque_noise_nm], 3)
        self.delay_steps = int(round(s.latency_s / dt_s))
        self._past: deque[list[float]] = deque(maxlen=self.delay_steps + 1)

    def __call__(self, values: list[float]) -> list[float]:
        """What the sensors report this step, given this step's exact values."""
        self._past.append(values)
        v = self._past[0]  # the oldest kept: delay_steps old once the buffer is full
        e = (self.bias + self.noise_std * self.rng.standard_normal(18)).tolist()
        n = self.n
        p = [v[0] + e[0], v[1] + e[1], v[2] + e[2]]
        quat = quat_wxyz_boxplus(v[3:7], e[3:6])  # the attitude error in {b}
        vel = [v[7] + e[6], v[8] + e[7], v[9] + e[8]]
        w = [v[10] + e[9], v[11] + e[10], v[12] + e[11]]
        joints = v[13:13 + 2 * n]
        f = v[13 + 2 * n:19 + 2 * n]
        wrench = [f[0] + e[12], f[1] + e[13], f[2] + e[14], f[3] + e[15], f[4] + e[16], f[5] + e[17]]
        return [*p, *quat, *vel, *w, *joints, *wrench]


