"""Review: per-phase numbers of a synthetic run whose answers are known in closed form."""
from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from amcore.so3 import R_to_quat_wxyz_shepperd, Rz
from ground_station.mcap_io import read_log
from ground_station.plots import rpy_zyx, write_plots
from ground_station.review import load_run, summarize
from telemetry import capture, schema
from telemetry.capture import finished
from telemetry.schema import Keys

from .conftest import write_mcap

KEYS = Keys()
ENDS = (1.0, 2.0, 3.0)
DT = 0.01
T = np.arange(0, 301) * DT
P_O0 = np.array([0.0, 0.0, 0.6])
OFFSET_O = {4: np.array([-0.1, 0.0, 0.0]), 5: np.array([0.1, 0.0, 0.0])}
PHASE_OF = lambda t: "approach" if t < ENDS[0] else ("grasp" if t < ENDS[1] else "hover")


def object_pose(t):
    h = max(0.0, t - ENDS[1])
    return P_O0 + np.array([0.0, 0.0, 0.05 * h]), Rz(0.1 * h)


def slip_O(sysid, t):  # am4's pad slides down the object during hover, am5's holds
    return np.array([0.0, 0.0, -0.005 * max(0.0, t - ENDS[1])]) if sysid == 4 else np.zeros(3)


def normal(t):
    return 0.0 if t < ENDS[0] else (10.0 * (t - ENDS[0]) if t < ENDS[1] else 10.0)


def tangential(t):
    return np.array([0.0, 0.0, -4.9]) if t >= ENDS[1] else np.zeros(3)


def com_err(sysid, t):
    return np.array([0.01 * math.exp(-t), 0.0, 0.0]) if sysid == 4 else np.array([0.0, 0.02 * math.exp(-t), 0.0])


def synthetic_samples(with_run_start=True, form="binary"):
    """The run's samples as the mains publish them (form "binary"), or all JSON as earlier
    versions did (form "json": the recorder writes the log the old way)."""
    if form == "binary":
        controller = lambda *a, **kw: finished(capture.controller(*a, **kw))  # noqa: E731
        truth = lambda gt, keys: [(k, finished(p)) for k, p in capture.ground_truth(gt, keys)]  # noqa: E731
    else:
        controller, truth = schema.controller_sample, schema.ground_truth_samples
    spec = NS(name="synthetic", rate_hz=100.0, duration_s=3.0, ams=[NS(sysid=4), NS(sysid=5)],
              mission=NS(approach_end_s=ENDS[0], grasp_end_s=ENDS[1], hover_end_s=ENDS[2]),
              object=NS(shape="box", mass_kg=1.0, position_m=tuple(P_O0), size_m=(0.2, 0.2, 0.2), radius_m=0.0,
                        height_m=0.0))
    out = [(KEYS.sim_event, schema.run_start_event(0.0, spec))] if with_run_start else []
    for t in T:
        t = float(t)
        p_WO, R_WO = object_pose(t)
        ams = {}
        for s in (4, 5):
            diag = NS(r_c=np.zeros(3), r_c_d=np.zeros(3), r_c_err=com_err(s, t), e_R=np.array([0.0, 0.1 * t, 0.0]),
                      e_w=np.zeros(3), R_WB=np.eye(3), R_d=np.eye(3), y=np.zeros(3), y_d=np.zeros(3),
                      y_err=np.array([0.001 * t, -0.002 * t, 0.0]), F_y=np.zeros(3), F_rc=np.zeros(3),
                      wrench_E_filtered=np.array([-normal(t), 0.0, 0.0, 0.0, 0.0, 0.0]),
                      wrench_W_filtered=np.array([normal(t), 0.0, 0.0, 0.0, 0.0, 0.0]), sigma_min_J3=0.55,
                      damping=0.0, com_err_saturated=False, y_err_saturated=False)
            cmd = NS(thrust_n=17.0, tau_B_nm=np.zeros(3), tau_q_nm=np.zeros(3))
            out.append((KEYS.controller(s), controller(t, PHASE_OF(t), diag, cmd, sysid=s)))
            p_WE = p_WO + R_WO @ (OFFSET_O[s] + slip_O(s, t))
            n = normal(t)
            ams[s] = NS(p_WB=p_WE + np.array([0.0, 0.0, 0.2]), R_WB=np.eye(3), p_WE=p_WE, R_WE=R_WO,
                        pad_object_contact=NS(normal_force_n=n, normal_W=np.array([1.0, 0, 0]) if n else np.zeros(3),
                                              tangential_force_W=tangential(t), point_W=p_WE, n_points=4 if n else 0),
                        pad_other_contacts=(), base_contacts=())
        gt = NS(time_s=t, ams=ams, object=NS(p_WO=p_WO, quat_WO_wxyz=np.array(R_to_quat_wxyz_shepperd(R_WO)),
                                             v_WO=np.zeros(3), w_WO=np.zeros(3), touching=("table",)))
        out.extend(truth(gt, KEYS))
    out.append((KEYS.sim_event, schema.run_end_event(float(T[-1]))))
    return out


@pytest.fixture(scope="module", params=["binary", "json"])
def log(request, tmp_path_factory):
    p = tmp_path_factory.mktemp("review") / f"synthetic-{request.param}.mcap"
    write_mcap(p, synthetic_samples(form=request.param))
    log = read_log(p)
    assert (log.encodings["/am/4/controller"] == "ros1") == (request.param == "binary")
    return log


def _window(name):
    a, b = {"approach": (0.0, ENDS[0]), "grasp": ENDS[:2], "hover": (ENDS[1], np.inf)}[name]
    return [float(t) for t in T if a <= t < b]


@pytest.mark.parametrize("phase", ["approach", "grasp", "hover"])
def test_per_phase_numbers_match_the_closed_form(log, phase):
    s = summarize(log)
    assert s["phase_source"] == "run_start" and s["phase_ends_s"] == list(ENDS) and not s["log"]["salvaged"]
    ts = _window(phase)
    p = s["phases"][phase]
    for sysid in (4, 5):
        a = p["ams"][str(sysid)]
        e = [np.linalg.norm(com_err(sysid, t)) for t in ts]
        assert a["samples"] == len(ts)
        assert a["com_err_m"] == pytest.approx({"final": e[-1], "max": max(e)}, rel=1e-12)
        assert a["e_R_rad"] == pytest.approx({"final": 0.1 * ts[-1], "max": 0.1 * ts[-1]}, rel=1e-12)
        assert a["task_err"]["final"] == pytest.approx([0.001 * ts[-1], -0.002 * ts[-1], 0.0])
        assert a["task_err"]["max_abs"] == pytest.approx([0.001 * ts[-1], 0.002 * ts[-1], 0.0])
        n = [normal(t) for t in ts]
        assert a["contact_normal_n"] == pytest.approx({"final": n[-1], "mean": float(np.mean(n)), "max": max(n)})
        assert a["contact_tangential_n"]["max"] == pytest.approx(4.9 if phase == "hover" else 0.0)
        assert a["ft_force_E_n"]["final"] == pytest.approx([-n[-1], 0.0, 0.0])
    lift = [object_pose(t)[0][2] - P_O0[2] for t in ts]
    assert p["object_lift_m"] == pytest.approx({"final": lift[-1], "max": max(lift)}, abs=1e-12)
    if phase == "hover":
        slip = p["ee_slip_m"]
        assert slip["4"] == pytest.approx({"final": 0.005 * (ts[-1] - ts[0]), "max": 0.005 * (ts[-1] - ts[0])})
        assert slip["5"]["max"] == pytest.approx(0.0, abs=1e-12)  # rigidly carried while the object turns and rises
    else:
        assert "ee_slip_m" not in p


def test_old_json_logs_and_binary_logs_review_the_same(tmp_path):
    """A log written from JSON samples (as every log before the binary channels) and one
    from binary samples give the same review, number for number."""
    got = {}
    for form in ("json", "binary"):
        p = tmp_path / f"{form}.mcap"
        write_mcap(p, synthetic_samples(form=form))
        s = summarize(read_log(p))
        del s["log"]["path"]
        got[form] = s
    assert got["json"] == got["binary"]
    assert got["json"]["phases"]["hover"]["ams"]["4"]["samples"] > 0


@pytest.mark.parametrize("form", ["binary", "json"])
def test_phases_fall_back_to_controller_labels(tmp_path, form):
    p = tmp_path / "nostart.mcap"
    write_mcap(p, synthetic_samples(with_run_start=False, form=form))
    s = summarize(read_log(p))
    assert s["phase_source"] == "controller"
    assert s["phase_ends_s"][:2] == [ENDS[0], ENDS[1]]
    assert s["phases"]["grasp"]["ams"]["4"]["samples"] == len(_window("grasp"))


def test_plots_reproduce_the_figure_rows(log, tmp_path):
    paths = write_plots(load_run(log), tmp_path)
    assert sorted(p.name for p in paths) == ["am4.png", "am5.png", "object.png"]
    for p in paths:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 10_000


def test_rpy_of_known_rotations():
    from amcore.so3 import exp_so3
    R = Rz(0.3) @ exp_so3(np.array([0.0, -0.2, 0.0])) @ exp_so3(np.array([0.1, 0.0, 0.0]))
    np.testing.assert_allclose(rpy_zyx(np.array([R_to_quat_wxyz_shepperd(R)])), [[0.1, -0.2, 0.3]], atol=1e-12)
