"""Shared helpers of the link tests: a scenario, deterministic frames and answers, linked endpoints."""

from __future__ import annotations

import contextlib
import threading

import numpy as np

from amlink.lockstep import CompanionClient, SimServer
from amlink.types import ScenarioInfo, SensorFrame, TorqueSetpoint

SCENARIO = ScenarioInfo(scenario_id=7, n_am=2, name="two_am_carry", seed=1234, rate_hz=1000.0)


def key_for(sysid: int) -> bytes:
    """A test key per vehicle (distinct for every sysid)."""
    return bytes((sysid * 37 + i) & 0xFF for i in range(32))


def make_frame(sysid: int, step: int) -> SensorFrame:
    """A frame whose content depends on (sysid, step), so mix-ups are visible."""
    n = sysid  # sysid 2 -> 2 joints, sysid 3 -> 3 joints
    return SensorFrame(
        step=step, time_s=step * 1e-3, p_WB=[sysid, step, 0.5], quat_WB_wxyz=[1, 0, 0, 0],
        v_B=[0, 0, 0], w_B=[0, 0, 0], q=np.arange(n) * 0.1 + step * 1e-3 + sysid, qdot=np.full(n, -step),
        wrench_E=[0, 0, sysid, 0, 0, step],
    )  # fmt: skip


def answer(frame: SensorFrame, sysid: int) -> TorqueSetpoint:
    """The companions' stand-in controller: a pure function of the frame and sysid."""
    return TorqueSetpoint(frame.step, 100.0 * sysid + frame.step, frame.p_WB * 2.0, frame.q * 3.0 + frame.qdot)


def server_for(sysids, timeout_s=1.0, signing=False, **kw) -> SimServer:
    keys = {s: key_for(s) for s in sysids} if signing else None
    return SimServer(bind="udp:127.0.0.1:0", sysids=sysids, scenario=SCENARIO, timeout_s=timeout_s,
                     signing_keys=keys, **kw)  # fmt: skip


def client_for(server: SimServer, sysid: int, signing=False, **kw) -> CompanionClient:
    return CompanionClient(sysid, sim=url(server), signing_key=key_for(sysid) if signing else None, **kw)


def url(server: SimServer) -> str:
    return f"udp:127.0.0.1:{server.address[1]}"


@contextlib.contextmanager
def linked(sysids, timeout_s=1.0, signing=False):
    """An open server and connected clients (handshake in threads), all closed afterwards."""
    server = server_for(sysids, timeout_s, signing)
    server.open()
    clients = {s: client_for(server, s, signing) for s in sysids}
    threads = [threading.Thread(target=c.connect, args=(5.0,)) for c in clients.values()]
    try:
        for t in threads:
            t.start()
        server.wait_for_peers(5.0)
        for t in threads:
            t.join(5.0)
        assert all(c.scenario == SCENARIO for c in clients.values())
        yield server, clients
    finally:
        server.close("test over")
        for c in clients.values():
            c.close()
