"""Physical outcome of a run, from the simulator's ground truth (pure: numpy only).

Fed `GroundTruth` samples (and the wrist sensor's reading) during the run, it reports what
the paper's Fig. 3 and the issue's acceptance checks need:
- object: rest height, lift above rest (final; min and mean over the hover window);
- per AM, over the hover window (the settled part of lift-and-hover): mean pad-object normal
  and tangential force [N, W] and the mean force the wrist sensor measures on the
  end-effector [N, W]; slip = largest displacement of the end-effector relative to the
  object (in the object's frame) from the end of the grasp phase on, lift included [m];
  crashes (base touching anything) and actuator saturation counts over the whole run.
"""
from __future__ import annotations

import numpy as np

from amcore.allocation import AXES
from amcore.so3 import quat_wxyz_to_R


class _AmAcc:
    def __init__(self) -> None:
        self.n = 0
        self.normal = 0.0
        self.tangential = np.zeros(3)
        self.ft_force_W = np.zeros(3)
        self.anchor_O: np.ndarray | None = None
        self.slip_max = 0.0
        self.base_contacts: set[str] = set()
        self.saturated_steps = 0
        self.rotor_saturated_steps = 0
        self.joint_saturated_steps = 0
        self.axis_saturated_steps = [0, 0, 0, 0]  # roll, pitch, yaw, thrust (amcore.allocation.AXES)
        self.hover_rotor_fraction_max = 0.0  # the busiest rotor's share of its range in the hover
        self.hover_rotor_fraction_min = 1.0  # the idlest rotor's
        self.first_saturation_s: float | None = None
        self.lowest_base_z = np.inf
        self.first_base_contact: tuple[float, tuple[str, ...]] | None = None  # (t, what it touched)
        self.slip_series: list[float] = []  # slip at every sample from slip_from_s on [m]


class RunOutcome:
    def __init__(self, sysids, hover_window: tuple[float, float], slip_from_s: float) -> None:
        self.hover_window = hover_window
        self.slip_from_s = slip_from_s
        self.ams = {s: _AmAcc() for s in sysids}
        self.z_rest: float | None = None
        self.final_lift = 0.0
        self._lift_n = 0
        self._lift_sum = 0.0
        self.lift_min = np.inf
        self.object_touching_in_hover: set[str] = set()
        self.t_last = 0.0
        # per sample, for the verdict (simulator.verdict): time, object lift, whether the object
        # touches the table or ground, the farthest base from the object's rest position
        self.t_series: list[float] = []
        self.lift_series: list[float] = []
        self.on_support_series: list[bool] = []
        self.base_distance_series: list[float] = []
        self.slip_t_series: list[float] = []
        self.p_rest: np.ndarray | None = None

    def saturation(self, sysid: int, t: float, rotors: bool = True, joints: bool = False,
                   axes: tuple[bool, bool, bool, bool] = (False, False, False, False)) -> bool:
        """Count one saturated step (the rotors', the joints' or both; for the rotors, which
        of roll, pitch, yaw and thrust fell short); True the first time (so the caller logs
        it once)."""
        a = self.ams[sysid]
        a.saturated_steps += 1
        a.rotor_saturated_steps += bool(rotors)  # bool(): numpy's bools would make the counts numpy
        a.joint_saturated_steps += bool(joints)  # integers, which outcome.json cannot hold
        for k, x in enumerate(axes):
            a.axis_saturated_steps[k] += bool(x)
        if a.first_saturation_s is None:
            a.first_saturation_s = t
            return True
        return False

    def add(self, gt, wrench_E: dict[int, np.ndarray]) -> None:
        """One ground-truth sample; wrench_E[sysid] = wrist reading on the ee, in E."""
        t = gt.time_s
        self.t_last = t
        obj = gt.object
        if self.z_rest is None:
            self.z_rest = float(obj.p_WO[2])
            self.p_rest = np.array(obj.p_WO, dtype=float)
        lift = float(obj.p_WO[2]) - self.z_rest
        self.final_lift = lift
        in_hover = self.hover_window[0] <= t <= self.hover_window[1]
        R_WO = quat_wxyz_to_R(obj.quat_WO_wxyz)
        self.t_series.append(t)
        self.lift_series.append(lift)
        self.on_support_series.append(any(n in ("table", "ground") for n in obj.touching))
        dist = max((float(np.linalg.norm(am.p_WB - self.p_rest)) for am in gt.ams.values()), default=0.0)
        finite = all(np.isfinite(am.p_WB).all() for am in gt.ams.values())
        self.base_distance_series.append(dist if finite and np.isfinite(obj.p_WO).all() else np.inf)
        if t >= self.slip_from_s:
            self.slip_t_series.append(t)
        if in_hover:
            self._lift_n += 1
            self._lift_sum += lift
            self.lift_min = min(self.lift_min, lift)
            self.object_touching_in_hover.update(n for n in obj.touching if not n.startswith("am"))
        for s, am in gt.ams.items():
            a = self.ams[s]
            a.base_contacts.update(am.base_contacts)
            if am.base_contacts and a.first_base_contact is None:
                a.first_base_contact = (t, tuple(am.base_contacts))
            a.lowest_base_z = min(a.lowest_base_z, float(am.p_WB[2]))
            if in_hover:
                a.hover_rotor_fraction_max = max(a.hover_rotor_fraction_max, getattr(am, "rotor_fraction_max", 0.0))
                a.hover_rotor_fraction_min = min(a.hover_rotor_fraction_min, getattr(am, "rotor_fraction_min", 1.0))
            if t >= self.slip_from_s:
                p_O = R_WO.T @ (am.p_WE - obj.p_WO)
                if a.anchor_O is None:
                    a.anchor_O = p_O
                slip = float(np.linalg.norm(p_O - a.anchor_O))
                a.slip_max = max(a.slip_max, slip)
                a.slip_series.append(slip)
            if not in_hover:
                continue
            a.n += 1
            pc = am.pad_object_contact
            a.normal += pc.normal_force_n
            a.tangential += pc.tangential_force_W
            a.ft_force_W += am.R_WE @ wrench_E[s][0:3]

    def to_dict(self) -> dict:
        ams = {}
        for s, a in self.ams.items():
            n = max(a.n, 1)
            ams[str(s)] = {
                "hover_samples": a.n,
                "hover_mean_normal_force_n": a.normal / n,
                "hover_mean_tangential_force_W_n": (a.tangential / n).tolist(),
                "hover_mean_ft_force_W_n": (a.ft_force_W / n).tolist(),
                "slip_max_m": a.slip_max,
                "base_contacts": sorted(a.base_contacts),
                "lowest_base_z_m": a.lowest_base_z,
                "saturated_steps": a.saturated_steps,
                "rotor_saturated_steps": a.rotor_saturated_steps,
                "joint_saturated_steps": a.joint_saturated_steps,
                "axis_saturated_steps": dict(zip(AXES, a.axis_saturated_steps)),
                "hover_rotor_fraction_max": a.hover_rotor_fraction_max,
                "hover_rotor_fraction_min": a.hover_rotor_fraction_min if a.n else None,
                "first_saturation_s": a.first_saturation_s,
                "first_base_contact_s": a.first_base_contact[0] if a.first_base_contact else None,
            }
        return {
            "t_last_s": self.t_last,
            "hover_window_s": list(self.hover_window),
            "slip_from_s": self.slip_from_s,
            "object": {
                "rest_z_m": self.z_rest,
                "final_lift_m": self.final_lift,
                "hover_min_lift_m": self.lift_min if self._lift_n else None,
                "hover_mean_lift_m": self._lift_sum / self._lift_n if self._lift_n else None,
                "touching_in_hover": sorted(self.object_touching_in_hover),
                "max_lift_m": max(self.lift_series, default=0.0),
            },
            "ams": ams,
        }
