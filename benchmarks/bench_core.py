"""Where the simulator's lockstep time goes, per AM and physics step, in place: `SitlCore`
driven as `simulator.main` drives it, with the MAVLink work of `amlink.server` for each AM
(frame and sign the sensor batch; verify and decode a signed answer) but no sockets and no
companions: every AM answers each control step with the same hovering setpoint.

    python -m benchmarks.bench_core [--n 2 10] [--duration 2] [--mode attitude torque] [--devices] [--unsigned]

Each part is timed with `time.perf_counter` around it inside the running loop (caches as a
run leaves them, not back to back), summed over the run and divided by AMs x physics steps:

- sense: `World.sensor_values` (PyBullet's getters and the F/T wrench), every control step;
  with --devices every physics step (on a step without a frame, `World.base_values` where
  the tree has it);
- estimate: the devices and the estimator, with --devices, where a tree steps them one AM at a
  time (`SitlCore._sense`); where it steps every AM in one compiled call
  (`simulator.fleet_kernels`), that time is in frame (control steps) and apply (the steps
  between, fused with the autopilots), and estimate reads 0: compare "lockstep work";
- frame: the frame's value type and the autopilot's reports (`SitlCore.iter_frames` less the above);
- sign: the sensor batch packed and signed (`codec.sensor_frame_payloads`, `Encoder.pack_payloads`;
  with --unsigned, packed and framed only);
- verify: the answer verified and decoded (`Decoder.feed_records`, `SetpointAssembler`);
- apply: the flight controllers (attitude mode: the emulated autopilot and allocation every
  physics step) and the world's actuation (`SitlCore.actuate` / `hold`);
- physics: `SitlCore.step` (the rotors' lag, PyBullet's setters, `stepSimulation`), per AM;
- bookkeeping: the digest and the ground-truth samples (`SitlCore.observe`; on a step without
  frames, the ground-truth sample `SitlCore.hold` takes, `SitlCore._truth` where the tree has it).

"lockstep work" is the sum of sense .. apply: the issue's "simulator's lockstep work per AM
and physics step"; physics is PyBullet's stepping of the whole world, divided by N. The
parts are wall time (a part during which another process took the core counts that time);
"CPU per AM" is this process's CPU time over the whole loop (time.process_time) per AM and
physics step, every part included, which other processes' load does not inflate.
"""
from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from amcore.config import load_scenario
from amlink import codec, wire
from amlink.protocol import SIM_COMPID, SIM_SYSID
from amlink.types import AttitudeSetpoint, AttitudeTarget, TorqueSetpoint
from simulator.core import SitlCore

ROOT = Path(__file__).resolve().parents[1]

SCENARIOS = {"attitude": ROOT / "configs" / "scenarios" / "ten_am_attitude.toml",
             "torque": ROOT / "configs" / "scenarios" / "ten_am.toml"}
KEY = bytes(range(32))
PARTS = ("sense", "estimate", "frame", "sign", "verify", "apply", "physics", "bookkeeping")


def spec_for(mode: str, n: int, devices: bool):
    from amcore.config import AmSpec
    spec = load_scenario(SCENARIOS[mode])
    ams = tuple(AmSpec(sysid=2 + i, azimuth_deg=360.0 * i / n) for i in range(n))
    spec = dataclasses.replace(spec, ams=ams, object=dataclasses.replace(spec.object, mass_kg=1.0))
    if devices:
        spec = dataclasses.replace(spec, devices=dataclasses.replace(spec.devices, enabled=True))
    return spec


def answers(core: SitlCore, s: int, mode: str, key: bytes | None = KEY):
    """(one, steps): one(k) is AM s's answer to step k, a hovering setpoint's datagram signed with
    key (None: unsigned), for the control steps 0, every, 2 every, ... (steps)."""
    n = core.model.n
    hover = core.model.mass_kg * core.model.gravity_mps2
    enc = wire.Encoder(s, 191, signing_key=key, link_id=2)
    steps = range(0, 1 << 20, core.control_every)

    def one(k):
        if mode == "attitude":
            att = AttitudeTarget(k, quat_wxyz=np.array([1.0, 0.0, 0.0, 0.0]), rates_rad_s=np.zeros(3),
                                 thrust_normalized=hover / core.vehicles[s].fc.allocation.thrust_scale_n)
            sp = AttitudeSetpoint(step=k, attitude=att, tau_q_nm=np.zeros(n))
            return enc.pack_payloads(codec.attitude_setpoint_payloads(sp))
        sp = TorqueSetpoint(step=k, thrust_n=hover, tau_B_nm=np.zeros(3), tau_q_nm=np.zeros(n))
        return enc.pack_payloads(codec.setpoint_payloads(sp, None))
    return one, steps


def run(mode: str, n: int, duration_s: float, devices: bool, signed: bool = True) -> dict[str, float]:
    """One run's parts per AM and physics step [us]; signed False: the link unsigned (MAVLink 2
    signing off, as PX4's SITL runs by default), so that sign and verify are framing alone."""
    key = KEY if signed else None
    spec = spec_for(mode, n, devices)
    core = SitlCore(spec)
    t = dict.fromkeys(PARTS, 0.0)
    pc = time.perf_counter
    # split iter_frames into sense, estimate and frame by timing the world's and the devices' calls
    w = core.world
    sense0 = w.sensor_values

    def timed_read(read):
        def timed(s):
            t0 = pc()
            v = read(s)
            t["sense"] += pc() - t0
            return v
        return timed
    w.sensor_values = timed_read(sense0)
    if hasattr(w, "base_values"):  # the base alone, on steps without a frame ([devices])
        w.base_values = timed_read(w.base_values)
    sense_core = core._sense

    def timed_sense(s, values, tt):
        t0 = pc()
        out = sense_core(s, values, tt)
        t["estimate"] += pc() - t0
        return out
    core._sense = timed_sense
    t_truth = [0.0]  # the ground-truth samples taken by `hold` (bookkeeping, not the autopilot's work)
    if hasattr(core, "_truth"):
        truth_core = core._truth

        def timed_truth(wrench_E):
            t0 = pc()
            truth_core(wrench_E)
            t_truth[0] += pc() - t0
        core._truth = timed_truth
    encs = {s: wire.Encoder(SIM_SYSID, SIM_COMPID, signing_key=key, link_id=1) for s in core.sysids}
    dec = wire.Decoder(None if key is None else {s: key for s in core.sysids}, readers=codec.READERS)
    asm = {s: codec.SetpointAssembler() for s in core.sysids}
    makers = {s: answers(core, s, mode, key)[0] for s in core.sysids}
    steps = int(round(duration_s * spec.rate_hz))
    # the answers are made before the run (they are the companions' work)
    pre = {s: {k: makers[s](k) for k in range(0, steps, core.control_every)} for s in core.sysids}
    core.connect()
    cpu0, wall0 = time.process_time(), pc()
    try:
        for k in range(steps):
            if core.is_control_step(k):
                t0 = pc()
                before = t["sense"] + t["estimate"]
                sent = []
                for s, f in core.iter_frames(k):
                    t1 = pc()
                    sent.append(encs[s].pack_payloads(codec.sensor_frame_payloads(f, 0)))
                    t["sign"] += pc() - t1
                t["frame"] += pc() - t0 - (t["sense"] + t["estimate"] - before) - 0.0
                t0 = pc()
                core.observe()
                t["bookkeeping"] += pc() - t0
                setpoints = {}
                for s in core.sysids:
                    t0 = pc()
                    for mid, _sysid, _compid, body in dec.feed_records(pre[s][k]):
                        r = asm[s].push(mid, body)
                        if r is not None:
                            setpoints[s] = r[0]
                    t["verify"] += pc() - t0
                t0 = pc()
                core.actuate(k, setpoints, ())
                t["apply"] += pc() - t0
            else:
                t0 = pc()
                before, truth0 = t["sense"] + t["estimate"], t_truth[0]
                core.hold(k, ())
                held = t_truth[0] - truth0
                t["apply"] += pc() - t0 - (t["sense"] + t["estimate"] - before) - held
                t["bookkeeping"] += held
            t0 = pc()
            core.step()
            t["physics"] += pc() - t0
        wall, cpu = pc() - wall0, time.process_time() - cpu0
    finally:
        core.close()
    # the sign column was measured inside the frame window: take it out
    t["frame"] -= t["sign"]
    per = {k: 1e6 * v / (steps * n) for k, v in t.items()}
    per["lockstep work"] = sum(per[k] for k in ("sense", "estimate", "frame", "sign", "verify", "apply"))
    per["rtf"] = steps * spec.dt_s / wall
    per["wall per step"] = 1e6 * wall / steps
    per["cpu per AM"] = 1e6 * cpu / (steps * n)
    return per


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[2, 10])
    ap.add_argument("--duration", type=float, default=2.0)
    ap.add_argument("--mode", nargs="+", default=["attitude", "torque"], choices=sorted(SCENARIOS))
    ap.add_argument("--devices", action="store_true", help="[devices] on: the sensors as devices and the estimator")
    ap.add_argument("--unsigned", action="store_true", help="the link unsigned (signing is on by default)")
    a = ap.parse_args(argv)
    cols = PARTS + ("lockstep work",)
    print(f"[us per AM and physics step] devices {'on' if a.devices else 'off'}, link "
          f"{'unsigned' if a.unsigned else 'signed'}, {a.duration:g} s each")
    print(f"{'mode':9s} {'N':>3s} " + " ".join(f"{c:>13s}" for c in cols)
          + f" {'wall/step':>10s} {'one-core rtf':>12s} {'CPU per AM':>11s}")
    for mode in a.mode:
        for n in a.n:
            r = run(mode, n, a.duration, a.devices, not a.unsigned)
            print(f"{mode:9s} {n:3d} " + " ".join(f"{r[c]:13.1f}" for c in cols)
                  + f" {r['wall per step']:10.0f} {r['rtf']:11.2f}x {r['cpu per AM']:11.1f}", flush=True)


if __name__ == "__main__":
    main()
