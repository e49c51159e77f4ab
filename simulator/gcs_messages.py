"""MAVLink messages of the GCS link, built from flight-controller snapshots (no I/O).

Each vehicle's flight controller speaks as (its sysid, MAV_COMP_ID_AUTOPILOT1) in MAVLink's
conventions: LOCAL_POSITION_NED in a north-east-down frame at the world origin, ATTITUDE as
the FRD body's roll, pitch, yaw against NED.  The simulator's world is ENU (x east, y north,
z up) and its bodies FLU, so

    p_NED = (p_W.y, p_W.x, -p_W.z),   R_NED_FRD = R_NED_ENU R_WB R_FLU_FRD,
    (roll, pitch, yaw) = ZYX Euler angles of R_NED_FRD,   w_FRD = (w_B.x, -w_B.y, -w_B.z).

HEARTBEAT says MAV_TYPE_QUADROTOR, MAV_AUTOPILOT_PX4 and encodes the mode as PX4 does, so
that mavutil, MAVProxy and QGroundControl name it (OFFBOARD, LOITER, LAND); the flight
controller is an emulation following PX4's conventions (modes, failsafe, force-disarm
magic), not PX4.
"""
from __future__ import annotations

from amcore.so3 import euler_zyx_of_quat_wxyz, quat_wxyz_rotate
from amlink.codec import mav
from amlink.px4 import q_enu_flu_to_ned_frd

from .fcstate import FcMode, FleetSnapshot, VehicleSnapshot

STATUSTEXT_LEN = 50  # bytes in one STATUSTEXT; longer texts go out in chunks (id, chunk_seq)

# PX4's px4_custom_mode.h: main modes and AUTO's sub modes
_PX4_OFFBOARD, _PX4_AUTO = 6, 4
_PX4_AUTO_LOITER, _PX4_AUTO_LAND = 3, 6
PX4_CUSTOM_MODE = {
    FcMode.STANDBY: _PX4_AUTO << 16 | _PX4_AUTO_LOITER << 24,
    FcMode.OFFBOARD: _PX4_OFFBOARD << 16,
    FcMode.HOLD: _PX4_AUTO << 16 | _PX4_AUTO_LOITER << 24,
    FcMode.LAND: _PX4_AUTO << 16 | _PX4_AUTO_LAND << 24,
    FcMode.LANDED: _PX4_AUTO << 16 | _PX4_AUTO_LAND << 24,
}
# what the vehicle's sensors and controllers are: rate and attitude sensing, attitude, altitude
# and position control, motors (a simulation knows its state; nothing is ever unhealthy)
SENSORS = (mav.MAV_SYS_STATUS_SENSOR_3D_GYRO | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
           | mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL | mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
           | mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
           | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)


def time_boot_ms(snapshot: FleetSnapshot) -> int:
    """Simulation time in ms (the flight controllers boot with the run), as uint32."""
    return int(round(snapshot.time_s * 1e3)) & 0xFFFFFFFF


def system_status(v: VehicleSnapshot) -> int:
    if v.failsafe:
        return mav.MAV_STATE_CRITICAL
    if not v.armed or v.mode in (FcMode.STANDBY, FcMode.LANDED):
        return mav.MAV_STATE_STANDBY
    return mav.MAV_STATE_ACTIVE


def heartbeat(v: VehicleSnapshot):
    base_mode = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mav.MAV_MODE_FLAG_SAFETY_ARMED if v.armed else 0)
    return mav.MAVLink_heartbeat_message(type=mav.MAV_TYPE_QUADROTOR, autopilot=mav.MAV_AUTOPILOT_PX4,
                                         base_mode=base_mode, custom_mode=PX4_CUSTOM_MODE[v.mode],
                                         system_status=system_status(v), mavlink_version=3)


# health: 1 = no error. GEOFENCE: there is no fence, so no breach (GCSes such as MAVProxy read a
# cleared GEOFENCE health bit as "fence breach" whether or not a fence is present)
HEALTHY = SENSORS | mav.MAV_SYS_STATUS_GEOFENCE


def sys_status(v: VehicleSnapshot):
    return mav.MAVLink_sys_status_message(
        onboard_control_sensors_present=SENSORS, onboard_control_sensors_enabled=SENSORS,
        onboard_control_sensors_health=HEALTHY, load=0, voltage_battery=0xFFFF, current_battery=-1,
        battery_remaining=-1, drop_rate_comm=0, errors_comm=0, errors_count1=0, errors_count2=0, errors_count3=0,
        errors_count4=0)  # battery: unknown (the simulation has none)


def euler_ned_frd(q_wxyz) -> tuple[float, float, float]:
    """(roll, pitch, yaw) [rad] of the FRD body against NED, from q_WB (ENU <- FLU)."""
    return euler_zyx_of_quat_wxyz(q_enu_flu_to_ned_frd(q_wxyz))


def attitude(v: VehicleSnapshot, t_ms: int):
    roll, pitch, yaw = euler_ned_frd(v.quat_WB_wxyz)
    p, q, r = v.w_B
    return mav.MAVLink_attitude_message(time_boot_ms=t_ms, roll=roll, pitch=pitch, yaw=yaw, rollspeed=p,
                                        pitchspeed=-q, yawspeed=-r)


def local_position_ned(v: VehicleSnapshot, t_ms: int):
    x, y, z = v.p_WB
    vx, vy, vz = quat_wxyz_rotate(v.quat_WB_wxyz, v.v_B)  # v_W, ENU
    return mav.MAVLink_local_position_ned_message(time_boot_ms=t_ms, x=y, y=x, z=-z, vx=vy, vy=vx, vz=-vz)


def statustexts(text: str, severity: int, chunk_id: int):
    """STATUSTEXT messages carrying ``text``: one if it fits in 50 bytes, else chunks sharing
    ``chunk_id`` (1..65535), the last one shorter than 50 bytes or empty (MAVLink's rule)."""
    data = text.encode("utf-8")
    if len(data) <= STATUSTEXT_LEN:
        return [mav.MAVLink_statustext_message(severity, data)]
    chunks = [data[i : i + STATUSTEXT_LEN] for i in range(0, len(data), STATUSTEXT_LEN)]
    if len(chunks[-1]) == STATUSTEXT_LEN:
        chunks.append(b"")
    return [mav.MAVLink_statustext_message(severity, c, chunk_id, n) for n, c in enumerate(chunks)]


_MODE_TEXT = {
    FcMode.OFFBOARD: (mav.MAV_SEVERITY_INFO, "OFFBOARD: companion in control"),
    FcMode.HOLD: (mav.MAV_SEVERITY_CRITICAL, "failsafe: companion lost, holding position"),
    FcMode.LANDED: (mav.MAV_SEVERITY_INFO, "landed, motors off"),
}


def status_changes(before: FleetSnapshot | None, now: FleetSnapshot) -> list[tuple[int, int, str]]:
    """``(sysid, MAV_SEVERITY, text)`` for each change between two snapshots worth a
    STATUSTEXT: a flight-controller mode (failsafe, landing, the companion back), arming,
    and the mission phase (said by every vehicle)."""
    out = []
    was = {v.sysid: v for v in before.vehicles} if before is not None else {}
    for v in now.vehicles:
        old = was.get(v.sysid)
        if old is not None and old.mode != v.mode:
            if v.mode == FcMode.LAND:
                out.append((v.sysid, mav.MAV_SEVERITY_CRITICAL if v.failsafe else mav.MAV_SEVERITY_NOTICE,
                            "failsafe: landing" if v.failsafe else "landing (GCS command)"))
            elif v.mode == FcMode.OFFBOARD and old.mode in (FcMode.HOLD, FcMode.LAND):
                out.append((v.sysid, mav.MAV_SEVERITY_NOTICE, "failsafe ended: companion back in control"))
            elif v.mode in _MODE_TEXT:
                out.append((v.sysid, *_MODE_TEXT[v.mode]))
        if old is not None and old.armed != v.armed:
            out.append((v.sysid, mav.MAV_SEVERITY_NOTICE, "armed" if v.armed else "disarmed"))
    if now.phase and (before is None or before.phase != now.phase):
        out += [(v.sysid, mav.MAV_SEVERITY_INFO, f"mission phase: {now.phase}") for v in now.vehicles]
    return out
