"""What a PX4 autopilot streams to its companion, in this stack's frames, and the latest-sample
store that holds it (pure: no I/O; the messages are pymavlink message objects of common.xml).

Frames (amlink.px4): PX4 speaks NED (earth) and FRD (body); values here are ENU / FLU: p_WB and
q_WB (w, x, y, z; ENU <- FLU), v_B and w_B in FLU, accelerations in FLU.

ODOMETRY.  PX4 streams its estimator's ``vehicle_odometry`` with ``time_usec = timestamp_sample``
(its boot time [us]), ``frame_id = MAV_FRAME_LOCAL_NED`` and ``child_frame_id`` from the
topic's ``velocity_frame`` (PX4-Autopilot src/modules/mavlink/streams/ODOMETRY.hpp).  PX4 up to
v1.13 rotated the velocity into the body and sent ``MAV_FRAME_BODY_FRD``; from v1.14 EKF2
publishes ``VELOCITY_FRAME_NED`` (src/modules/ekf2/EKF2.cpp, PublishOdometry) and the stream
sends ``MAV_FRAME_LOCAL_NED`` with the velocity in NED.  Both are read here, each exactly:
``BODY_FRD`` velocity is in the body, ``LOCAL_NED`` velocity is rotated into the body by the
message's own attitude.  Any other frame pair is refused (:class:`FrameRefused`); the
angular rates are body rates (FRD) in every PX4 version.

Rejections (every one counted by the link, never raised to the loop): :class:`NonFiniteSample`
(a NaN or infinity in a field used), :class:`MalformedSample` (a quaternion that is not a unit
one, a zero timestamp), :class:`FrameRefused`.

Staleness.  :class:`StaleLimits` holds, per source, the age past which a sample is stale:
three periods of the rate PX4 streams it at by default on an onboard link (mavlink_main.cpp,
``MAVLINK_MODE_ONBOARD``: ODOMETRY 30 Hz, ATTITUDE_QUATERNION 50 Hz, HIGHRES_IMU 50 Hz,
ATTITUDE_TARGET 10 Hz), and 3 s for HEARTBEAT (three of its 1 Hz periods: the usual
MAVLink link-lost rule) and the status messages.  Ages are local-receive ages
(:meth:`Sample.age_ns`); a step that wants the age in the autopilot's time base has the
sample's source time ``fc_us`` and the link's time base.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

from amcore.so3 import quat_wxyz_rotate_inverse
from amlink import px4
from amlink.types import AttitudeTarget

MAV_FRAME_LOCAL_NED = 1
MAV_FRAME_BODY_FRD = 12
MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
MAV_AUTOPILOT_PX4 = 12
QUAT_NORM_TOL = 1e-3  # |‖q‖ - 1| a float32 unit quaternion may show; beyond it: not a rotation
_FRAME_NAMES = {0: "GLOBAL", 1: "LOCAL_NED", 7: "LOCAL_OFFSET_NED", 8: "BODY_NED", 9: "BODY_OFFSET_NED",
                12: "BODY_FRD", 20: "LOCAL_FRD", 21: "LOCAL_FLU"}


class SampleError(ValueError):
    """A message whose values cannot be a sample; ``message`` names it."""

    def __init__(self, message: str, why: str) -> None:
        self.message, self.why = message, why
        super().__init__(f"{message}: {why}")


class NonFiniteSample(SampleError):
    pass


class MalformedSample(SampleError):
    pass


class FrameRefused(SampleError):
    pass


# -- values -----------------------------------------------------------------------------
Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


@dataclass(frozen=True)
class Odometry:
    """The autopilot's estimate: t_us its time [us, autopilot boot], p_WB [m, ENU], q_WB (w x y z,
    ENU <- FLU), v_B [m/s, FLU], w_B [rad/s, FLU]; ``child_frame_id`` as it came (velocity frame)."""

    t_us: int
    p_WB: Vec3
    q_WB_wxyz: Quat
    v_B: Vec3
    w_B: Vec3
    reset_counter: int
    quality: int
    child_frame_id: int


@dataclass(frozen=True)
class Attitude:
    """ATTITUDE_QUATERNION: t_us [us, autopilot], q_WB (ENU <- FLU), w_B [rad/s, FLU]."""

    t_us: int
    q_WB_wxyz: Quat
    w_B: Vec3


@dataclass(frozen=True)
class Imu:
    """HIGHRES_IMU: t_us [us, autopilot]; acc_B [m/s^2] and gyro_B [rad/s] in FLU; mag_B [gauss]
    in FLU; pressures [hPa]; pressure_alt_m [m]; temperature_c [degC]; fields_updated bits."""

    t_us: int
    acc_B: Vec3
    gyro_B: Vec3
    mag_B_gauss: Vec3
    abs_pressure_hpa: float
    diff_pressure_hpa: float
    pressure_alt_m: float
    temperature_c: float
    fields_updated: int


@dataclass(frozen=True)
class AutopilotHeartbeat:
    """HEARTBEAT of the autopilot: its mode (amlink.px4.mode_name) and whether it is armed."""

    type: int
    autopilot: int
    base_mode: int
    custom_mode: int
    system_status: int

    @property
    def armed(self) -> bool:
        return bool(self.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def main_mode(self) -> int:
        return px4.modes_of(self.custom_mode)[0]

    @property
    def mode(self) -> str:
        return px4.mode_name(self.custom_mode)

    @property
    def offboard(self) -> bool:
        return bool(self.base_mode & MAV_MODE_FLAG_CUSTOM_MODE_ENABLED) and self.main_mode == px4.MAIN_OFFBOARD


@dataclass(frozen=True)
class ExtendedSysState:
    vtol_state: int  # MAV_VTOL_STATE
    landed_state: int  # MAV_LANDED_STATE: 1 on ground, 2 in air, 3 taking off, 4 landing


@dataclass(frozen=True)
class SysStatus:
    """SYS_STATUS: sensor bitmasks (MAV_SYS_STATUS_SENSOR), load [%], battery (None: unknown)."""

    sensors_present: int
    sensors_enabled: int
    sensors_health: int
    load_pct: float
    voltage_v: float | None
    current_a: float | None
    battery_remaining_pct: int | None
    drop_rate_comm_pct: float


# -- decoding ---------------------------------------------------------------------------
def _finite(name: str, **values) -> None:
    for field, v in values.items():
        vs = v if isinstance(v, (tuple, list)) else (v,)
        if not all(math.isfinite(x) for x in vs):
            raise NonFiniteSample(name, f"non-finite {field}")


def _unit(name: str, q) -> Quat:
    n = math.sqrt(sum(x * x for x in q))
    if abs(n - 1.0) > QUAT_NORM_TOL:
        raise MalformedSample(name, f"attitude quaternion of norm {n:.6g} is not a rotation")
    return tuple(x / n for x in q)


def odometry_of(m) -> Odometry:
    """ODOMETRY (PX4's frames, module docstring) as an :class:`Odometry` in ENU / FLU."""
    name = "ODOMETRY"
    if m.frame_id != MAV_FRAME_LOCAL_NED or m.child_frame_id not in (MAV_FRAME_BODY_FRD, MAV_FRAME_LOCAL_NED):
        raise FrameRefused(name, f"frame_id {m.frame_id} ({_FRAME_NAMES.get(m.frame_id, '?')}), child_frame_id "
                                 f"{m.child_frame_id} ({_FRAME_NAMES.get(m.child_frame_id, '?')}): PX4 sends "
                                 f"LOCAL_NED with BODY_FRD (up to v1.13) or LOCAL_NED (v1.14 on)")
    p, q, v = (m.x, m.y, m.z), tuple(m.q), (m.vx, m.vy, m.vz)
    w = (m.rollspeed, m.pitchspeed, m.yawspeed)
    _finite(name, position=p, q=q, velocity=v, rates=w)
    if m.time_usec <= 0:
        raise MalformedSample(name, "time_usec 0 (no timestamp)")
    q_WB = px4.q_ned_frd_to_enu_flu(_unit(name, q))
    if m.child_frame_id == MAV_FRAME_BODY_FRD:
        v_B = px4.frd_to_flu(v)
    else:
        v_B = quat_wxyz_rotate_inverse(q_WB, px4.ned_to_enu(v))
    return Odometry(int(m.time_usec), px4.ned_to_enu(p), q_WB, v_B, px4.frd_to_flu(w),
                    int(m.reset_counter), int(m.quality), int(m.child_frame_id))


def attitude_of(m) -> Attitude:
    name = "ATTITUDE_QUATERNION"
    q, w = (m.q1, m.q2, m.q3, m.q4), (m.rollspeed, m.pitchspeed, m.yawspeed)
    _finite(name, q=q, rates=w)
    return Attitude(int(m.time_boot_ms) * 1000, px4.q_ned_frd_to_enu_flu(_unit(name, q)), px4.frd_to_flu(w))


def attitude_target_of(m) -> tuple[int, AttitudeTarget]:
    """ATTITUDE_TARGET (the target the autopilot flies) as (t_us, AttitudeTarget in ENU / FLU)."""
    name = "ATTITUDE_TARGET"
    q, w = tuple(m.q), (m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate)
    _finite(name, q=q, rates=w, thrust=m.thrust)
    target = AttitudeTarget(0, quat_wxyz=px4.q_ned_frd_to_enu_flu(_unit(name, q)), rates_rad_s=px4.frd_to_flu(w),
                            thrust_normalized=float(m.thrust))
    return int(m.time_boot_ms) * 1000, target


def imu_of(m) -> Imu:
    name = "HIGHRES_IMU"
    acc, gyro, mag = (m.xacc, m.yacc, m.zacc), (m.xgyro, m.ygyro, m.zgyro), (m.xmag, m.ymag, m.zmag)
    _finite(name, acc=acc, gyro=gyro, mag=mag, abs_pressure=m.abs_pressure, diff_pressure=m.diff_pressure,
            pressure_alt=m.pressure_alt, temperature=m.temperature)
    if m.time_usec <= 0:
        raise MalformedSample(name, "time_usec 0 (no timestamp)")
    return Imu(int(m.time_usec), px4.frd_to_flu(acc), px4.frd_to_flu(gyro), px4.frd_to_flu(mag),
               float(m.abs_pressure), float(m.diff_pressure), float(m.pressure_alt), float(m.temperature),
               int(m.fields_updated))


def heartbeat_of(m) -> AutopilotHeartbeat:
    return AutopilotHeartbeat(int(m.type), int(m.autopilot), int(m.base_mode), int(m.custom_mode), int(m.system_status))


def extended_sys_state_of(m) -> ExtendedSysState:
    return ExtendedSysState(int(m.vtol_state), int(m.landed_state))


def sys_status_of(m) -> SysStatus:
    """SYS_STATUS; common.xml's "unknown" markers (UINT16_MAX mV, -1 cA, -1 %) become None."""
    return SysStatus(int(m.onboard_control_sensors_present), int(m.onboard_control_sensors_enabled),
                     int(m.onboard_control_sensors_health), m.load / 10.0,
                     None if m.voltage_battery == 0xFFFF else m.voltage_battery / 1000.0,
                     None if m.current_battery == -1 else m.current_battery / 100.0,
                     None if m.battery_remaining == -1 else int(m.battery_remaining), m.drop_rate_comm / 100.0)


# -- the store --------------------------------------------------------------------------
@dataclass(frozen=True)
class StaleLimits:
    """Age [s] past which a source's latest sample is stale (module docstring for the choice)."""

    odometry_s: float = 3 / 30.0
    attitude_s: float = 3 / 50.0
    imu_s: float = 3 / 50.0
    attitude_target_s: float = 3 / 10.0
    heartbeat_s: float = 3.0
    extended_sys_state_s: float = 3.0
    sys_status_s: float = 3.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"StaleLimits.{f.name} must be a finite number > 0 s, got {v!r}")

    def limit_ns(self, source: str) -> int:
        try:
            return round(getattr(self, f"{source}_s") * 1e9)
        except AttributeError:
            raise KeyError(f"no staleness limit for source {source!r}; sources: {', '.join(SOURCES)}") from None


SOURCES = ("odometry", "attitude", "imu", "attitude_target", "heartbeat", "extended_sys_state", "sys_status")


@dataclass(frozen=True)
class Sample:
    """The latest sample of one source.

    value: the decoded value (ENU / FLU). fc_us: its source time [us, autopilot boot time], None
    for messages without one (HEARTBEAT, status). rx_ns: when it was received [ns, companion
    monotonic]. count: samples of the source so far; gaps: intervals between consecutive
    samples longer than ``gap_factor`` times the source's typical interval."""

    source: str
    value: object
    fc_us: int | None
    rx_ns: int
    count: int
    gaps: int

    def age_ns(self, now_ns: int) -> int:
        """Time since it was received [ns] (the link's latency is not in it)."""
        return now_ns - self.rx_ns


class _Track:
    __slots__ = ("latest", "count", "gaps", "out_of_order", "interval", "intervals", "last_t")

    def __init__(self) -> None:
        self.latest: Sample | None = None
        self.count = self.gaps = self.out_of_order = self.intervals = 0
        self.interval = 0.0  # typical interval [ns or us, the source's own time]: EWMA
        self.last_t: float | None = None


class SampleStore:
    """Per source the latest sample, its count, gaps and out-of-order drops.

    A sample whose source time is not newer than the latest one's (a duplicate or a reordered
    datagram) does not replace it and is counted in ``out_of_order``.  Gaps are judged on the
    source's own time (its ``fc_us``, else the receive time): an interval longer than
    ``gap_factor`` (2) times the typical one, an exponential average (weight 0.1) of the
    intervals, each clipped to ``gap_factor`` times the average, so that a source slowed on
    purpose (SET_MESSAGE_INTERVAL) counts a few gaps and is then followed."""

    EWMA = 0.1
    WARMUP = 3  # intervals before gaps are judged

    def __init__(self, limits: StaleLimits = StaleLimits(), gap_factor: float = 2.0) -> None:
        if not gap_factor > 1.0:
            raise ValueError(f"gap_factor must be > 1, got {gap_factor}")
        self.limits, self.gap_factor = limits, float(gap_factor)
        self._tracks = {s: _Track() for s in SOURCES}

    def put(self, source: str, value, fc_us: int | None, rx_ns: int) -> Sample | None:
        """Store ``value``; the new :class:`Sample`, or None if it is older than the latest."""
        tr = self._tracks[source]
        t = float(fc_us) if fc_us is not None else float(rx_ns)
        if tr.last_t is not None:
            dt = t - tr.last_t
            if fc_us is not None and dt <= 0:
                tr.out_of_order += 1
                return None
            if tr.intervals >= self.WARMUP and dt > self.gap_factor * tr.interval:
                tr.gaps += 1
            tr.interval = dt if tr.intervals == 0 else (
                (1 - self.EWMA) * tr.interval + self.EWMA * min(dt, self.gap_factor * tr.interval))
            tr.intervals += 1
        tr.last_t = t
        tr.count += 1
        tr.latest = Sample(source, value, fc_us, rx_ns, tr.count, tr.gaps)
        return tr.latest

    def latest(self, source: str) -> Sample | None:
        return self._tracks[source].latest

    def out_of_order(self, source: str) -> int:
        return self._tracks[source].out_of_order

    def age_ns(self, source: str, now_ns: int) -> int | None:
        """Receive age of the source's latest sample [ns]; None if none came."""
        s = self._tracks[source].latest
        return None if s is None else s.age_ns(now_ns)

    def is_stale(self, source: str, now_ns: int) -> bool:
        """No sample yet, or the latest older than the source's limit (:class:`StaleLimits`)."""
        age = self.age_ns(source, now_ns)
        return age is None or age > self.limits.limit_ns(source)

    def stale(self, now_ns: int, sources=("odometry", "heartbeat")) -> list[str]:
        """Which of ``sources`` are stale now."""
        return [s for s in sources if self.is_stale(s, now_ns)]
