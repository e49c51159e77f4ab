"""One AM as the simulator's flight controller holds it: its link, its autopilot and devices, and
where its state machine stands (offboard, failsafe, a GCS command), all in one object.

`SitlCore` keeps one `Vehicle` per sysid (`SitlCore.vehicles`) and moves it between the states:

    offboard  -- companion silent (lost) --------------------------> failsafe (hold, then land)
    failsafe  -- companion answers again ---------------------------> offboard (autopilot afresh)
    offboard  -- K refused setpoints in a row (distrusted) ---------> failsafe, for good
    offboard  -- no setpoint for COM_OF_LOSS_T (offboard_lost) -----> failsafe, for good
    any       -- GCS land / disarm (overridden) --------------------> landing / motors off;
                                                                     setpoints ignored and counted
"""
from __future__ import annotations

import dataclasses

import numpy as np

from amlink.impair import ImpairedLink

from .devices import DeviceSuite, JointEffortSensor
from .failsafe import Failsafe
from .fcstate import FcMode
from .flight_controller import FlightController
from .sensors import SensorModel

_FAILSAFE_MODE = {"hold": FcMode.HOLD, "land": FcMode.LAND, "landed": FcMode.LANDED}


@dataclasses.dataclass(eq=False)
class Vehicle:
    """One AM's flight controller: what reaches it (`link`, the servo bus), what it flies with
    (the autopilot in attitude mode, the devices and their estimator), and its state."""
    sysid: int
    slot: int  # its row in the simulator's stacked autopilots and devices (simulator.fleet_kernels)
    link: ImpairedLink  # the setpoint link as the flight controller sees it (amlink.impair)
    joints_on_bus: bool = False  # [link].joints = "servo_bus": the arm's torques bypass the link
    sensor: SensorModel | None = None  # [sensors] noise on the frames (None: exact, or [devices])
    fc: FlightController | None = None  # attitude mode: the emulated autopilot
    effort: JointEffortSensor | None = None  # attitude mode: the servos' measured joint torques
    devices: DeviceSuite | None = None  # [devices]: sensors and estimator (made at the first step)
    odometry: list[float] | None = None  # the estimator's last values (odometry first)
    reported: list[float] | None = None  # the last frame's reported values (telemetry)
    values: list[float] | None = None  # the last frame's exact values (`SitlCore.snapshot`)
    target_set: object = None  # the setpoint whose target its row of the autopilots' arrays holds
    bus_torques: np.ndarray | None = None  # the last joint torques on the servo bus (zero-order hold)
    failsafe: Failsafe | None = None  # companion lost, distrusted or offboard lost: hold, then land
    landing: Failsafe | None = None  # landing on a GCS command (companion ignored)
    disarmed: bool = False  # by a GCS command: motors off, joints limp
    distrusted: bool = False  # K refused setpoints in a row: failsafe for good
    offboard_lost: bool = False  # no setpoint for COM_OF_LOSS_T: failsafe for good
    actuated: bool = False  # applied on arrival (`SitlCore.on_setpoint`) at the current step
    ignored_setpoints: int = 0  # arrived while a GCS command ruled
    wrong_kind: int = 0  # setpoints of the other mode, ignored
    rejected_in_a_row: int = 0

    @property
    def overridden(self) -> bool:
        """A GCS command rules this flight controller (landing, disarmed): setpoints are not applied."""
        return self.landing is not None or self.disarmed

    @property
    def for_good(self) -> bool:
        """In failsafe for the rest of the run, whatever its companion sends."""
        return self.distrusted or self.offboard_lost

    def flown_target(self):
        """The attitude target the autopilot is flying (its ATTITUDE_TARGET report), or None:
        none yet, or its failsafe (or a GCS command) flies the vehicle."""
        if self.failsafe is not None or self.overridden or self.for_good:
            return None
        sp = self.link.hold.command
        return None if sp is None else sp.attitude

    def mode(self, started: bool) -> FcMode:
        """What the flight controller reports (`started`: the lockstep has sent frames)."""
        fs = self.landing or self.failsafe
        if fs is not None:
            return _FAILSAFE_MODE[fs.mode]
        return FcMode.OFFBOARD if started else FcMode.STANDBY
