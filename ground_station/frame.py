"""One 3D frame of a recorded run: the object and every AM (base, arm, pad) as the simulator's
ground truth has them at time t, drawn with matplotlib (the README's picture of the team).

    python -m ground_station.frame runs/<run>/run.mcap --t 18 --out team.png

Reads /sim/am/<sysid>/truth (base pose, joint origins, end-effector) and /sim/object/state
from the log; the object's shape and size come from the log's run_start metadata's scenario
when it has them, else a 0.2 m box.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from amcore import cliargs  # noqa: E402
from amcore.so3 import unit_quat_wxyz_to_R  # noqa: E402

from .mcap_io import NotAnMcapError, read_log  # noqa: E402


def _at(samples: list[tuple[float, dict]], t: float) -> dict:
    """The last sample at or before t (the first one if t is before them all)."""
    best = samples[0][1]
    for ts, d in samples:
        if ts > t:
            break
        best = d
    return best


def _box(ax, p, R, size, color) -> None:
    hx, hy, hz = np.asarray(size) / 2.0
    corners = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    c = corners @ R.T + p
    for i in range(8):
        for j in range(i + 1, 8):
            if bin(i ^ j).count("1") == 1:
                ax.plot(*zip(c[i], c[j]), color=color, lw=1.5)


def _cylinder(ax, p, R, radius, height, color) -> None:
    a = np.linspace(0, 2 * np.pi, 48)
    for z in (-height / 2, height / 2):
        ring = np.stack([radius * np.cos(a), radius * np.sin(a), np.full_like(a, z)], axis=1) @ R.T + p
        ax.plot(ring[:, 0], ring[:, 1], ring[:, 2], color=color, lw=1.5)


def render(log_path: Path, t: float, out: Path, shape: str = "box", size=(0.2, 0.2, 0.2), radius: float = 0.0,
           height: float = 0.0) -> Path:
    """Draw the frame at simulated time t [s] into out (PNG)."""
    log = read_log(log_path)
    truths = log.topics("/sim/am/", "/truth")
    if not truths:
        raise ValueError(f"{log_path}: no /sim/am/<sysid>/truth topic: nothing to draw")
    fig = plt.figure(figsize=(7, 5))
    ax = fig.add_subplot(projection="3d")
    obj = log.decoded("/sim/object/state")
    if obj:
        o = _at(obj, t)
        p, R = np.asarray(o["p_WO"]), unit_quat_wxyz_to_R(o["q_WO"])
        if shape == "cylinder":
            _cylinder(ax, p, R, radius, height, "tab:brown")
        else:
            _box(ax, p, R, size, "tab:brown")
    for topic in truths:
        d = _at(log.decoded(topic), t)
        sysid = topic.split("/")[3]
        base, ee = np.asarray(d["p_WB"]), np.asarray(d["p_WE"])
        joints = np.asarray(d.get("p_W_joints", [])).reshape(-1, 3)
        arm = np.vstack([base, *joints, ee])
        R = unit_quat_wxyz_to_R(d["q_WB"])
        a = np.linspace(0, 2 * np.pi, 32)
        disc = np.stack([0.2 * np.cos(a), 0.2 * np.sin(a), np.zeros_like(a)], axis=1) @ R.T + base
        ax.plot(disc[:, 0], disc[:, 1], disc[:, 2], color="tab:blue", lw=2)
        ax.plot(arm[:, 0], arm[:, 1], arm[:, 2], "-o", color="tab:gray", ms=3, lw=2)
        ax.scatter(*ee, color="tab:red", s=25)
        ax.text(base[0], base[1], base[2] + 0.12, f"am{sysid}", fontsize=8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    # true proportions: the same metre on every axis (a tilt drawn as it is), the ground at z = 0
    pts = np.array([line.get_data_3d() for line in ax.lines], dtype=object)
    xyz = np.hstack([np.vstack([np.asarray(c, dtype=float) for c in p]) for p in pts])
    lo, hi = xyz.min(axis=1) - 0.1, xyz.max(axis=1) + 0.1
    lo[2] = 0.0
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple(hi - lo))
    ax.set_title(f"{log_path.parent.name}, t = {t:g} s (ground truth)", fontsize=9)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = cliargs.ArgumentParser(prog="python -m ground_station.frame", description=__doc__.split("\n\n")[0],
                                epilog=cliargs.exit_codes(0, 2, c0="drawn", c2="bad input (a missing or empty log)"))
    ap.add_argument("log", type=Path, help="MCAP log (run.mcap)")
    ap.add_argument("--t", type=cliargs.seconds_or_zero, default=0.0, help="simulated time [s]")
    ap.add_argument("--out", type=Path, required=True, help="PNG to write")
    ap.add_argument("--cylinder", type=float, nargs=2, metavar=("RADIUS", "HEIGHT"), default=None,
                    help="draw the object as a cylinder of this radius and height [m] (default: a 0.2 m box)")
    a = ap.parse_args(argv)
    try:
        kw = {"shape": "cylinder", "radius": a.cylinder[0], "height": a.cylinder[1]} if a.cylinder else {}
        print(render(a.log, a.t, a.out, **kw))
    except (OSError, ValueError, NotAnMcapError) as exc:
        return cliargs.fail("ground_station.frame", f"{a.log}: {exc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
