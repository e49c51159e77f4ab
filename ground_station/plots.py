"""PNG plots of a recorded run, after the paper's simulation figure (Fig. simulation).

One figure per AM, rows as in the paper: CoM position error r~_c, base orientation error
e_R, attitude (roll, pitch, yaw; desired dashed), task error y~, F/T force f_e in the
end-effector frame; approach / grasp / hover shaded green / yellow / grey. One more
figure with every AM's pad-object normal force and the object's lift.
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from amcore.so3 import euler_zyx_of_quats_wxyz  # noqa: E402

from .review import RunData, phase_windows  # noqa: E402

PHASE_COLORS = {"approach": "#c8ecc8", "grasp": "#fff2b0", "hover": "#dddddd"}
XYZ = ("x", "y", "z")


def rpy_zyx(q: np.ndarray) -> np.ndarray:
    """(N,4) (w,x,y,z) -> (N,3) roll, pitch, yaw [rad] (R = Rz(yaw) Ry(pitch) Rx(roll)), yaw unwrapped."""
    if len(q) == 0:
        return np.zeros((0, 3))
    rpy = euler_zyx_of_quats_wxyz(q)
    rpy[:, 2] = np.unwrap(rpy[:, 2])
    return rpy


def _shade(ax, run: RunData) -> None:
    for name, (a, b) in phase_windows(run).items():
        if name in PHASE_COLORS:
            ax.axvspan(max(a, run.t_first), min(b, run.t_last), color=PHASE_COLORS[name], zorder=0, lw=0)


def _rows(ax, t, y, labels, dashed=None) -> None:
    for k, lab in enumerate(labels):
        line, = ax.plot(t, y[:, k], lw=1.0, label=lab)
        if dashed is not None:
            ax.plot(t, dashed[:, k], "--", lw=1.0, color=line.get_color())
    ax.legend(loc="upper right", fontsize=7, ncol=len(labels))
    ax.grid(alpha=0.3)


def write_plots(run: RunData, out_dir: Path) -> list[Path]:
    paths = []
    for sysid, s in run.ams.items():
        if len(s.t) == 0:
            continue
        fig, axes = plt.subplots(5, 1, figsize=(8, 11), sharex=True)
        n = s.y_err.shape[1]
        ylab = [f"y~{k}" for k in (("x", "z", "theta") if n == 3 else range(n))]
        _rows(axes[0], s.t, s.r_c_err, [f"r~c,{a}" for a in XYZ])
        axes[0].set_ylabel("CoM error [m]")
        _rows(axes[1], s.t, s.e_R, [f"e_R,{a}" for a in XYZ])
        axes[1].set_ylabel("orientation error [rad]")
        _rows(axes[2], s.t, rpy_zyx(s.q_WB), ["roll", "pitch", "yaw"], dashed=rpy_zyx(s.q_WB_d))
        axes[2].set_ylabel("attitude [rad]\n(desired dashed)")
        _rows(axes[3], s.t, s.y_err, ylab)
        axes[3].set_ylabel("task error")
        _rows(axes[4], s.t, s.wrench_E[:, :3], [f"f_e,{a}" for a in XYZ])
        axes[4].set_ylabel("F/T force in E [N]")
        axes[4].set_xlabel("simulation time [s]")
        for ax in axes:
            _shade(ax, run)
        fig.suptitle(f"AM {sysid}: approach (green), grasp (yellow), hover (grey)")
        fig.tight_layout()
        p = out_dir / f"am{sysid}.png"
        fig.savefig(p, dpi=90)
        plt.close(fig)
        paths.append(p)
    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for sysid, s in run.ams.items():
        if len(s.t_contact):
            axes[0].plot(s.t_contact, s.normal_n, lw=1.0, label=f"am{sysid}")
    axes[0].set_ylabel("pad normal force [N]")
    if run.ams:
        axes[0].legend(fontsize=7)
    if len(run.t_obj):
        axes[1].plot(run.t_obj, run.p_WO[:, 2] - run.p_WO[0, 2], lw=1.0, color="k")
    axes[1].set_ylabel("object lift [m]")
    axes[1].set_xlabel("simulation time [s]")
    for ax in axes:
        _shade(ax, run)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    p = out_dir / "object.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    paths.append(p)
    return paths
