"""Sensors as devices produce them, and the flight controller's estimator between them and the
sensor frames (pure: numpy, and amcore's estimator; no I/O).

Each device is a small object with its own seeded generator and a `sample(truth, t)` step,
parameters under the names of its reference model ([devices] in a scenario,
`amcore.config.DevicesSpec`; values and sources in configs/randomize/default.toml):

- `Imu`: gyroscope and accelerometer as PX4's Gazebo IMU plugin models them (white noise of
  a given density, a Gauss-Markov bias driven by a random walk, a turn-on bias), every
  physics step. The accelerometer measures specific force in the body frame,
  f_B = R_WB^T (a_W + g e_3), with a_W the base's acceleration over the last physics step
  (the difference of PyBullet's velocities).
- `Mocap`: the base pose every 1 / rate_hz s, delivered latency_s later, with white noise,
  a fixed position and body-frame attitude bias, and frames dropped at random.
- `ForceTorque`: the wrist F/T reading with white noise, a power-on offset that drifts as a
  random walk, and a tare (the driver's bias command) at a set time.
- `Encoders`: joint positions quantized to whole counts, velocities to the servo's unit.

The classes here hold each device's constants and the draws made when it is switched on (turn-on
biases, offsets); the per-step arithmetic of the truth, the IMU, the encoders and the F/T
sensor is `simulator.device_kernels` (numba; one call a step), the motion capture's is
`Mocap.sample_values`. The readable reference of the compiled steps, in plain Python and
numpy, is tests/simulator/reference_devices.py.

`DeviceSuite` holds one AM's devices and its `amcore.estimator.Estimator` (it runs where PX4
runs EKF2, in the flight controller, and its output is the frame's odometry, as PX4 streams
ODOMETRY). `step(values, k)` takes the AM's exact values (the order of
`World.sensor_values`) every physics step and returns the frame's values in that order.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from amcore.config import DevicesSpec, EncoderSpec, ForceTorqueSpec, ImuSpec, MocapSpec
from amcore.estimator import BG, N_OUT, Estimator
from amcore.quat_kernels import quat_exp, quat_mul

from . import device_kernels as dk

_STREAM = 0xDE71  # distinguishes the devices' streams from the other seeded streams of an AM
IMU, MOCAP, FT = 1, 2, 3  # each device's sub-stream


def _gauss_markov(sigma_rw: float, tau_s: float, dt_s: float) -> tuple[float, float]:
    """(phi, sigma_d) of the bias's discrete update b <- phi b + sigma_d N(0, 1), as the Gazebo
    IMU plugin discretizes a first-order Gauss-Markov process of correlation time tau_s driven
    by a random walk of sigma_rw."""
    if tau_s <= 0.0:
        return 1.0, sigma_rw * math.sqrt(dt_s)
    return math.exp(-dt_s / tau_s), math.sqrt(-sigma_rw ** 2 * tau_s / 2.0 * math.expm1(-2.0 * dt_s / tau_s))


class Imu:
    """Gyroscope and accelerometer (module doc): constants, turn-on biases, and the Gauss-Markov
    biases' initial values `b_g`, `b_a`; its draws come from `rng`."""

    def __init__(self, spec: ImuSpec, scale: float, dt_s: float, g: float, rng: np.random.Generator) -> None:
        self.rng, self.g = rng, g
        s = spec
        self.sigma_g = scale * s.gyroscope_noise_density / math.sqrt(dt_s)
        self.sigma_a = scale * s.accelerometer_noise_density / math.sqrt(dt_s)
        self.phi_g, self.sigma_bg = _gauss_markov(scale * s.gyroscope_random_walk,
                                                  s.gyroscope_bias_correlation_time_s, dt_s)
        self.phi_a, self.sigma_ba = _gauss_markov(scale * s.accelerometer_random_walk,
                                                  s.accelerometer_bias_correlation_time_s, dt_s)
        self.turn_on_g = scale * s.gyroscope_turn_on_bias_sigma * rng.standard_normal(3)
        self.turn_on_a = scale * s.accelerometer_turn_on_bias_sigma * rng.standard_normal(3)
        self.b_g = np.zeros(3)  # the Gauss-Markov part
        self.b_a = np.zeros(3)


class Mocap:
    """Motion capture (module doc); `sample_values(x)` once per physics step -> a pose
    (p_m, q_m (w, x, y, z)) and its age in steps when a frame arrives this step, else None."""

    def __init__(self, spec: MocapSpec, scale: float, dt_s: float, rng: np.random.Generator) -> None:
        self.rng = rng
        self.every = max(1, round(1.0 / (spec.rate_hz * dt_s)))
        self.lag = int(round(spec.latency_s / dt_s))
        self.sigma_p, self.sigma_R = scale * spec.position_noise_m, scale * spec.attitude_noise_rad
        self.drop = spec.drop_probability
        self.bias_p = scale * spec.position_bias_m * rng.standard_normal(3)
        self.bias_R = scale * spec.attitude_bias_rad * rng.standard_normal(3)
        self._k = -1
        self._in_flight: deque[tuple[int, np.ndarray, np.ndarray]] = deque()
        self.dropped = self.captured = 0

    @property
    def frame_period_steps(self) -> int:
        return self.every

    def sample_values(self, x: np.ndarray):
        """This step's frame, if one arrives, from the base's exact values x (p_WB, quat_WB
        first, as `World.sensor_values`: all a motion capture sees), read on the steps that
        capture a frame."""
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


class ForceTorque:
    """Wrist F/T sensor (module doc): constants, the power-on offset, the tare window; its
    draws come from `rng`."""

    def __init__(self, spec: ForceTorqueSpec, scale: float, dt_s: float, rng: np.random.Generator) -> None:
        self.rng, self.spec = rng, spec
        self.sigma = scale * np.repeat([spec.force_noise_n, spec.torque_noise_nm], 3)
        self.drift = scale * np.repeat([spec.force_drift_n_per_sqrt_s, spec.torque_drift_nm_per_sqrt_s], 3) \
            * math.sqrt(dt_s)
        self.offset = scale * np.repeat([spec.force_offset_n, spec.torque_offset_nm], 3) * rng.standard_normal(6)
        self.tare = np.zeros(6)
        self._sum, self._count = np.zeros(6), 0
        self.tared = spec.tare_at_s < 0.0  # nothing to do: counts as done
        self._window = (spec.tare_at_s - spec.tare_window_s, spec.tare_at_s)


class Encoders:
    """Joint encoders (module doc): the position step (one count) and the velocity quantum;
    0 is exact. Readings round to the nearest count, as an absolute magnetic encoder's."""

    def __init__(self, spec: EncoderSpec) -> None:
        self.dq = 2.0 * math.pi / spec.counts_per_rev if spec.counts_per_rev > 0 else 0.0
        self.dqdot = spec.velocity_quantum_radps


class DeviceSuite:
    """One AM's devices and estimator (module doc). Seeded by (scenario seed, sysid); each
    device draws from its own stream, so changing one device's levels leaves the others'
    draws alone.

    The truth's, the IMU's, the encoders' and the F/T sensor's per-step arithmetic is
    `simulator.device_kernels.suite_step` (numba; the draws taken in blocks, the same numbers
    in the same order); the device objects hold the draws made at construction."""

    def __init__(self, spec: DevicesSpec, n_joints: int, dt_s: float, g: float, seed: int, sysid: int,
                 initial_values: list[float]) -> None:
        rng = lambda sub: np.random.default_rng([seed, sysid, _STREAM, sub])  # noqa: E731
        self.n, self.dt = n_joints, dt_s
        self.imu = Imu(spec.imu, spec.scale, dt_s, g, rng(IMU))
        self.mocap = Mocap(spec.mocap, spec.scale, dt_s, rng(MOCAP))
        self.ft = ForceTorque(spec.ft, spec.scale, dt_s, rng(FT))
        self.encoders = Encoders(spec.encoders)
        e = spec.estimator
        if self.mocap.lag >= e.history_steps:
            raise ValueError(f"[devices.mocap].latency_s is {self.mocap.lag} steps; [devices.estimator]."
                             f"history_steps ({e.history_steps}) must be longer")
        # the estimator is aligned on the ground before take-off, on a motion-capture pose
        p0 = np.array(initial_values[0:3]) + self.mocap.bias_p
        q0 = np.array(quat_mul(np.array(initial_values[3:7]), quat_exp(self.mocap.bias_R)))
        self._frame = np.empty(N_OUT + 2 * n_joints + 6)  # a frame's values, written in place
        self.estimator = Estimator(p0, q0, dt_s, self.mocap.every * dt_s, g, e.attitude_bandwidth_radps,
                                   e.position_bandwidth_radps, e.gyro_cutoff_hz, e.history_steps,
                                   out=self._frame[:N_OUT])
        self._b_g_estimate = self.estimator.x[BG:BG + 3]  # a view: the estimator updates it in place
        self._k = -1
        self._kernel_state()

    def _kernel_state(self) -> None:
        """The device objects' constants and state as `simulator.device_kernels.suite_step`
        takes them (`CONSTANTS` and `STATE`, each a record in an array of one; the parts named
        here are views of them)."""
        imu, ft = self.imu, self.ft
        self._c, self._s = np.zeros(1, dk.CONSTANTS), np.zeros(1, dk.STATE)
        c, st = self._c[0], self._s[0]  # views of the records
        c["phi_g"], c["sigma_bg"], c["phi_a"], c["sigma_ba"] = imu.phi_g, imu.sigma_bg, imu.phi_a, imu.sigma_ba
        c["sigma_g"], c["sigma_a"] = imu.sigma_g, imu.sigma_a
        c["turn_on_g"], c["turn_on_a"] = imu.turn_on_g, imu.turn_on_a
        c["ft_drift"], c["ft_sigma"], (c["ft_lo"], c["ft_hi"]) = ft.drift, ft.sigma, ft._window
        self._tare_from = ft._window[0]  # `needs_reading`'s, on Python values
        self._tare_pending = not ft.tared
        c["dt"], c["g"], c["dq"], c["dqdot"] = self.dt, imu.g, self.encoders.dq, self.encoders.dqdot
        st["b_g"], st["b_a"] = imu.b_g, imu.b_a
        self._omega_m, self._f_m = self._s["omega_m"][0], self._s["f_m"][0]  # views: the kernel writes them
        st["ft_offset"], st["ft_tared"] = ft.offset, 1.0 if ft.tared else 0.0
        self._state = st
        self._imu_noise, self._ft_noise = dk.NoiseBlock(imu.rng, 12), dk.NoiseBlock(ft.rng, 12)
        self._tail = self._frame[N_OUT:]

    @property
    def autopilot_rate(self) -> np.ndarray:
        """The body rate the autopilot's rate loop takes after the last step [rad/s]: the gyro
        with the estimator's bias removed, which the loop filters once itself (IMU_GYRO_CUTOFF),
        as PX4's VehicleAngularVelocity takes EKF2's bias; the odometry's rate, already
        low-passed for the law, would be filtered twice. Formed when read (attitude mode only)."""
        return self._omega_m - self._b_g_estimate

    def needs_reading(self, t: float) -> bool:
        """Whether a step at t needs the arm's and the wrist's values although no frame is sent:
        the F/T tare averages its readings until it is done."""
        if self._tare_pending and self._state["ft_tared"] != 0.0:  # done by the last step's kernel
            self._tare_pending = False
        return self._tare_pending and t >= self._tare_from

    def step(self, values: list[float], t: float) -> list[float]:
        """The sensor frame's values (p_WB, quat_WB, v_B, w_B from the estimator; q, qdot from
        the encoders; wrench_E from the F/T sensor) after this physics step's exact values: one
        call of `simulator.device_kernels.suite_step`, the motion capture, one of the
        estimator's. `values` may be the base's alone (the first 13, `World.base_values`) on a step that
        sends no frame and reads no F/T (`needs_reading` False): then only the odometry (the
        first 13 of a frame) is returned, and the encoders are not read; the devices' draws
        and drift advance as on any step."""
        self._k = k = self._k + 1
        x = np.array(values)
        full = x.shape[0] > N_OUT
        if not full and self.needs_reading(t):
            raise ValueError(f"t = {t} s: the F/T tare needs this step's reading; give the full values")
        dk.suite_step(x, t, self._c, self._s, self._imu_noise.next(), self._ft_noise.next(), self._tail)
        arrived = self.mocap.sample_values(x)
        pose, lag = arrived if arrived is not None else (None, 0)
        odo = self.estimator.step(k, self._omega_m, self._f_m, pose, lag)  # into self._frame's head
        return self._frame.tolist() if full else odo.tolist()
