"""Benchmark of one full controller step (pinocchio terms included): median and p95, where the
time goes, and the ratio to the literal transcription of the paper timed in the same run.

    python -m benchmarks.bench_controller [--iters 3000]

Targets (medians on the project's 2-core machines): controller step, pinocchio's terms
included, <= 20 us (issue 26; issue 15's was 30 us, goal 15 us); against the literal
transcription (tests/amcore/literal.py) <= 0.1x (goal 0.05x); the companion's whole step
from a sensor frame to its setpoint, telemetry excluded, <= 50 us (goal 25 us).

The step is fed back its own memory every call, as the companion does at 1 kHz. Where the
time goes: the state as pinocchio takes it (amcore.model.pin_configuration, one compiled
call), pinocchio's six calls (M^-1, C, CoM Jacobian, {e}'s placement, Jacobian and its
rate), the compiled law (amcore.law.control_law, called alone on the same inputs), and the
rest of `step` (argument passing, naming the results). The companion calls, every step
besides, mission.reference and the wire conversions of companion/pilot.py; each has its
own line. In attitude mode the companion calls amcore.offboard.offboard_step instead of
`step` (every 4 ms): its row, and the same with the numpy reference the compiled estimate
is tested against (tests/amcore/reference_offboard.py), show what the body torque estimate
and the arm's torques add. With the robust options (amcore.adapt: the trim, the heading
turn, the lateral shift) the companion shapes the reference first: one compiled call, and
beside it its numpy reference (tests/amcore/reference_adapt.py).
Rows are timed in interleaved rounds so that a change in machine load hits all
of them alike. The literal transcription (finite differences, generic inverses) is timed
on fewer calls: it takes milliseconds.
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

from amcore import law
from amcore.adapt import HeadingState, LateralState, adapted
from amcore.allocation import Allocation
from amcore.config import load_scenario
from amcore.control import ControllerMemory, ControllerParams, pinocchio_terms, step
from amcore.mission import am_mission
from amcore.offboard import Applied, OffboardMemory, OffboardParams, offboard_step
from amcore.model import AmState, build_model, create_data, pin_configuration
from amcore.so3 import R_to_quat_wxyz, exp_so3
from amlink.types import SensorFrame
from companion.pilot import setpoint_from_result, state_from_frame
from tests.amcore import reference_adapt, reference_offboard
from tests.amcore.literal import controller_literal

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Print the table; return its medians [us] (`benchmarks.bench_targets` reads them)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=3000)
    a = ap.parse_args(argv)
    spec = load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp.toml")
    model = build_model(spec.vehicle)
    mission = am_mission(spec, spec.ams[0], model)
    params = ControllerParams.from_vehicle(spec.vehicle, mission.frame)
    data = create_data(model)
    rng = np.random.default_rng(0)
    x = mission.initial_state()
    sts = [AmState(x.p_WB + 0.01 * rng.normal(size=3), x.R_WB @ exp_so3(0.05 * rng.normal(size=3)),
                   0.1 * rng.normal(size=3), 0.1 * rng.normal(size=3), x.q + 0.05 * rng.normal(size=3),
                   0.1 * rng.normal(size=3)) for _ in range(64)]
    refs = [mission.reference(t) for t in np.linspace(0, 20, 64)]
    F = rng.normal(size=6)
    # the same states as sensor frames (the wire carries the quaternion as float32)
    frames = [SensorFrame(step=k, time_s=0.0, p_WB=s.p_WB, quat_WB_wxyz=R_to_quat_wxyz(s.R_WB).astype(np.float32),
                          v_B=s.v_B, w_B=s.w_B, q=s.q, qdot=s.qdot, wrench_E=F) for k, s in enumerate(sts)]
    thrust_max = Allocation(spec.vehicle.rotors).thrust_scale_n
    mem = [ControllerMemory(), ControllerMemory()]
    # attitude mode's companion law with the options of the attitude scenario's vehicle
    oparams = OffboardParams.from_vehicle(load_scenario(ROOT / "configs" / "scenarios" / "two_am_comp_attitude.toml").vehicle)
    off_mem = [OffboardMemory(), OffboardMemory()]
    applied = Applied(20.0, np.zeros(model.n)) if oparams.inputs == "reported" else None
    pm, fid = model.pin_model, model.ee_frame_id
    clock = time.perf_counter_ns

    p, wf = params, params.wrench_filter
    res0 = step(model, data, params, sts[0], refs[0], F, ControllerMemory(), 0.0)
    x0, xd0 = res0.memory.wrench.x.copy(), res0.memory.wrench.xdot.copy()
    Phi = wf.transition(1e-3)
    configurations = [pin_configuration(st) for st in sts]
    law_inputs = []
    for st, ref, (q_pin, V) in zip(sts, refs, configurations):
        Jcom, M_inv, C, H_WE, J_e, Jd_e = pinocchio_terms(pm, data, fid, q_pin, V)
        law_inputs.append((model.mass_kg, model.gravity_mps2, st.R_WB, st.p_WB, st.w_B, V, Jcom.copy(), M_inv.copy(),
                           C.copy(), H_WE.copy(), J_e.copy(), Jd_e.copy(), p.task_frame.H_TW, p.axes, *ref,
                           F, x0, xd0, Phi, wf.omega, wf.zeta, p.gains_K_t, p.gains_D_t, p.k_R, p.k_w,
                           p.Lambda_wb_d_inv, p.K_y, p.D_y, p.com_err_max, p.y_err_max, p.sigma_damping,
                           p.damping_max, p.force_compensation, p.force_rate_feedforward, p.zero_task, np.zeros(3),
                           p.damping_dt))

    def run_step(i):
        mem[0] = step(model, data, params, sts[i % 64], refs[i % 64], F, mem[0], 1e-3 * i).memory

    def run_offboard(i, compiled):
        c = int(not compiled)
        f = offboard_step if compiled else reference_offboard.offboard_step
        off_mem[c] = f(model, data, params, sts[i % 64], refs[i % 64], F, off_mem[c], 4e-3 * i, oparams=oparams,
                       applied=applied).memory

    # the robust options' shaping of the reference (amcore.adapt.adapted): trim, heading turn and
    # lateral shift all acting, the turned frame's H_TW and e_y_W read as the step reads them
    headings = [HeadingState(*(0.05 * rng.normal(size=3)), 0.0) for _ in range(64)]
    laterals = [LateralState(*(0.003 * rng.normal(size=3)), 0.0) for _ in range(64)]
    trim_dr = np.array([0.004, -0.002, 0.0])

    def run_adapted(i, compiled):
        f = adapted if compiled else reference_adapt.adapted
        _, frame = f(refs[i % 64], mission.frame, trim_dr, headings[i % 64], mission.contact_point_W, laterals[i % 64])
        return frame.H_TW, frame.e_y_W

    def run_companion(i):  # companion.pilot's per-frame work, without its outcome bookkeeping
        frame, t = frames[i % 64], 0.0067 * i
        res = step(model, data, params, state_from_frame(frame), mission.reference(t), frame.wrench_E, mem[1], t)
        mem[1] = res.memory
        setpoint_from_result(i, res, thrust_max)

    parts = {
        "step": run_step,
        "configuration": lambda i: pin_configuration(sts[i % 64]),
        "pinocchio": lambda i: pinocchio_terms(pm, data, fid, *configurations[i % 64]),
        "law": lambda i: law.control_law(*law_inputs[i % 64]),
        "reference": lambda i: mission.reference(0.0067 * i),
        "state_from_frame": lambda i: state_from_frame(frames[i % 64]),
        "setpoint_from_result": lambda i: setpoint_from_result(i, res0, thrust_max),
        "companion": run_companion,
        "offboard": lambda i: run_offboard(i, True),
        "offboard_numpy": lambda i: run_offboard(i, False),
        "adapted": lambda i: run_adapted(i, True),
        "adapted_numpy": lambda i: run_adapted(i, False),
    }
    for i in range(300):
        for fn in parts.values():
            fn(i)
    samples = {name: [] for name in parts}
    cpu = {name: [] for name in parts}  # each round's CPU time per call (this thread's, 100 calls)
    literal = []
    load_before = os.getloadavg()
    for r in range(max(1, a.iters // 100)):
        for name, fn in parts.items():
            ts = samples[name]
            c0 = time.thread_time_ns()
            for i in range(r * 100, r * 100 + 100):
                t0 = clock()
                fn(i)
                ts.append(clock() - t0)
            cpu[name].append((time.thread_time_ns() - c0) / 100)
        if r % 3 == 0:  # the literal transcription: a few calls per round
            for i in range(2):
                k = (r + i) % 64
                t0 = clock()
                controller_literal(model, params, sts[k], refs[k], F)
                literal.append(clock() - t0)
    load_after = os.getloadavg()

    def med(ts):
        return np.median(ts) / 1e3

    def row(name, ts, key=None):
        c = f"{med(cpu[key]):10.1f}" if key else ""
        print(f"{name:<62} {med(ts):12.1f} {np.percentile(ts, 95) / 1e3:10.1f}{c}")

    # the CPU column: this thread's CPU time per call, median over rounds of 100 calls; on a
    # shared machine it moves less with the load than the wall-clock median beside it
    print(f"{'what':<62} {'median [us]':>12} {'p95 [us]':>10} {'CPU [us]':>9}")
    row("full controller step (amcore.control.step)", samples["step"], "step")
    row("  the state as pinocchio takes it (model.pin_configuration)", samples["configuration"], "configuration")
    row("  pinocchio: M^-1, C, CoM Jacobian, {e}'s placement, J_e, Jdot_e", samples["pinocchio"], "pinocchio")
    row("  compiled law (amcore.law.control_law) alone", samples["law"], "law")
    rest = med(samples["step"]) - med(samples["configuration"]) - med(samples["pinocchio"]) - med(samples["law"])
    rest_cpu = med(cpu["step"]) - med(cpu["configuration"]) - med(cpu["pinocchio"]) - med(cpu["law"])
    print(f"{'  the rest of step (arguments, naming the results)':<62} {rest:12.1f} {'':>10}{rest_cpu:10.1f}")
    row("literal transcription (tests/amcore/literal.py)", literal)
    print("  called by the companion every step besides:")
    row("    mission.reference (7th-order paths)", samples["reference"], "reference")
    row("    adapter.state_from_frame", samples["state_from_frame"], "state_from_frame")
    row("    adapter.setpoint_from_result", samples["setpoint_from_result"], "setpoint_from_result")
    row("companion step: frame -> state, reference, step, setpoint", samples["companion"], "companion")
    print(f"  attitude mode (amcore.offboard, inputs {oparams.inputs!r}, torque cutoff {oparams.torque_cutoff_hz:g} Hz):")
    row("    offboard_step: step, then tau_b^ and the arm's torques", samples["offboard"], "offboard")
    row("    the same with its numpy reference (tests/amcore)", samples["offboard_numpy"], "offboard_numpy")
    print("  the robust options (amcore.adapt: trim, heading turn, lateral shift, all acting):")
    row("    adapted: one compiled call (amcore.law.adapted_reference)", samples["adapted"], "adapted")
    row("    the same with its numpy reference (tests/amcore)", samples["adapted_numpy"], "adapted_numpy")
    step_us, comp_us, ratio = med(samples["step"]), med(samples["companion"]), med(samples["step"]) / med(literal)
    print(f"step / literal transcription, same run: {ratio:.4f}x")
    print(f"controller step, CPU time: {med(cpu['step']):.1f} us per call (median of {len(cpu['step'])} rounds)")
    print(f"load average (1 min) {load_before[0]:.2f} before, {load_after[0]:.2f} after; {os.cpu_count()} CPUs")
    for what, value, target, goal, unit in (("controller step", step_us, 20, 15, " us"),
                                            ("step / literal", ratio, 0.1, 0.05, "x"),
                                            ("companion step", comp_us, 50, 25, " us")):
        verdict = "goal met" if value <= goal else ("target met" if value <= target else "NOT met")
        print(f"{what}: {value:.4g}{unit} (target <= {target}{unit}, goal <= {goal}{unit}): {verdict}")
    return {"step": step_us, "configuration": med(samples["configuration"]), "pinocchio": med(samples["pinocchio"]),
            "law": med(samples["law"]), "rest": rest, "companion": comp_us}


if __name__ == "__main__":
    main()
