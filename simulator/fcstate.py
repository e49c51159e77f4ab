"""What each emulated flight controller reports about itself: its mode and a snapshot of its
vehicle (pure: no I/O, no numpy).

The simulator's main loop builds a :class:`FleetSnapshot` every few steps
(:meth:`simulator.core.SitlCore.snapshot`); the GCS link (:mod:`simulator.gcs_link`) turns
it into MAVLink telemetry on its own thread, so it must not change once built: every field
is a tuple or a number.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass


class FcMode(enum.Enum):
    """The flight controller's mode.  The GCS sees it in HEARTBEAT.custom_mode, encoded as PX4
    encodes its own (main mode << 16 | sub mode << 24), so stock tools name it."""

    STANDBY = "standby"  # before the companion armed it: held, nothing applied (shown as LOITER)
    OFFBOARD = "offboard"  # the companion's setpoints are applied
    HOLD = "hold"  # failsafe after companion loss: hold position (LOITER)
    LAND = "land"  # failsafe landing, or landing on a GCS command (NAV_LAND, mission abort)
    LANDED = "landed"  # on the ground, motors off (still LAND)


@dataclass(frozen=True)
class VehicleSnapshot:
    """One vehicle as its flight controller knows it, world ENU / body FLU as the sensor frame."""

    sysid: int
    p_WB: tuple[float, float, float]  # base position [m], world frame (x east, y north, z up)
    quat_WB_wxyz: tuple[float, float, float, float]  # base attitude, body FLU to world ENU
    v_B: tuple[float, float, float]  # base velocity [m/s], body frame
    w_B: tuple[float, float, float]  # base angular velocity [rad/s], body frame
    mode: FcMode
    armed: bool
    failsafe: bool  # the mode is the companion-loss failsafe's (not a GCS command's)


@dataclass(frozen=True)
class FleetSnapshot:
    """Every vehicle at simulation time ``time_s`` [s] and the mission phase then."""

    time_s: float
    phase: str  # "" before the run starts
    vehicles: tuple[VehicleSnapshot, ...]

    def vehicle(self, sysid: int) -> VehicleSnapshot | None:
        return next((v for v in self.vehicles if v.sysid == sysid), None)
