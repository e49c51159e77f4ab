"""`companion --clock wall`: the wiring of one AM's wall-clock companion (process level).

It opens, in this order, each endpoint with its own clear error: the motion capture (only
when the scenario plans from the measured object, [mission].object_pose = "mocap"), the
servo bus (servos left holding until OFFBOARD), the wrist F/T sensor, and the autopilot's
link; then runs `companion.wallclock.WallClockLoop` until the vehicle is handed back, the
handshake fails, the autopilot falls silent, or a signal stops it. Defaults are the
free-running simulator's endpoints for this AM's place i in the scenario's [[am]] list:
the autopilot on udpin:0.0.0.0:14540+i (PX4 SITL's onboard port), the servo bus on
tcp:127.0.0.1:7200+i, the F/T sensor on udp:127.0.0.1:49152+i, the motion capture on
udp:127.0.0.1:7400. Exit codes: 0 stopped or yielded to a pilot/GCS (the vehicle is theirs),
1 a device or the autopilot unreachable, the handshake refused, the autopilot silent, or
inputs stale beyond the hand-back limit (the vehicle was handed back to HOLD), 2 bad arguments.
"""
from __future__ import annotations

import time

from amcore.mission import ObjectPose
from amlink import dxl_protocol, px4, rdt_protocol
from amlink.mocap_protocol import MOCAP_PORT
from amlink.px4link import LinkOpenError, Px4Link

from .autopilot import Autopilot
from .devices import DeviceError
from .devices.arm import ArmClient
from .devices.mocap import DEFAULT_ENDPOINT as MOCAP_DEFAULT, MocapClient
from .devices.netft import NetFtClient
from .pilot import Pilot
from .sampling import StalenessLimits
from .wallclock import WallClockLoop


def default_endpoints(index: int, instance: int = 0) -> dict[str, str]:
    """The free-running simulator's endpoints of the AM at place `index` of [[am]] (its vehicles
    PX4 SITL instances `instance` + index)."""
    i = instance + index
    return {"fc": f"udpin:0.0.0.0:{px4.onboard_port(i)}",
            "arm": f"tcp:127.0.0.1:{dxl_protocol.servo_bus_port(i)}",
            "ft": f"udp:127.0.0.1:{rdt_protocol.netft_port(i)}",
            "mocap": MOCAP_DEFAULT if instance == 0 else f"udp:127.0.0.1:{MOCAP_PORT + instance}"}


class WallRun:
    """The devices and the link of one wall-clock companion, opened and closed together."""

    def __init__(self, spec, sysid: int, endpoints: dict[str, str], *, signing_key=None, tlog=None,
                 type_mask: int | None = None, log=print) -> None:
        self.spec, self.sysid, self.endpoints, self.log = spec, sysid, endpoints, log
        self.n = spec.vehicle.n_joints
        self.arm = ArmClient(endpoints["arm"], self.n)
        self.ft = NetFtClient(endpoints["ft"]) if endpoints.get("ft") != "none" else None
        self.mocap = MocapClient(endpoints["mocap"]) if spec.mission.object_pose == "mocap" else None
        link = Px4Link(sysid, endpoints["fc"], signing_key=signing_key, tlog=tlog)
        self.autopilot = Autopilot.for_rate(link, spec.control_rate_hz,
                                            **({} if type_mask is None else {"type_mask": type_mask}))
        self._opened: list = []

    def open(self, connect_timeout_s: float) -> ObjectPose | None:
        """Open every endpoint (DeviceError / LinkOpenError naming the one that failed); the
        object's measured pose when the scenario plans from it."""
        pose = None
        if self.mocap is not None:
            self.mocap.open()
            self._opened.append(self.mocap)
            self.mocap.wait(connect_timeout_s)  # MocapError naming the stream if nothing comes
            pose = self.mocap.object_pose()
        self.arm.open(current_control=False)
        self._opened.append(self.arm)
        if self.ft is not None:
            self.ft.open()
            self._opened.append(self.ft)
            self.ft.wait(min(connect_timeout_s, 5.0))
        self.autopilot.open()
        self._opened.append(self.autopilot)
        return pose

    def close(self) -> None:
        for dev in reversed(self._opened):
            try:
                dev.close()
            except (DeviceError, OSError) as exc:  # the run's record matters more than a clean close
                self.log(f"closing {type(dev).__name__}: {exc}")
        self._opened = []


def fly(run: WallRun, pilot: Pilot, *, on_step=None, stop=lambda: False, predict: bool = True,
        mission_start_s: float | None = None, link_timeout_s: float = 5.0, log=print, on_stats=None):
    """The loop of `companion.wallclock` over an opened `WallRun`; returns its WallClockResult.
    The F/T sensor is biased (ATI's bias command) at [devices.ft].tare_at_s of mission time,
    as the lockstep's device model tares it."""
    tare_at = pilot.spec.devices.ft.tare_at_s if pilot.spec.devices.enabled else -1.0
    tared = [tare_at < 0.0 or run.ft is None]

    def step(t, phase, res):
        if not tared[0] and t >= tare_at:
            run.ft.bias()
            tared[0] = True
        if on_step is not None:
            on_step(t, phase, res)

    loop = WallClockLoop(pilot, run.autopilot, run.arm, run.ft, limits=StalenessLimits(), predict=predict,
                         on_step=step, log=log, link_timeout_s=link_timeout_s, mission_start_s=mission_start_s,
                         on_stats=on_stats)
    t0 = time.perf_counter()
    result = loop.run(stop)
    result.stats["wall_s"] = round(time.perf_counter() - t0, 3)
    result.stats["arm"] = {**vars(run.arm.stats), "errors": loop.arm_errors}
    if run.ft is not None:
        result.stats["ft"] = vars(run.ft.stats)
    result.stats["autopilot_link"] = {k: v for k, v in vars(run.autopilot.link.stats).items()
                                      if isinstance(v, (int, float))}
    result.stats["handshake_notes"] = list(getattr(run.autopilot.hs, "notes", []))
    return result


__all__ = ["WallRun", "default_endpoints", "fly", "LinkOpenError", "DeviceError"]
