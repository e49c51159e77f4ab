"""The devices' per-step arithmetic in plain Python and numpy: the readable reference of
simulator.device_kernels (the truth as the IMU sees it, the IMU's biases and noise, the F/T
sensor's drift, noise and tare, the encoders' quantization, the motion capture's frames), as
methods on the device classes of simulator.devices, which hold each device's constants and
turn-on draws.

`ReferenceDeviceSuite` is a `DeviceSuite` whose `step` runs these methods, drawing from the
same streams one step (or one frame) at a time, with the same estimator."""
from __future__ import annotations

from collections import deque
from typing import NamedTuple

import numpy as np

from amcore.quat_kernels import quat_exp, quat_mul, rotation
from simulator.devices import DeviceSuite, Encoders, ForceTorque, Imu, Mocap


class BodyTruth(NamedTuple):
    """The base's exact state at one physics step: p_WB [m], quat_WB (w, x, y, z), R_WB,
    v_W [m/s], w_B [rad/s], a_W [m/s^2] (its acceleration over the last step)."""

    p_WB: np.ndarray
    quat_WB: np.ndarray
    R_WB: np.ndarray
    v_W: np.ndarray
    w_B: np.ndarray
    a_W: np.ndarray


def truth_of(v: list[float], v_W_prev, dt_s: float) -> BodyTruth:
    """The base's truth from its exact values (`World.sensor_values`' first 13) and its world
    velocity at the last step (None at the first: no acceleration yet)."""
    p = np.array(v[0:3])
    quat = np.array(v[3:7])
    R = rotation(quat)
    v_W = R @ np.array(v[7:10])
    a_W = np.zeros(3) if v_W_prev is None else (v_W - v_W_prev) / dt_s
    return BodyTruth(p, quat, R, v_W, np.array(v[10:13]), a_W)


class ReferenceImu(Imu):
    """`sample(truth, t)` -> (omega_m [rad/s], f_m [m/s^2]), body frame."""

    def sample(self, truth: BodyTruth, t: float) -> tuple[np.ndarray, np.ndarray]:
        n = self.rng.standard_normal(12)
        self.b_g = self.phi_g * self.b_g + self.sigma_bg * n[0:3]
        self.b_a = self.phi_a * self.b_a + self.sigma_ba * n[3:6]
        f_B = truth.R_WB.T @ (truth.a_W + np.array([0.0, 0.0, self.g]))
        omega_m = truth.w_B + self.turn_on_g + self.b_g + self.sigma_g * n[6:9]
        f_m = f_B + self.turn_on_a + self.b_a + self.sigma_a * n[9:12]
        return omega_m, f_m


class ReferenceForceTorque(ForceTorque):
    """`sample(wrench_E, t)` -> the reading [f; m] in E."""

    def sample(self, wrench_E, t: float) -> np.ndarray:
        n = self.rng.standard_normal(12)
        self.offset = self.offset + self.drift * n[0:6]
        raw = np.asarray(wrench_E, dtype=float) + self.offset + self.sigma * n[6:12]
        if not self.tared:
            lo, hi = self._window
            if lo <= t < hi:
                self._sum += raw
                self._count += 1
            elif t >= hi:
                self.tare = self._sum / self._count if self._count else raw.copy()
                self.tared = True
        return raw - self.tare


class ReferenceEncoders(Encoders):
    """`sample(q, qdot)` -> the quantized (q, qdot)."""

    @staticmethod
    def _quantize(x: np.ndarray, step: float) -> np.ndarray:
        return np.round(x / step) * step if step > 0.0 else x

    def sample(self, q, qdot) -> tuple[np.ndarray, np.ndarray]:
        return self._quantize(np.asarray(q, dtype=float), self.dq), self._quantize(np.asarray(qdot, dtype=float),
                                                                                  self.dqdot)


class ReferenceMocap(Mocap):
    """`sample_values(x)` -> ((p_m, q_m), lag) when a frame arrives this step, else None;
    `captured` and `dropped` count the frames. `start()` readies a `Mocap`'s constants and
    turn-on biases for it (the class is swapped in, as `ReferenceDeviceSuite` does)."""

    captured = dropped = 0  # plain counters here, not the compiled state's

    def start(self) -> ReferenceMocap:
        self._k = -1
        self._in_flight: deque[tuple[int, np.ndarray, np.ndarray]] = deque()
        self.captured = self.dropped = 0
        return self

    def sample_values(self, x: np.ndarray):
        self._k = k = self._k + 1
        if k % self.every == 0:
            n = self.rng.standard_normal(6)
            lost = self.drop > 0.0 and self.rng.random() < self.drop
            self.captured += 1
            if lost:
                self.dropped += 1
            else:
                p = x[0:3] + self.bias_p + self.sigma_p * n[0:3]
                q = np.array(quat_mul(x[3:7], quat_exp(self.bias_R + self.sigma_R * n[3:6])))
                self._in_flight.append((k + self.lag, p, q))
        if self._in_flight and self._in_flight[0][0] == k:
            _, p, q = self._in_flight.popleft()
            return (p, q), self.lag
        return None


def reference_mocap(*args, **kwargs) -> ReferenceMocap:
    """A `Mocap(*args, **kwargs)` (the same constants and turn-on draws) stepping as above."""
    m = Mocap(*args, **kwargs)
    m.__class__ = ReferenceMocap
    return m.start()


class ReferenceDeviceSuite(DeviceSuite):
    """A `DeviceSuite` (the same construction, the same draws at switch-on) whose `step` runs
    the reference devices above; it reads every value every step."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.imu.__class__, self.ft.__class__, self.encoders.__class__ = (ReferenceImu, ReferenceForceTorque,
                                                                            ReferenceEncoders)
        self.mocap.__class__ = ReferenceMocap
        self.mocap.start()
        self._v_W_prev: np.ndarray | None = None
        self._k = -1  # the last IMU sample

    def needs_reading(self, t: float) -> bool:
        return True

    def step(self, values: list[float], t: float) -> list[float]:
        """The sensor frame's values (p_WB, quat_WB, v_B, w_B from the estimator; q, qdot from
        the encoders; wrench_E from the F/T sensor) after this physics step's exact values."""
        self._k = k = self._k + 1
        truth = truth_of(values, self._v_W_prev, self.dt)
        self._v_W_prev = truth.v_W
        omega_m, f_m = self.imu.sample(truth, t)
        arrived = self.mocap.sample_values(np.concatenate([truth.p_WB, truth.quat_WB]))
        pose, lag = arrived if arrived is not None else (None, 0)
        odo = self.estimator.step(k, omega_m, f_m, pose, lag)
        self._omega_m = omega_m  # the autopilot's rate reads it
        n = self.n
        q, qdot = self.encoders.sample(values[13:13 + n], values[13 + n:13 + 2 * n])
        wrench = self.ft.sample(values[13 + 2 * n:19 + 2 * n], t)
        return [*odo.tolist(), *q.tolist(), *qdot.tolist(), *wrench.tolist()]

