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
- `JointEffortSensor` (attitude mode): the joint torques the arm's servos report. A
  Dynamixel-class servo reports its present current; the driver multiplies it by the torque
  constant and the flight controller (or the servo bus) streams the result as
  AM_JOINT_STATE.effort_nm. Its reading of the torque the joint actually receives
  ([devices.effort], `amcore.config.JointEffortSpec`; its sources in docs/flight_controller.md),
  once per physics step:

      x <- x + (1 - exp(-dt / lag_s)) (tau_applied - x)          first-order lag (lag_s = 0: none)
      effort = resolution_nm * round((x + noise_nm * N(0, 1)) / resolution_nm)   (resolution 0: none)

  with its own seeded generator (scenario seed, sysid, its stream), so that the other devices'
  draws do not depend on it.

Each device's random draws are taken in blocks (`NoiseBlock`, `CaptureDraws`): the numbers,
in the order, that a call per step would give.

The classes here hold each device's constants and the draws made when it is switched on (turn-on
biases, offsets); the per-step arithmetic of the truth, the IMU, the encoders and the F/T
sensor is `simulator.device_kernels.suite_step`, the motion capture's
`simulator.device_kernels.mocap_step` (numba; with the estimator, one call a step for every
AM: `simulator.fleet_kernels.sense`; `Mocap.sample_values` calls `mocap_step` alone, for a
motion capture outside a fleet's arrays, as simulator.object_mocap's). The readable reference
of the compiled steps, in plain Python and numpy, is tests/simulator/reference_devices.py.

`DeviceSuite` holds one AM's devices and its `amcore.estimator.Estimator` (it runs where PX4
runs EKF2, in the flight controller, and its output is the frame's odometry, as PX4 streams
ODOMETRY). `step(values, k)` takes the AM's exact values (the order of
`World.sensor_values`) every physics step and returns the frame's values in that order.
"""
from __future__ import annotations

import math

import numpy as np

from amcore.config import DevicesSpec, EncoderSpec, ForceTorqueSpec, ImuSpec, JointEffortSpec, MocapSpec
from amcore.estimator import BIQUAD, LOOP_GAINS, N_OUT, SNAPSHOT, STATE, Estimator
from amcore.quat_kernels import quat_exp, quat_mul

from . import device_kernels as dk
from . import fleet_kernels

_STREAM = 0xDE71  # distinguishes the devices' streams from the other seeded streams of an AM
IMU, MOCAP, FT = 1, 2, 3  # each device's sub-stream
NOISE_ROWS = 256  # physics steps of draws taken at once (`DeviceSuite.draw_noise`)
MOCAP_ROWS = 64  # motion-capture frames' draws taken at once (`Mocap.draw`)


# ----------------------------------------------------------------------------- random draws, in blocks
class NoiseBlock:
    """Draws of `rng.standard_normal(width)` step after step, taken from blocks of `rows`
    draws at once: numpy's generator fills a large array with the numbers, in the order,
    that the small calls would give (tests/simulator/test_device_kernels.py). `block`: the
    (rows, width) array to hold a block in, e.g. a view of a fleet's (`DeviceArrays`);
    None: one of its own."""

    def __init__(self, rng: np.random.Generator, width: int, rows: int = 256, block: np.ndarray | None = None) -> None:
        self.rng, self.width, self.rows = rng, width, rows
        self.block = np.empty((rows, width)) if block is None else block
        if self.block.shape != (rows, width):
            raise ValueError(f"a noise block of {self.block.shape}, not ({rows}, {width})")
        self._i = rows  # nothing drawn yet: the first `next` fills the first block

    def fill(self) -> None:
        """The next block, in place."""
        self.block[:] = self.rng.standard_normal(self.rows * self.width).reshape(self.rows, self.width)
        self._i = 0

    def next(self) -> np.ndarray:
        if self._i == self.rows:
            self.fill()
        self._i += 1
        return self.block[self._i - 1]


class CaptureDraws:
    """The motion capture's draws, capture after capture, taken a block of `rows` captures at
    once into `block` ((rows, 7): a view of a fleet's, `DeviceArrays`): per capture
    `rng.standard_normal(6)`, then `rng.random()` if `with_drop` (else column 6 is left 0),
    the numbers, in the order, that a call per capture gives. Without drops, one call fills
    the block, as `NoiseBlock`; with them the normals and the uniforms interleave in the
    generator's stream, so each capture's are drawn in turn."""

    def __init__(self, rng: np.random.Generator, rows: int, block: np.ndarray, with_drop: bool) -> None:
        self.rng, self.rows, self.block, self.with_drop = rng, rows, block, with_drop
        if block.shape != (rows, 7):
            raise ValueError(f"a capture block of {block.shape}, not ({rows}, 7)")

    def fill(self) -> None:
        """The next block, in place."""
        b, rng = self.block, self.rng
        if not self.with_drop:
            b[:, :6] = rng.standard_normal(self.rows * 6).reshape(self.rows, 6)
            return
        for r in range(self.rows):
            b[r, :6] = rng.standard_normal(6)
            b[r, 6] = rng.random()


# ----------------------------------------------------------------------------- the devices
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
    (p_m, q_m (w, x, y, z)) and its age in steps when a frame arrives this step, else None.

    Its per-step arithmetic is `simulator.device_kernels.mocap_step`, on its constants and state
    (`MOCAP_CONSTANTS`, `MOCAP_STATE`, a ring of `MOCAP_PENDING`) and a block of draws
    (`CaptureDraws`): arrays of its own, or its rows of a fleet's once
    `DeviceArrays.adopt_mocap` has moved it there (then `simulator.fleet_kernels.sense` steps it)."""

    def __init__(self, spec: MocapSpec, scale: float, dt_s: float, rng: np.random.Generator,
                 rows: int = MOCAP_ROWS) -> None:
        self.rng = rng
        self.every = max(1, round(1.0 / (spec.rate_hz * dt_s)))
        self.lag = int(round(spec.latency_s / dt_s))
        self.sigma_p, self.sigma_R = scale * spec.position_noise_m, scale * spec.attitude_noise_rad
        self.drop = spec.drop_probability
        self.bias_p = scale * spec.position_bias_m * rng.standard_normal(3)
        self.bias_R = scale * spec.attitude_bias_rad * rng.standard_normal(3)
        c = np.zeros(1, dk.MOCAP_CONSTANTS)
        c["every"], c["lag"], c["sigma_p"], c["sigma_R"] = self.every, self.lag, self.sigma_p, self.sigma_R
        c["drop"], c["bias_p"], c["bias_R"] = self.drop, self.bias_p, self.bias_R
        state = np.zeros(1, dk.MOCAP_STATE)
        state["k"] = -1
        self.use(c, state, np.zeros(self.lag // self.every + 1, dk.MOCAP_PENDING),
                 np.zeros((rows, dk.MOCAP_DRAWS)), np.full(1, rows, np.int64))
        self._p_m, self._q_m = np.zeros(3), np.zeros(4)

    def use(self, constants: np.ndarray, state: np.ndarray, pending: np.ndarray, draws: np.ndarray,
            draw_row: np.ndarray) -> None:
        """Step on these arrays (`mocap_step`'s; views of a fleet's row, or its own)."""
        if pending.shape[0] <= self.lag // self.every:
            raise ValueError(f"{pending.shape[0]} frames in flight held, {self.lag // self.every + 1} needed")
        self.constants, self.state, self.pending, self.draw_row = constants, state, pending, draw_row
        self.draws = CaptureDraws(self.rng, draws.shape[0], draws, self.drop > 0.0)

    @property
    def frame_period_steps(self) -> int:
        return self.every

    @property
    def captured(self) -> int:
        """Frames captured so far, the dropped ones included."""
        return int(self.state["captured"][0])

    @property
    def dropped(self) -> int:
        return int(self.state["dropped"][0])

    def draw(self) -> None:
        """The next block of draws (`CaptureDraws`), taken from its first row on."""
        self.draws.fill()
        self.draw_row[0] = 0

    def sample_values(self, x: np.ndarray):
        """This step's frame, if one arrives, from the base's exact values x (p_WB, quat_WB
        first, as `World.sensor_values`: all a motion capture sees), read on the steps that
        capture a frame."""
        if self.draw_row[0] == self.draws.rows:
            self.draw()
        if not dk.mocap_step(self.constants, self.state, self.pending, np.asarray(x, dtype=np.float64),
                             self.draws.block, self.draw_row, self._p_m, self._q_m):
            return None
        return (self._p_m.copy(), self._q_m.copy()), self.lag


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


class DeviceArrays:
    """The devices' and estimators' state of `count` AMs, stacked (one row per AM, its slot),
    so that one compiled call (`simulator.fleet_kernels.sense`) steps every AM; each
    `DeviceSuite` keeps views of its row. `step` takes the AMs' exact values of one physics step."""

    def __init__(self, count: int, n_joints: int, history_steps: int, dt_s: float, g: float,
                 rows: int = NOISE_ROWS, mocap_rows: int = MOCAP_ROWS) -> None:
        self.count, self.n, self._dt, self._g = count, n_joints, dt_s, g
        self.constants, self.state = np.zeros(count, dk.CONSTANTS), np.zeros(count, dk.STATE)
        self.imu_noise, self.ft_noise = np.zeros((count, rows, 12)), np.zeros((count, rows, 12))
        self.noise_row = np.zeros(count, np.int64)  # each AM's next row of its blocks
        self._rows = rows
        self.k = np.full(count, -1, np.int64)  # each AM's last IMU sample
        self.values = np.zeros((count, N_OUT + 2 * n_joints + 6))  # the exact values of the step (the base's: 13)
        self.full = np.zeros(count, np.bool_)  # whether a row holds the arm's and the wrist's values too
        self.frames = np.zeros((count, N_OUT + 2 * n_joints + 6))  # each AM's frame values, odometry first
        self.est_x, self.est_hist = np.zeros(count, STATE), np.zeros((count, history_steps), SNAPSHOT)
        self.est_lpf = np.zeros((count, 2, 3))
        self.est_coef, self.est_gains = np.zeros(count, BIQUAD), np.zeros(count, LOOP_GAINS)
        self.innovation = np.zeros((count, 6))
        self.mocap_c, self.mocap_state = np.zeros(count, dk.MOCAP_CONSTANTS), np.zeros(count, dk.MOCAP_STATE)
        self.mocap_pending = np.zeros((count, history_steps), dk.MOCAP_PENDING)  # the latency is shorter (DeviceSuite)
        self.mocap_draws = np.zeros((count, mocap_rows, dk.MOCAP_DRAWS))
        self.mocap_row = np.full(count, mocap_rows, np.int64)  # each AM's next row of its block
        self._mocap_rows = mocap_rows
        # the motion capture's frame of the step, for the estimator (`simulator.fleet_kernels.sense` writes it)
        self.has_pose, self.lag = np.zeros(count, np.bool_), np.zeros(count, np.int64)
        self.p_m, self.q_m = np.zeros((count, 3)), np.zeros((count, 4))
        self.suites: list[DeviceSuite | None] = [None] * count
        self._all = np.arange(count, dtype=np.int64)
        self._sense_args = (self.values, self.full, self.constants, self.state, self.imu_noise, self.ft_noise,
                            self.noise_row, self.k, self.mocap_c, self.mocap_state, self.mocap_pending,
                            self.mocap_draws, self.mocap_row, self.frames, self.est_x, self.est_hist, self.est_lpf,
                            self.est_coef, self.est_gains, self.has_pose, self.lag, self.p_m, self.q_m,
                            self.innovation, dt_s, g)

    def adopt_mocap(self, mocap: Mocap, slot: int) -> None:
        """AM `slot`'s motion capture (not yet stepped) moved onto its rows here: its constants
        and state copied, and it steps on views of them from now on."""
        i = slot
        self.mocap_c[i], self.mocap_state[i] = mocap.constants[0], mocap.state[0]
        self.mocap_row[i] = self._mocap_rows
        mocap.use(self.mocap_c[i:i + 1], self.mocap_state[i:i + 1], self.mocap_pending[i], self.mocap_draws[i],
                  self.mocap_row[i:i + 1])

    def refill(self, slot: int) -> None:
        """New blocks of draws for AM `slot` where it has used its last: the IMU's and the F/T
        sensor's (a row a step), the motion capture's (a row a frame)."""
        if self.noise_row[slot] == self._rows:
            self.suites[slot].draw_noise()
        if self.mocap_row[slot] == self._mocap_rows:
            self.suites[slot].mocap.draw()

    def load(self, values, slot: int) -> None:
        """AM `slot`'s exact values of this step (full, or the base's 13), and new blocks of
        draws if it used its last (`refill`)."""
        self.refill(slot)
        m = len(values)
        self.values[slot, :m] = values
        self.full[slot] = m > N_OUT

    def step(self, t: float, slots: np.ndarray | None = None) -> None:
        """One physics step of the loaded AMs (`slots`; None: all) in one compiled call; their
        frames into `frames`."""
        fleet_kernels.sense(self._all if slots is None else slots, t, *self._sense_args)

    def sense_arrays(self) -> tuple:
        """The arrays `simulator.fleet_kernels.sense` takes after the slots and the time (made
        once: the arrays are filled in place, never replaced)."""
        return self._sense_args


class DeviceSuite:
    """One AM's devices and estimator (module doc). Seeded by (scenario seed, sysid); each
    device draws from its own stream, so changing one device's levels leaves the others'
    draws alone.

    Its state is a row (`slot`) of a `DeviceArrays` (its own, of one row, unless a fleet's is
    given): the truth's, the IMU's, the encoders' and the F/T sensor's per-step arithmetic is
    `simulator.device_kernels.suite_step`, the motion capture's `mocap_step`, the estimator's
    `amcore.estimator`, all called by `simulator.fleet_kernels.sense` over every AM of the
    arrays at once; the draws are taken in blocks (the same numbers in the same order); the
    device objects hold the draws made at construction."""

    def __init__(self, spec: DevicesSpec, n_joints: int, dt_s: float, g: float, seed: int, sysid: int,
                 initial_values: list[float], arrays: DeviceArrays | None = None, slot: int = 0) -> None:
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
        a = DeviceArrays(1, n_joints, e.history_steps, dt_s, g) if arrays is None else arrays
        if (a.n, a.est_hist.shape[1], a._dt, a._g) != (n_joints, e.history_steps, dt_s, g):
            raise ValueError(f"device arrays for {a.n} joints, {a.est_hist.shape[1]} history steps, dt {a._dt} s "
                             f"and g {a._g}, not {n_joints}, {e.history_steps}, {dt_s} and {g}")
        self.arrays, self.slot = a, slot
        self._slots = np.array([slot], np.int64)  # its row alone, as `DeviceArrays.step` takes it
        a.suites[slot] = self
        i = slot
        # the estimator is aligned on the ground before take-off, on a motion-capture pose
        p0 = np.array(initial_values[0:3]) + self.mocap.bias_p
        q0 = np.array(quat_mul(np.array(initial_values[3:7]), quat_exp(self.mocap.bias_R)))
        self._frame = a.frames[i]  # a frame's values, written in place
        self.estimator = Estimator(p0, q0, dt_s, self.mocap.every * dt_s, g, e.attitude_bandwidth_radps,
                                   e.position_bandwidth_radps, e.gyro_cutoff_hz, e.history_steps,
                                   out=self._frame[:N_OUT],
                                   storage=(a.est_x[i:i + 1], a.est_hist[i], a.est_lpf[i], a.est_coef[i:i + 1],
                                            a.est_gains[i:i + 1]))
        self.estimator.innovation = a.innovation[i]
        self._b_g_estimate = a.est_x["b_g"][i]  # a view: the estimator updates it in place
        a.k[i] = -1
        a.adopt_mocap(self.mocap, i)
        self._kernel_state()

    def _kernel_state(self) -> None:
        """The device objects' constants and state as `simulator.device_kernels.suite_step`
        takes them (`CONSTANTS` and `STATE`, rows of the arrays' records; the parts named here
        are views of them), and the first blocks of draws."""
        imu, ft, a, i = self.imu, self.ft, self.arrays, self.slot
        c, st = a.constants[i], a.state[i]  # views of the records
        c["phi_g"], c["sigma_bg"], c["phi_a"], c["sigma_ba"] = imu.phi_g, imu.sigma_bg, imu.phi_a, imu.sigma_ba
        c["sigma_g"], c["sigma_a"] = imu.sigma_g, imu.sigma_a
        c["turn_on_g"], c["turn_on_a"] = imu.turn_on_g, imu.turn_on_a
        c["ft_drift"], c["ft_sigma"], (c["ft_lo"], c["ft_hi"]) = ft.drift, ft.sigma, ft._window
        self._tare_from = ft._window[0]  # `needs_reading`'s, on Python values
        self._tare_pending = not ft.tared
        c["dt"], c["g"], c["dq"], c["dqdot"] = self.dt, imu.g, self.encoders.dq, self.encoders.dqdot
        st["b_g"], st["b_a"] = imu.b_g, imu.b_a
        self._omega_m, self._f_m = a.state["omega_m"][i], a.state["f_m"][i]  # views: the kernel writes them
        st["ft_offset"], st["ft_tared"] = ft.offset, 1.0 if ft.tared else 0.0
        self._state = st
        rows = a.imu_noise.shape[1]
        self._imu_noise = NoiseBlock(imu.rng, 12, rows, a.imu_noise[i])
        self._ft_noise = NoiseBlock(ft.rng, 12, rows, a.ft_noise[i])
        a.noise_row[i] = rows  # no draws yet: the first step takes the first blocks

    def draw_noise(self) -> None:
        """The next blocks of the IMU's and the F/T sensor's standard normal draws (12 a step
        each, `NoiseBlock`: the numbers, in the order, that a call per step
        would give) into the arrays' rows; the compiled step takes them row after row."""
        self._imu_noise.fill()
        self._ft_noise.fill()
        self.arrays.noise_row[self.slot] = 0

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
        the encoders; wrench_E from the F/T sensor) after this physics step's exact values: this
        AM's row of `DeviceArrays.step` (the devices, the motion capture, the estimator).
        `values` may be the base's alone (the first 13, `World.base_values`) on a step that
        sends no frame and reads no F/T (`needs_reading` False): then only the odometry (the
        first 13 of a frame) is returned, and the encoders are not read; the devices' draws
        and drift advance as on any step."""
        full = len(values) > N_OUT
        if not full and self.needs_reading(t):
            raise ValueError(f"t = {t} s: the F/T tare needs this step's reading; give the full values")
        a = self.arrays
        a.load(values, self.slot)
        a.step(t, self._slots)
        return self._frame.tolist() if full else self._frame[:N_OUT].tolist()


# ----------------------------------------------------------------------------- the servos' joint effort
_EFFORT_STREAM = 0xEFF0  # distinguishes the effort's stream from the other seeded streams of an AM


class JointEffortSensor:
    """One arm's measured joint torques; `sample(tau_applied)` once per physics step of dt_s.

    `advance(tau_applied)` is `sample` for a step whose reading may not be read: the lag and
    the draws advance (the draws taken in blocks, `NoiseBlock`), and the reading is
    formed when `last` is read, from the same numbers, so that a run reads the same readings
    either way."""

    def __init__(self, spec: JointEffortSpec, scale: float, n: int, dt_s: float, seed: int, sysid: int) -> None:
        self.noise_nm = scale * spec.noise_nm
        self.resolution_nm = spec.resolution_nm
        self.alpha = 1.0 if spec.lag_s <= 0.0 else -math.expm1(-dt_s / spec.lag_s)
        self._rng = np.random.default_rng([seed, sysid, _EFFORT_STREAM])
        self._noise = NoiseBlock(self._rng, n) if self.noise_nm > 0.0 else None
        self._x: list[float] | None = None  # the lagged torque, on Python floats
        self._draw: np.ndarray | None = None  # the last step's draws
        self.n = n
        self._last: np.ndarray | None = np.zeros(n)

    def advance(self, tau_applied_nm) -> None:
        """One more physics step with `tau_applied_nm` acting; its reading is `last`."""
        u = np.asarray(tau_applied_nm, dtype=float).tolist()
        x = self._x
        self._x = u if x is None else [xi + self.alpha * (ui - xi) for xi, ui in zip(x, u)]
        self._draw = None if self._noise is None else self._noise.next()
        self._last = None

    def sample(self, tau_applied_nm) -> np.ndarray:
        """The reading [N m] after one more physics step with `tau_applied_nm` acting."""
        self.advance(tau_applied_nm)
        return self.last

    @property
    def last(self) -> np.ndarray:
        """The reading of the last step [N m] (zeros before the first)."""
        if self._last is None:
            x = np.array(self._x)
            y = x + self.noise_nm * self._draw if self._draw is not None else x
            if self.resolution_nm > 0.0:
                y = self.resolution_nm * np.round(y / self.resolution_nm)
            self._last = y
        return self._last
