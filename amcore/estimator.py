"""The flight controller's state estimator: a complementary filter fusing a 1 kHz IMU with
motion capture, as PX4's EKF2 fuses external vision (pure math: numpy and numba, no I/O).

State (world frame W, ENU; body frame B, FLU): position p_WB [m], velocity v_WB_W [m/s],
attitude q_WB (w, x, y, z), gyroscope bias b_g [rad/s] and accelerometer bias b_a [m/s^2]
in B. Every IMU sample propagates it (strapdown, `predict`):

    w = omega_m - b_g,   a_W = R_WB (f_m - b_a) - g e_3
    q <- q (x) exp(w dt),   p <- p + v dt + a_W dt^2 / 2,   v <- v + a_W dt

(f_m measured over the step that ends at the sample, rotated by the attitude at its end; the
first sample only stores the initial state).

A motion-capture pose (p_m, q_m) measured L steps ago (its latency) is fused against the
state of that time, kept in a history of the last N steps (EKF2's delayed-fusion horizon),
and the correction is carried forward to now, as EKF2's output predictor carries its
delayed-horizon correction to the IMU-rate output (`fuse_pose`). The innovations are

    r = p_m - p(k - L)                       (world frame)
    e = log(q(k - L)^-1 (x) q_m)              (body frame)

and the gains of a third-order position loop and a second-order attitude loop with all
poles at -omega_p and -omega_R (critically damped), applied once per frame of period T_m:

    delta_p = 3 omega_p T_m r,   delta_v = 3 omega_p^2 T_m r,   b_a <- b_a - omega_p^3 T_m R^T r
    delta_theta = 2 omega_R T_m e,                               b_g <- b_g - omega_R^2 T_m e

(the loop's characteristic polynomials are (s + omega_p)^3 and (s + omega_R)^2). A state i
steps after the measurement takes p += delta_p + i dt delta_v, v += delta_v, q <- q (x)
exp(delta_theta): exact for the position and velocity, whose error propagates linearly,
and to first order in the rotation over the lag for the attitude.

The body rate handed to the law is omega_m - b_g, optionally through PX4's 2nd-order
Butterworth low-pass (IMU_GYRO_CUTOFF; `biquad_coefficients`).

Why a complementary filter, not an error-state EKF: with a motion-capture pose at 100 Hz
and a tactical-grade-or-better IMU the EKF's gains reach a steady state within a second;
fixed gains of that shape give the same smooth output at a fraction of the cost (no 15x15
covariance per step) and are set by two bandwidths a user can reason about.

The quaternion helpers are amcore.quat_kernels' (tuples in, tuples out).
"""
from __future__ import annotations

import math

import numpy as np

from .jit import kernel
from .quat_kernels import quat_conj, quat_exp, quat_log, quat_mul, quat_normalized, rotation

_F8 = np.float64
# the filter's state (a numpy record, in an array of one: numba reads and writes it by name):
# p_WB [m], v_WB_W [m/s], q_WB (w, x, y, z), the gyroscope bias b_g [rad/s] and the
# accelerometer bias b_a [m/s^2] in B
STATE = np.dtype([("p", _F8, 3), ("v", _F8, 3), ("q", _F8, 4), ("b_g", _F8, 3), ("b_a", _F8, 3)])
# one step of the history (an array of these records, one per step of the delayed-fusion horizon)
SNAPSHOT = np.dtype([("p", _F8, 3), ("v", _F8, 3), ("q", _F8, 4)])
# the gyro low-pass's coefficients (a numpy record, in an array of one: `biquad_coefficients`):
# the numerator b0, b1, b2 and the denominator a1, a2 (a0 = 1)
BIQUAD = np.dtype([("b0", _F8), ("b1", _F8), ("b2", _F8), ("a1", _F8), ("a2", _F8)])
# the fusion's gains (a numpy record, in an array of one: `loop_gains`), each times the frame
# period: position k_p, velocity k_v, accelerometer bias k_a, attitude k_R, gyroscope bias k_g
LOOP_GAINS = np.dtype([("k_p", _F8), ("k_v", _F8), ("k_a", _F8), ("k_R", _F8), ("k_g", _F8)])
# indices into the output (one odometry frame): p_WB, quat_WB (w, x, y, z; w >= 0), v_B, w_B
N_OUT = 13


# ----------------------------------------------------------------------------- gyro low-pass
def biquad_coefficients(sample_hz: float, cutoff_hz: float) -> np.ndarray:
    """The `BIQUAD` record (in an array of one) of PX4's math::LowPassFilter2p (2nd-order
    Butterworth by the bilinear transform); cutoff 0 gives the pass-through (b0 = 1, the rest 0)."""
    coef = np.zeros(1, BIQUAD)
    c = coef[0]
    if cutoff_hz <= 0.0:
        c["b0"] = 1.0
        return coef
    if not cutoff_hz < 0.5 * sample_hz:
        raise ValueError(f"gyro cutoff {cutoff_hz} Hz must be below half the IMU rate {sample_hz} Hz")
    ohm = math.tan(math.pi * cutoff_hz / sample_hz)
    a0 = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
    b0 = ohm * ohm / a0
    c["b0"], c["b1"], c["b2"] = b0, 2.0 * b0, b0
    c["a1"], c["a2"] = 2.0 * (ohm * ohm - 1.0) / a0, (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / a0
    return coef


@kernel
def biquad_step(d, coef, x):
    """One step of the biquad (direct form II) per axis; d (2, 3) its delay state, updated;
    coef the `BIQUAD` record in an array of one."""
    c = coef[0]
    y = np.empty(3)
    for i in range(3):
        d0 = x[i] - d[0, i] * c.a1 - d[1, i] * c.a2
        y[i] = d0 * c.b0 + d[0, i] * c.b1 + d[1, i] * c.b2
        d[1, i] = d[0, i]
        d[0, i] = d0
    return y


@kernel
def biquad_reset(d, coef, x):
    """Delay state at steady state on input x (PX4's reset(sample)); coef as `biquad_step`'s."""
    c = coef[0]
    s = c.b0 + c.b1 + c.b2
    for i in range(3):
        d[0, i] = x[i] / s
        d[1, i] = x[i] / s


# ----------------------------------------------------------------------------- the filter
@kernel
def _set_quat(dst, q):
    """A quaternion tuple q into the array dst (4,)."""
    dst[0], dst[1], dst[2], dst[3] = q[0], q[1], q[2], q[3]


@kernel
def _copy(dst, src):
    """src's entries into dst (a record's field into another's: the state's p, v, q into a
    history step and back)."""
    for i in range(src.shape[0]):
        dst[i] = src[i]


@kernel
def predict(x, hist, k, omega_m, f_m, dt, g):
    """Strapdown propagation over one IMU sample (module doc); stores the state of step k
    in hist[k % N] (p, v, q). x: the `STATE` record in an array of one; hist: `SNAPSHOT`s."""
    s = x[0]
    w = omega_m - s.b_g
    a_B = f_m - s.b_a
    _set_quat(s.q, quat_normalized(quat_mul(s.q, quat_exp(w * dt))))
    R = rotation(s.q)  # the sample's specific force is taken at the end of its interval
    a_W = np.zeros(3)
    for i in range(3):
        a_W[i] = R[i, 0] * a_B[0] + R[i, 1] * a_B[1] + R[i, 2] * a_B[2]
    a_W[2] -= g
    for i in range(3):
        s.p[i] += s.v[i] * dt + 0.5 * a_W[i] * dt * dt
        s.v[i] += a_W[i] * dt
    h = hist[k % hist.shape[0]]
    _copy(h.p, s.p)
    _copy(h.v, s.v)
    _copy(h.q, s.q)


@kernel
def fuse_pose(x, hist, k, lag, p_m, q_m, gains, dt):
    """Fuse a pose measured at step k - lag (lag < N) into the state of step k and into the
    history after the measurement (module doc). gains: the `LOOP_GAINS` record in an array of
    one. Returns the innovations (r [m], e [rad]) as one (6,) array."""
    s = x[0]
    gn = gains[0]
    N = hist.shape[0]
    past = hist[(k - lag) % N]
    p_past, q_past = past.p, past.q
    r = p_m - p_past
    e = np.array(quat_log(quat_mul(quat_conj(q_past), q_m)))
    R_past = rotation(q_past)
    dp = gn.k_p * r
    dv = gn.k_v * r
    dq = quat_exp(gn.k_R * e)
    for i in range(3):
        s.b_a[i] -= gn.k_a * (R_past[0, i] * r[0] + R_past[1, i] * r[1] + R_past[2, i] * r[2])
        s.b_g[i] -= gn.k_g * e[i]
    for a in range(lag + 1):  # the history from the measurement's step to now
        h = hist[(k - lag + a) % N]
        for i in range(3):
            h.p[i] += dp[i] + a * dt * dv[i]
            h.v[i] += dv[i]
        _set_quat(h.q, quat_normalized(quat_mul(h.q, dq)))
    h = hist[k % N]
    _copy(s.p, h.p)
    _copy(s.v, h.v)
    _copy(s.q, h.q)
    out = np.empty(6)
    out[0:3] = r
    out[3:6] = e
    return out


@kernel
def odometry(x, lpf, coef, omega_m, out):
    """The odometry frame of the current state into out (N_OUT,): p_WB, quat_WB (w >= 0),
    v_B = R^T v_W, w_B = lowpass(omega_m - b_g)."""
    st = x[0]
    q = st.q
    s = 1.0 if q[0] >= 0.0 else -1.0
    R = rotation(q)
    w = biquad_step(lpf, coef, omega_m - st.b_g)
    v = st.v
    for i in range(3):
        out[i] = st.p[i]
        out[7 + i] = R[0, i] * v[0] + R[1, i] * v[1] + R[2, i] * v[2]
        out[10 + i] = w[i]
    for i in range(4):
        out[3 + i] = s * q[i]


@kernel
def estimator_update(x, hist, lpf, coef, k, omega_m, f_m, dt, g, has_pose, lag, p_m, q_m, gains, out, nu):
    """One IMU step: `predict`, then `fuse_pose` if a pose arrived this step, then the
    odometry frame into out; the innovations into nu (6,) (zero without a pose)."""
    predict(x, hist, k, omega_m, f_m, dt, g)
    if has_pose:
        nu[:] = fuse_pose(x, hist, k, lag, p_m, q_m, gains, dt)
    else:
        nu[:] = 0.0
    odometry(x, lpf, coef, omega_m, out)


@kernel
def estimator_sample(x, hist, lpf, coef, k, first, omega_m, f_m, dt, g, has_pose, lag, p_m, q_m, gains, out, nu):
    """`estimator_update` for IMU sample k; the first sample (`first`) ends no interval: it
    takes dt = 0 and starts the gyro low-pass at its steady state on omega_m."""
    if first:
        biquad_reset(lpf, coef, omega_m)
        dt = 0.0
    estimator_update(x, hist, lpf, coef, k, omega_m, f_m, dt, g, has_pose, lag, p_m, q_m, gains, out, nu)


@kernel
def estimator_step(x, hist, lpf, coef, k, omega_m, f_m, dt, g, has_pose, lag, p_m, q_m, gains, out):
    """`estimator_update` returning the innovations as a new array."""
    nu = np.zeros(6)
    estimator_update(x, hist, lpf, coef, k, omega_m, f_m, dt, g, has_pose, lag, p_m, q_m, gains, out, nu)
    return nu


# ----------------------------------------------------------------------------- set-up (Python)
def loop_gains(attitude_bandwidth_radps: float, position_bandwidth_radps: float, frame_period_s: float) -> np.ndarray:
    """The `LOOP_GAINS` record (in an array of one) of the module doc for frames every
    frame_period_s: k_p = 3 omega_p T_m, k_v = 3 omega_p^2 T_m, k_a = omega_p^3 T_m,
    k_R = 2 omega_R T_m, k_g = omega_R^2 T_m."""
    wp, wR, T = position_bandwidth_radps, attitude_bandwidth_radps, frame_period_s
    gains = np.zeros(1, LOOP_GAINS)
    g = gains[0]
    g["k_p"], g["k_v"], g["k_a"] = 3.0 * wp * T, 3.0 * wp * wp * T, wp ** 3 * T
    g["k_R"], g["k_g"] = 2.0 * wR * T, wR * wR * T
    return gains


class Estimator:
    """One vehicle's filter: the state, its history and the gyro low-pass, and `step` once per
    IMU sample. Construct it at the vehicle's first pose (at rest: v = 0, biases 0). `out` and
    `innovation` (r [m], e [rad]) hold the last step's odometry and innovations, updated in place."""

    def __init__(self, p_WB, quat_WB_wxyz, dt_s: float, frame_period_s: float, g: float,
                 attitude_bandwidth_radps: float, position_bandwidth_radps: float,
                 gyro_cutoff_hz: float, history_steps: int, out: np.ndarray | None = None,
                 storage: tuple[np.ndarray, ...] | None = None) -> None:
        """out: where `step` writes the odometry (N_OUT,), e.g. the head of a caller's larger
        array (a view); None: an array of its own. storage: (x (1,) `STATE`, hist (history_steps,)
        `SNAPSHOT`, lpf (2, 3), coef (1,) `BIQUAD`, gains (1,) `LOOP_GAINS`) to hold the filter in,
        e.g. views of a fleet's arrays (simulator.devices.DeviceArrays); None: arrays of its own."""
        x, hist, lpf, coef, gains = storage if storage is not None else (
            np.zeros(1, STATE), np.zeros(history_steps, SNAPSHOT), np.zeros((2, 3)), np.zeros(1, BIQUAD),
            np.zeros(1, LOOP_GAINS))
        if hist.shape != (history_steps,) or hist.dtype != SNAPSHOT or x.shape != (1,) or x.dtype != STATE:
            raise ValueError(f"the estimator's storage: a state {x.dtype} {x.shape} and a history {hist.dtype} "
                             f"{hist.shape}, not STATE (1,) and SNAPSHOT ({history_steps},)")
        if coef.shape != (1,) or coef.dtype != BIQUAD or gains.shape != (1,) or gains.dtype != LOOP_GAINS:
            raise ValueError(f"the estimator's storage: coefficients {coef.dtype} {coef.shape} and gains "
                             f"{gains.dtype} {gains.shape}, not BIQUAD (1,) and LOOP_GAINS (1,)")
        self.x, self.hist, self.lpf, self.coef, self.gains = x, hist, lpf, coef, gains
        s = x[0]
        s["p"], s["v"], s["q"], s["b_g"], s["b_a"] = p_WB, 0.0, quat_WB_wxyz, 0.0, 0.0
        for name in ("p", "v", "q"):
            hist[name] = s[name]
        coef[:] = biquad_coefficients(1.0 / dt_s, gyro_cutoff_hz)
        lpf[:] = 0.0
        gains[:] = loop_gains(attitude_bandwidth_radps, position_bandwidth_radps, frame_period_s)
        self.dt, self.g = dt_s, g
        self.out = np.zeros(N_OUT) if out is None else out
        self.innovation = np.zeros(6)
        self._started = False
        self._none = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])

    def step(self, k: int, omega_m: np.ndarray, f_m: np.ndarray, pose=None, lag: int = 0) -> np.ndarray:
        """The odometry (N_OUT,) after IMU sample k; pose (p_m, q_m) measured lag steps ago
        if a motion-capture frame arrived now. lag must be below the history length."""
        first, self._started = not self._started, True
        if pose is None:
            p_m, q_m = self._none
            has = False
        else:
            p_m, q_m = pose
            has = True
            if not 0 <= lag < self.hist.shape[0]:
                raise ValueError(f"pose lag {lag} steps outside the estimator's history ({self.hist.shape[0]})")
        estimator_sample(self.x, self.hist, self.lpf, self.coef, k, first, omega_m, f_m, self.dt, self.g, has, lag,
                         p_m, q_m, self.gains, self.out, self.innovation)
        return self.out

    @property
    def b_g(self) -> np.ndarray:
        return self.x[0]["b_g"].copy()

    @property
    def b_a(self) -> np.ndarray:
        return self.x[0]["b_a"].copy()
