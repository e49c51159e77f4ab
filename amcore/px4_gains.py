"""Attitude mode's PX4 gains for a vehicle, derived from a tuned reference (pure: numbers only).

PX4's rate loop works in normalized torque: one unit on axis a is S_a [N m] of physical torque
(amcore.allocation's `torque_scale_nm`, from the rotor table). A rate gain G in PX4's units is
a physical gain S_a G; divided by the whole AM's rotational inertia J_a it is a bandwidth. The
rule keeps the reference's bandwidths on every axis (roll, pitch, yaw):

    MC_<a>RATE_P, _I, _D = reference's * (J_a / J_ref,a) * (S_ref,a / S_a)
    MC_<a>_INT_LIM       = reference's * (S_ref,a / S_a)          (a moment, not a bandwidth)
    every other MC_* / IMU_* key: the reference's                  (rates and angles, unit-free)

J_a: the diagonal of the whole AM's rotational inertia about the base's origin, body axes, arm
at q_nominal_rad (pinocchio's CRBA, M[3:6, 3:6]). The reference is am3dof's tuning
(configs/vehicles/am3dof.toml and docs/flight_controller.md give why each value is what it is),
at its J_ref and S_ref. hex3dof's values were made by this rule by hand; a key a vehicle's
[flight_controller] table gives overrides the rule.
"""
from __future__ import annotations

AXES = ("roll", "pitch", "yaw")

# am3dof at q_nominal_rad: whole-AM inertia about the base [kg m^2] and PX4's torque units [N m]
REFERENCE_J_KG_M2 = (0.03509103, 0.0460513, 0.06602427)
REFERENCE_S_NM = (7.2, 7.2, 0.768)

# am3dof's tuned values (configs/vehicles/am3dof.toml)
REFERENCE = {
    "MC_ROLL_P": 17.0, "MC_PITCH_P": 25.0, "MC_YAW_P": 17.0, "MC_YAW_WEIGHT": 1.0,
    "MC_ROLLRATE_MAX": 220.0, "MC_PITCHRATE_MAX": 220.0, "MC_YAWRATE_MAX": 45.0,
    "MC_ROLLRATE_P": 0.32, "MC_ROLLRATE_I": 0.0, "MC_ROLLRATE_D": 0.006, "MC_ROLLRATE_FF": 0.0,
    "MC_ROLLRATE_K": 1.0, "MC_RR_INT_LIM": 0.3,
    "MC_PITCHRATE_P": 0.45, "MC_PITCHRATE_I": 3.0, "MC_PITCHRATE_D": 0.01, "MC_PITCHRATE_FF": 0.0,
    "MC_PITCHRATE_K": 1.0, "MC_PR_INT_LIM": 0.6,
    "MC_YAWRATE_P": 2.9, "MC_YAWRATE_I": 0.0, "MC_YAWRATE_D": 0.0, "MC_YAWRATE_FF": 0.0,
    "MC_YAWRATE_K": 1.0, "MC_YR_INT_LIM": 0.3,
    "IMU_GYRO_CUTOFF": 40.0, "IMU_DGYRO_CUTOFF": 30.0,
}
_RATE = {"roll": "MC_ROLLRATE_", "pitch": "MC_PITCHRATE_", "yaw": "MC_YAWRATE_"}
_INT_LIM = {"roll": "MC_RR_INT_LIM", "pitch": "MC_PR_INT_LIM", "yaw": "MC_YR_INT_LIM"}


def derived_gains(J_kg_m2, S_nm) -> dict[str, float]:
    """Every key of REFERENCE for a vehicle of inertia J_kg_m2 (roll, pitch, yaw) [kg m^2] and
    torque units S_nm [N m per unit] (module doc)."""
    out = dict(REFERENCE)
    for k, a in enumerate(AXES):
        units = REFERENCE_S_NM[k] / S_nm[k]
        for g in ("P", "I", "D"):
            out[_RATE[a] + g] = REFERENCE[_RATE[a] + g] * (J_kg_m2[k] / REFERENCE_J_KG_M2[k]) * units
        out[_INT_LIM[a]] = REFERENCE[_INT_LIM[a]] * units
    return out
