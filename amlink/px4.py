"""PX4's conventions on a standard-MAVLink (common.xml) link, defined once for both ends:
the free-running simulator's PX4 ports (`simulator.px4`) and the companion's PX4 client.
Pure: no I/O.

Ports. PX4 SITL instance i runs its onboard MAVLink instance as
``mavlink start -x -u 14580+i -r 4000000 -f -m onboard -o 14540+i`` (PX4
ROMFS/px4fmu_common/init.d-posix/px4-rc.mavlink): it binds UDP 14580+i and sends to
14540+i, and answers whoever last sent to it. A program written for PX4 listens on
14540+i (MAVSDK's ``udpin://0.0.0.0:14540``). Its GCS instance,
``mavlink start -x -u 18570+i -r 4000000 -f`` (MAVLINK_MODE_NORMAL), binds 18570+i and sends
to 127.0.0.1:14550, where QGroundControl and MAVProxy listen. Vehicle i is the i-th [[am]] entry.

Identity. The autopilot of vehicle s speaks as (s, MAV_COMP_ID_AUTOPILOT1 = 1); its
onboard computer as (s, MAV_COMP_ID_ONBOARD_COMPUTER = 191): PX4 counts an onboard
computer's HEARTBEAT only when its sysid is PX4's own (MavlinkReceiver::handle_message_heartbeat).

Modes. PX4's custom_mode packs (main_mode << 16) | (sub_mode << 24) (PX4
src/modules/commander/px4_custom_mode.h).

Frames. PX4 speaks NED (earth) and FRD (body); this stack works in ENU (world x east,
y north, z up) and FLU (body x forward, y left, z up). The maps below are the only place
the two meet.
"""
from __future__ import annotations

import math

ONBOARD_PORT_BASE = 14540  # the program's port of instance i: 14540 + i (PX4 px4-rc.mavlink, -o)
PX4_LOCAL_PORT_BASE = 14580  # the autopilot's own port of instance i: 14580 + i (-u)
GCS_PORT = 14550  # PX4 SITL's GCS instances send to 127.0.0.1:14550 (mavlink_main.h:96, mavlink_main.cpp:1002-1007)
GCS_LOCAL_PORT_BASE = 18570  # ... from 18570 + i (px4-rc.mavlink: udp_gcs_port_local, -u), MAVLINK_MODE_NORMAL

PX4_COMPID = 1  # MAV_COMP_ID_AUTOPILOT1
ONBOARD_COMPID = 191  # MAV_COMP_ID_ONBOARD_COMPUTER

# px4_custom_mode.h: PX4_CUSTOM_MAIN_MODE_*
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = 1, 2, 3, 4, 5, 6, 7
# PX4_CUSTOM_SUB_MODE_AUTO_*
SUB_AUTO_READY, SUB_AUTO_TAKEOFF, SUB_AUTO_LOITER, SUB_AUTO_MISSION, SUB_AUTO_RTL, SUB_AUTO_LAND = 1, 2, 3, 4, 5, 6

# SET_ATTITUDE_TARGET.type_mask bits (common.xml ATTITUDE_TARGET_TYPEMASK)
IGNORE_ROLL_RATE, IGNORE_PITCH_RATE, IGNORE_YAW_RATE = 1, 2, 4
THRUST_BODY_SET = 32
IGNORE_THROTTLE = 64
IGNORE_ATTITUDE = 128
IGNORE_BODY_RATES = IGNORE_ROLL_RATE | IGNORE_PITCH_RATE | IGNORE_YAW_RATE  # 7: what MAVSDK's set_attitude sends


def onboard_port(index: int) -> int:
    """The UDP port a PX4 offboard program listens on for vehicle `index` (0-based [[am]] order)."""
    return ONBOARD_PORT_BASE + index


def px4_local_port(index: int) -> int:
    """The UDP port the autopilot of vehicle `index` sends from."""
    return PX4_LOCAL_PORT_BASE + index


def gcs_local_port(index: int) -> int:
    """The UDP port the GCS instance of vehicle `index` binds and sends to GCS_PORT from."""
    return GCS_LOCAL_PORT_BASE + index


def custom_mode(main: int, sub: int = 0) -> int:
    """HEARTBEAT.custom_mode of PX4 main mode `main` and sub mode `sub`."""
    return (main << 16) | (sub << 24)


def modes_of(custom: int) -> tuple[int, int]:
    """(main mode, sub mode) of a PX4 HEARTBEAT.custom_mode."""
    return (custom >> 16) & 0xFF, (custom >> 24) & 0xFF


MODE_NAMES = {
    (MAIN_MANUAL, 0): "MANUAL", (MAIN_ALTCTL, 0): "ALTCTL", (MAIN_POSCTL, 0): "POSCTL",
    (MAIN_OFFBOARD, 0): "OFFBOARD", (MAIN_STABILIZED, 0): "STABILIZED", (MAIN_ACRO, 0): "ACRO",
    (MAIN_AUTO, SUB_AUTO_READY): "AUTO.READY", (MAIN_AUTO, SUB_AUTO_TAKEOFF): "AUTO.TAKEOFF",
    (MAIN_AUTO, SUB_AUTO_LOITER): "HOLD", (MAIN_AUTO, SUB_AUTO_MISSION): "MISSION",
    (MAIN_AUTO, SUB_AUTO_RTL): "RTL", (MAIN_AUTO, SUB_AUTO_LAND): "LAND",
}


def mode_name(custom: int) -> str:
    main, sub = modes_of(custom)
    return MODE_NAMES.get((main, sub if main == MAIN_AUTO else 0), f"main {main} sub {sub}")


# -- frames -------------------------------------------------------------------------
_H = math.sqrt(0.5)


def enu_to_ned(v) -> tuple[float, float, float]:
    """A vector in ENU (x east, y north, z up) in NED (x north, y east, z down); its own inverse."""
    return (v[1], v[0], -v[2])


ned_to_enu = enu_to_ned


def flu_to_frd(v) -> tuple[float, float, float]:
    """A body vector in FLU in FRD; its own inverse."""
    return (v[0], -v[1], -v[2])


frd_to_flu = flu_to_frd


def q_enu_flu_to_ned_frd(q_wxyz) -> tuple[float, float, float, float]:
    """q_ENU_FLU (world <- body, w x y z) as q_NED_FRD, the convention of SET_ATTITUDE_TARGET,
    ATTITUDE_QUATERNION and ODOMETRY: q_NED_ENU * q * q_FLU_FRD with q_NED_ENU = (0, h, h, 0),
    q_FLU_FRD = (0, 1, 0, 0), h = sqrt(1/2), sign dropped (the same rotation), so the map is
    linear, orthogonal and its own inverse (q_ned_frd_to_enu_flu is the same function)."""
    w, x, y, z = q_wxyz
    return (_H * (w + z), _H * (x + y), _H * (x - y), _H * (w - z))


q_ned_frd_to_enu_flu = q_enu_flu_to_ned_frd
