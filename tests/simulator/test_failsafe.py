"""The flight controller's failsafe after offboard loss: hold, then land, in PyBullet."""
from __future__ import annotations

import numpy as np

from amcore.so3 import exp_so3
from simulator.failsafe import Failsafe, FailsafeGains
from simulator.world import World

from .sim_testing import far_apart


def _fly(spec, model, x0_of, seconds, gains=FailsafeGains()):
    states = far_apart(spec, height_m=1.5)
    states = {s: x0_of(x) for s, x in states.items()}
    w = World(spec, states)
    w.connect()
    try:
        fs = {s: Failsafe(model, w.state(s), 0.0, gains) for s in w.sysids}
        log = []
        for k in range(int(seconds * spec.rate_hz)):
            t = k * spec.dt_s
            for s in w.sysids:
                c = fs[s].command(t, w.state(s))
                w.apply(s, c.thrust_n, c.tau_B_nm, c.tau_q_nm)
            w.step()
            if k % 100 == 0:
                log.append((t, {s: (w.state(s), fs[s].mode) for s in w.sysids}))
        return log, w.ground_truth()
    finally:
        w.close()


def test_hold_keeps_the_am_where_it_was_lost(spec, model):
    log, _ = _fly(spec, model, lambda x: x, 3.0)
    t, last = log[-1]
    for s, (x, mode) in last.items():
        x0 = log[0][1][s][0]
        assert mode == "hold"
        assert np.linalg.norm(x.p_WB - x0.p_WB) < 0.02
        assert np.linalg.norm(x.q - x0.q) < 0.05  # compliant arm, gravity compensated: stays put in free air
        assert abs(x.R_WB[2, 2] - 1.0) < 1e-3  # level


def test_hold_recovers_from_a_tilted_spinning_start(spec, model):
    def disturbed(x):
        return type(x)(x.p_WB, x.R_WB @ exp_so3(np.array([0.3, -0.2, 0.1])), x.v_B + np.array([0.5, 0, 0.2]),
                       np.array([1.0, -0.5, 0.3]), x.q, x.qdot)
    log, _ = _fly(spec, model, disturbed, 4.0)
    for s, (x, mode) in log[-1][1].items():
        assert abs(x.R_WB[2, 2] - 1.0) < 1e-3
        assert np.linalg.norm(x.v_B) < 0.02 and np.linalg.norm(x.w_B) < 0.02


def test_land_descends_and_turns_the_motors_off(spec, model):
    gains = FailsafeGains(hold_s=0.5, descent_mps=0.8)
    log, gt = _fly(spec, model, lambda x: x, 4.5, gains)
    modes = [m for _, d in log for (_, m) in d.values()]
    assert "land" in modes and modes[-1] == "landed"
    for s, am in gt.ams.items():
        assert am.p_WB[2] < 0.3  # down on the ground, not fallen from height: see the speed check
    zs = np.array([[d[s][0].p_WB[2] for s in d] for _, d in log])
    assert np.all(np.diff(zs, axis=0) > -0.8 * 0.1 * 1.5)  # never faster than 1.5x the commanded descent: no drop


def test_the_failsafe_takes_its_joint_damping_from_the_vehicle():
    """[safety].failsafe_joint_damping when the file gives it (am3dof), else M_qq,ii(q_nominal) /
    13.5 ms, one per joint (am4dof: the rule gives its shoulder about the 1.0 N m s/rad am3dof
    was tuned with)."""
    from pathlib import Path

    import pinocchio as pin

    from amcore.config import load_scenario
    from amcore.model import build_model
    from simulator.failsafe import JOINT_DAMPING_TAU_S, joint_damping

    root = Path(__file__).resolve().parents[2] / "configs" / "scenarios"
    paper = build_model(load_scenario(root / "two_am_comp.toml").vehicle)
    assert joint_damping(paper) == (1.0, 0.4, 0.1)
    wrist = build_model(load_scenario(root / "two_am_comp_4dof.toml").vehicle)
    d = joint_damping(wrist)
    pm = wrist.pin_model
    q = pin.neutral(pm)
    q[7:] = wrist.vehicle.q_nominal_rad
    M = pin.crba(pm, pm.createData(), q)
    assert len(d) == 4 and all(x > 0.0 for x in d)
    np.testing.assert_allclose(d, np.diag(M)[6:] / JOINT_DAMPING_TAU_S, rtol=1e-12)
    assert abs(d[0] - 1.0) < 0.02


def test_hold_then_land_on_the_four_joint_arm():
    """am4dof (a wrist roll: its damping derived): the failsafe holds a disturbed AM level and
    lands it, the arm limp and still."""
    from pathlib import Path

    from amcore.config import load_scenario
    from amcore.model import build_model

    spec = load_scenario(Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "two_am_comp_4dof.toml")
    model = build_model(spec.vehicle)

    def disturbed(x):
        return type(x)(x.p_WB, x.R_WB @ exp_so3(np.array([0.2, -0.1, 0.1])), x.v_B, np.array([0.5, -0.3, 0.2]),
                       x.q, x.qdot + np.array([0.5, -0.5, 0.5, 2.0]))
    log, gt = _fly(spec, model, disturbed, 5.0, FailsafeGains(hold_s=1.5, descent_mps=0.8))
    held = [d for t, d in log if 1.0 <= t < 1.5]
    for s, (x, mode) in held[-1].items():
        assert mode == "hold" and abs(x.R_WB[2, 2] - 1.0) < 1e-3 and np.linalg.norm(x.qdot) < 0.05
    assert [m for _, d in log for (_, m) in d.values()][-1] == "landed"
    for s, am in gt.ams.items():
        assert am.p_WB[2] < 0.3
