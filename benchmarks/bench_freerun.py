"""How many AMs the free-running simulator holds at a real-time factor, devices on, and where
its CPU goes; beside it, the lockstep simulator's CPU per AM and physics step for the same N
(`bench_core.py`'s measurement), in the same run.

    python -m benchmarks.bench_freerun [--n 1 2 4 10] [--duration 10] [--speed 1.0]

For each N: ten_am_attitude's object with N AMs (`bench_core.spec_for`, [devices] on), flown by
`simulator.freerun.FreeRun` in this process with every device the free-running simulator
serves (each arm's Dynamixel bus, each wrist's Net F/T RDT stream at the physics rate, the
object's motion-capture stream) and no GCS ports. The vehicles are flown by one client process
(`_client`, its CPU reported apart) that plays N light companions: per vehicle, SET_ATTITUDE_TARGET
at 50 Hz with an altitude hold on LOCAL_POSITION_NED (OFFBOARD, then armed, as PX4 wants) and a
Dynamixel SYNC READ and SYNC WRITE of the arm at 250 Hz, the bus traffic a companion makes. So
the simulator does what it does in a run; the companions' control law is not in the figure
(its CPU per step: `bench_controller.py`, and a companion's loop figures in am<sysid>.json).

Printed per N: the factor flown, the physics steps that started more than a period late
(deadline misses) and the worst lateness, the simulator's CPU per physics step (its own thread's,
apart from what other processes took), that step's split (physics: PyBullet's stepping; vehicles:
the commanders, the emulated autopilot and the actuation; ports: the PX4 ports' reading and
streams; devices: the servo buses, the F/T and mocap servers), the client's CPU, and the lockstep's
CPU per physics step (all N AMs: `bench_core.py`'s CPU per AM times N, devices on, every AM
answering each control step with a hovering setpoint, no sockets) and the factor it runs at
without companions. "holds" when fewer than 1 % of the steps missed their deadline.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from amlink.endpoint import parse_endpoint
from benchmarks.bench_core import run as lockstep_run, spec_for
from benchmarks.cputime import wrap
from simulator.freerun import FreeRun
from simulator.main import freerun_devices
from tests.ports import free_udp_ports

ROOT = Path(__file__).resolve().parents[1]

INSTANCE = 60  # device ports 7260+, 49212+, mocap 7460: apart from runs on the defaults

_CLIENT = textwrap.dedent('''
    import json, socket, struct, sys, time
    from amlink import dxl_protocol as dxl, px4
    from amlink.wire import Decoder, Encoder, mav
    cfg = json.loads(sys.argv[1])
    socks, encs, buses, reads, writes = [], [], [], [], []
    for i, (sysid, port, bus) in enumerate(zip(cfg["sysids"], cfg["ports"], cfg["buses"])):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind(("127.0.0.1", port)); s.setblocking(False)
        socks.append(s); encs.append(Encoder(sysid, px4.ONBOARD_COMPID))
        b = socket.create_connection(("127.0.0.1", bus)); b.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buses.append(b)
        ids = [dxl.joint_id(j) for j in range(cfg["n_joints"])]
        reads.append(dxl.instruction(dxl.BROADCAST_ID, dxl.SYNC_READ,
                                     struct.pack("<HH", *dxl.PRESENT_BLOCK) + bytes(ids)))
        writes.append(dxl.instruction(dxl.BROADCAST_ID, dxl.SYNC_WRITE, struct.pack("<HH", dxl.ADDR_GOAL_CURRENT, 2)
                                      + b"".join(bytes([k]) + b"\\0\\0" for k in ids)))
    dec = Decoder(None)
    n = len(socks)
    peers, z, vz, z0, engaged = [None] * n, [None] * n, [0.0] * n, [None] * n, [False] * n
    hover, t0 = cfg["hover"], time.monotonic()
    q = px4.q_enu_flu_to_ned_frd((1.0, 0.0, 0.0, 0.0))


    def serve():
        t_sp = t_bus = t0
        while time.monotonic() - t0 < cfg["seconds"]:
            for i, s in enumerate(socks):
                try:
                    while True:
                        data, addr = s.recvfrom(65536)
                        peers[i] = addr
                        for m in dec.feed(data):
                            if m.get_type() == "LOCAL_POSITION_NED":
                                z[i], vz[i] = -m.z, -m.vz
                                z0[i] = z[i] if z0[i] is None else z0[i]
                except BlockingIOError:
                    pass
            now = time.monotonic()
            if now >= t_bus:  # the arm's bus at 250 Hz: a sync read (answered), a sync write (not)
                t_bus += 0.004
                for b, r in zip(buses, reads):
                    b.sendall(r)
                for b, w in zip(buses, writes):
                    b.recv(4096)
                    b.sendall(w)
            if now >= t_sp:  # 50 Hz setpoints; OFFBOARD after 1.5 s of them, then arm
                t_sp += 0.02
                for i, s in enumerate(socks):
                    if peers[i] is None:
                        continue
                    thrust = hover if z[i] is None else hover + 0.15 * (z0[i] + 1.0 - z[i]) - 0.12 * vz[i]
                    msgs = [mav.MAVLink_set_attitude_target_message(0, cfg["sysids"][i], 1, px4.IGNORE_BODY_RATES,
                                                                    q, 0, 0, 0, min(max(thrust, 0.0), 0.9))]
                    if not engaged[i] and now - t0 > 1.5:
                        engaged[i] = True
                        msgs += [mav.MAVLink_command_long_message(cfg["sysids"][i], 1, mav.MAV_CMD_DO_SET_MODE, 0,
                                                                  1, px4.MAIN_OFFBOARD, 0, 0, 0, 0, 0),
                                 mav.MAVLink_command_long_message(cfg["sysids"][i], 1,
                                                                  mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0,
                                                                  0, 0, 0)]
                    s.sendto(encs[i].pack(msgs), peers[i])
            time.sleep(0.0005)


    try:
        serve()
    except OSError:  # the simulator ended first
        pass
    print(json.dumps({"cpu_s": time.process_time()}))
''')


def freerun(n: int, duration_s: float, speed: float) -> dict:
    spec = spec_for("attitude", n, devices=True)
    ports = free_udp_ports(n)
    arms, wrists, mocap = freerun_devices(spec, INSTANCE)
    run = FreeRun(spec, [parse_endpoint(f"udpout:127.0.0.1:{p}") for p in ports], speed=speed, arms=arms,
                  wrist_sensors=wrists, mocap=mocap)
    run.open()
    acc = dict.fromkeys(("physics", "vehicles", "ports", "devices"), 0)
    wrap(run.core.world, "step", acc, "physics")
    wrap(run, "_vehicle", acc, "vehicles")
    for p in run.ports:
        wrap(p, "poll", acc, "ports")
        wrap(p, "publish", acc, "ports")
    wrap(run, "_poll_arms", acc, "devices")
    for d in run._devices():
        wrap(d, "poll", acc, "devices")
        wrap(d, "publish", acc, "devices")
    hover = run.model.mass_kg * spec.vehicle.gravity_mps2 / run.thrust_scale_n
    cfg = {"sysids": run.sysids, "ports": ports, "buses": [a.address[1] for a in arms], "n_joints": spec.vehicle.n_joints,
           "hover": hover, "seconds": duration_s / speed + 5.0}
    client = subprocess.Popen([sys.executable, "-c", _CLIENT, json.dumps(cfg)], stdout=subprocess.PIPE, text=True,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
    try:
        time.sleep(0.5)
        result = run.run(duration_s)
    finally:
        run.close()
        out, _ = client.communicate(timeout=60)
    timing = result["timing"]
    steps = timing["steps"]
    flying = sum(1 for v in result["vehicles"].values() if v["armed_at_end"])
    return {"n": n, "flying": flying, "rtf": result["real_time_factor"], "steps": steps,
            "misses": timing["deadline_misses"], "worst_ms": 1e3 * timing["worst_lateness_s"],
            "cpu_ms_per_step": 1e3 * timing.get("mean_step_cpu_s", float("nan")),
            "split_ms": {k: 1e-6 * v / steps for k, v in acc.items()},
            "client_cpu_s": json.loads(out.strip().splitlines()[-1])["cpu_s"] if out.strip() else None,
            "wall_s": result["wall_s"]}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[1, 2, 4, 10])
    ap.add_argument("--duration", type=float, default=10.0, help="simulated seconds per N (the take-off included)")
    ap.add_argument("--speed", type=float, default=1.0, help="the real-time factor asked")
    a = ap.parse_args(argv)
    print(f"free-running at {a.speed:g}x, devices on, {a.duration:g} s simulated per N; {os.cpu_count()} cores")
    print("  N  flying  factor  misses         worst    CPU/step  physics vehicles  ports devices  client CPU"
          "  | lockstep: CPU/step  factor")
    for n in a.n:
        r = freerun(n, a.duration, a.speed)
        lock = lockstep_run("attitude", n, min(a.duration, 2.0), True)
        s = r["split_ms"]
        ok = "holds" if r["misses"] < 0.01 * r["steps"] else "misses"
        client = f"{100 * r['client_cpu_s'] / r['wall_s']:.0f} %" if r["client_cpu_s"] is not None else "-"
        print(f"{n:3d}  {r['flying']:6d}  {r['rtf']:5.2f}x  {r['misses']:6d} ({100 * r['misses'] / r['steps']:4.1f} %)"
              f"  {r['worst_ms']:6.1f} ms  {r['cpu_ms_per_step']:6.3f} ms  {s['physics']:6.3f}  {s['vehicles']:6.3f}"
              f"  {s['ports']:6.3f} {s['devices']:6.3f}  {client:>10}  |  {1e-3 * n * lock['cpu per AM']:6.3f} ms"
              f"  {lock['rtf']:5.2f}x  {ok}")


if __name__ == "__main__":
    main()
