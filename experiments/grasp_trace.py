"""Trace a grasp: run a scenario (or a trial's scenario file) in-process and record, every
ground-truth sample (10 ms), what happens at each pad: where the pad sits on the object, the
contact's normal force, friction force and mean contact point on the pad, the base pose and
the flight controller's estimate of it; and every 10th control step each companion's CoM
and task errors, f_d, the filtered contact force and the admittances' corrections.

    python experiments/grasp_trace.py runs/c/scenarios/trial-0001.toml --out trace.npz
    python experiments/grasp_trace.py ... --set options.lateral_admittance_hz=0.0

Prints the verdict and, for each AM, the pad's slip on the object and the RMS and largest
lateral (along-face) contact force from the grasp's end on. The npz holds `truth`
(columns in `truth_columns`) and `companion` (`companion_columns`).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from amcore.config import ConfigError, read_scenario, scenario_from_dict
from amcore.so3 import quat_wxyz_to_R
from companion.pilot import Pilot
from sitl import inprocess
from trials.cli import apply_overrides

PER_AM = ("pad_O_x", "pad_O_y", "pad_O_z", "contact_E_x", "contact_E_y", "contact_E_z", "normal_n",
          "friction_W_x", "friction_W_y", "friction_W_z", "base_W_x", "base_W_y", "base_W_z",
          "est_minus_true_x", "est_minus_true_y", "est_minus_true_z")
COMPANION = ("t", "sysid", "com_err_x", "com_err_y", "com_err_z", "y_err_0", "y_err_1", "y_err_2",
             "f_d_x", "f_d_y", "f_d_z", "F_x", "F_y", "F_z", "lateral_shift_m", "heading_shift_rad")


def main() -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("scenario", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE")
    a = ap.parse_args()
    path = a.scenario.resolve()
    try:
        spec = scenario_from_dict(apply_overrides(read_scenario(path), a.set), path)
    except ConfigError as exc:
        print(f"grasp_trace: {exc}", file=sys.stderr)
        return 2
    truth, comp = [], []

    def on_truth(gt):
        obj = gt.object
        R_WO = quat_wxyz_to_R(np.asarray(obj.quat_WO_wxyz))
        row = [gt.time_s, *obj.p_WO]
        for _, am in sorted(gt.ams.items()):
            pc = am.pad_object_contact
            contact_E = am.R_WE.T @ (pc.point_W - am.p_WE) if pc.n_points else np.zeros(3)
            est = np.asarray(am.estimate[:3]) - am.p_WB if len(am.estimate) >= 3 else np.full(3, np.nan)
            row += [*(R_WO.T @ (am.p_WE - obj.p_WO)), *contact_E, pc.normal_force_n, *pc.tangential_force_W,
                    *am.p_WB, *est]
        truth.append(row)

    pilot_step = Pilot.step

    def step(self, frame):
        out = pilot_step(self, frame)
        if frame.step % 10 == 0:
            d = out[2].diagnostics
            dy = self.lateral_state.dy if self.lateral is not None else 0.0  # the shift along the face
            comp.append([frame.time_s, self.am.sysid, *d.r_c_err, *d.y_err[:3], *d.f_d, *d.F_rc, dy,
                         self.heading_state.dpsi])
        return out

    Pilot.step = step  # the companions' diagnostics, as they are computed
    result = inprocess.run(spec, on_truth=on_truth)
    sysids = sorted(result["ams"], key=int)
    cols = ["t", "object_x", "object_y", "object_z"] + [f"am{s}.{c}" for s in sysids for c in PER_AM]
    tr = np.array(truth)
    np.savez(a.out, truth=tr, truth_columns=np.array(cols), companion=np.array(comp),
             companion_columns=np.array(COMPANION))
    print(result["verdict"]["text"])
    after = tr[:, 0] >= spec.mission.grasp_end_s
    for i, s in enumerate(sysids):
        b = 4 + i * len(PER_AM)
        lateral = np.asarray(comp)[np.asarray(comp)[:, 1] == int(s)]
        lat = lateral[lateral[:, 0] >= spec.mission.grasp_end_s, 12]
        print(f"am{s}: slip {1e3 * result['ams'][s]['slip_max_m']:.2f} mm; pad contact point moved "
              f"{1e3 * np.ptp(tr[after, b + 4]):.1f} mm across the crown; lateral force on the pad (filtered, "
              f"along {{w}} y) RMS {np.sqrt(np.mean(lat ** 2)):.2f} N, largest {np.abs(lat).max():.2f} N")
    return 0


if __name__ == "__main__":
    sys.exit(main())
