"""The per-AM work of one physics step over every AM in one compiled call (numba): the devices
and the estimator (`sense`), the emulated autopilot's loops and its allocation (`fly`), and
both at once on a step that exchanges nothing with the companions (`hold`).

Each AM is a row (its slot) of stacked arrays: `simulator.devices.DeviceArrays` for the
devices and estimators, `simulator.flight_controller.AutopilotArrays` for the autopilots. The
per-AM objects (`DeviceSuite`, `FlightController`) keep views of their rows, and their own
`step` calls these kernels for their slot alone. The arithmetic is the kernels' each runs:
`simulator.device_kernels.suite_step` and `mocap_step`, `amcore.estimator.estimator_sample`,
`simulator.fc_kernels.rate_loops` and `amcore.allocation_kernels.allocate`, called in the
order one AM's step calls them; one call over the AMs saves the interpreter's work between
them (arguments unboxed once, no Python objects per AM).
"""
from __future__ import annotations

from amcore.allocation_kernels import allocate
from amcore.estimator import N_OUT, estimator_sample
from amcore.jit import kernel

from .device_kernels import mocap_step, suite_step
from .fc_kernels import autopilot_step


@kernel
def sense(slots, t, values, full, constants, state, imu_noise, ft_noise, noise_row, k, mocap_c, mocap_state,
          mocap_pending, mocap_draws, mocap_row, frames, est_x, est_hist, est_lpf, est_coef, est_gains, has_pose, lag,
          p_m, q_m, innovation, dt, g):
    """One physics step at t of the devices and the estimator of each AM in `slots`, from its
    row of `values` (the arm's and the wrist's too where `full`, else the base's 13): the
    devices, then the motion capture (its frame of the step, if one arrives, into `has_pose`,
    `lag`, `p_m`, `q_m`), then the estimator on both; its frame's values into its row of
    `frames` (the odometry first). Each AM takes the next row of its blocks of draws
    (`noise_row`, and `mocap_row` on a step that captures; `DeviceArrays.load` draws new blocks
    before a step that has none left)."""
    for a in range(slots.shape[0]):
        i = slots[a]
        j = noise_row[i]
        if j >= imu_noise.shape[1]:
            raise IndexError("an AM without draws left: DeviceArrays.load draws its next blocks")
        frame = frames[i]
        if full[i]:
            suite_step(values[i], t, constants[i:i + 1], state[i:i + 1], imu_noise[i, j], ft_noise[i, j],
                       frame[N_OUT:])
        else:
            suite_step(values[i, :N_OUT], t, constants[i:i + 1], state[i:i + 1], imu_noise[i, j], ft_noise[i, j],
                       frame[N_OUT:])
        noise_row[i] = j + 1
        has_pose[i] = mocap_step(mocap_c[i:i + 1], mocap_state[i:i + 1], mocap_pending[i], values[i], mocap_draws[i],
                                 mocap_row[i:i + 1], p_m[i], q_m[i])
        if has_pose[i]:
            lag[i] = mocap_c[i].lag
        s = state[i]
        k[i] += 1
        estimator_sample(est_x[i:i + 1], est_hist[i], est_lpf[i], est_coef[i:i + 1], k[i], k[i] == 0, s.omega_m,
                         s.f_m, dt, g, has_pose[i], lag[i], p_m[i], q_m[i], est_gains[i:i + 1], frame[:N_OUT],
                         innovation[i])


@kernel
def fly_on(slots, params, state, ap, attitude, rate, target_q, target_w, target_thrust, alloc_c, tol, result):
    """One physics step of the autopilot of each AM in `slots` (`fc_kernels.autopilot_step`) on
    the attitude (w, x, y, z) and body rates [rad/s] in its rows of `attitude` and `rate`."""
    for a in range(slots.shape[0]):
        i = slots[a]
        q, w = attitude[i], rate[i]
        autopilot_step(params[i:i + 1], state[i:i + 1], ap[i:i + 1], (q[0], q[1], q[2], q[3]), (w[0], w[1], w[2]),
                       target_q[i], target_w[i], target_thrust[i], alloc_c, tol, result[i:i + 1])


@kernel
def estimates(slots, frames, state, est_x, attitude, rate):
    """The attitude and rates each AM in `slots` flies on with [devices]: its estimator's
    attitude (the frame's) and the gyro less the estimator's bias (`DeviceSuite.autopilot_rate`)."""
    for a in range(slots.shape[0]):
        i = slots[a]
        for c in range(4):
            attitude[i, c] = frames[i, 3 + c]
        s = state[i]
        for c in range(3):
            rate[i, c] = s.omega_m[c] - est_x[i].b_g[c]


@kernel
def fly(slots, frames, dev_state, est_x, params, state, ap, attitude, rate, target_q, target_w, target_thrust,
        alloc_c, tol, result):
    """`fly_on` with [devices]: on the estimates (`estimates`)."""
    estimates(slots, frames, dev_state, est_x, attitude, rate)
    fly_on(slots, params, state, ap, attitude, rate, target_q, target_w, target_thrust, alloc_c, tol, result)


@kernel
def hold(sense_slots, t, values, full, constants, dev_state, imu_noise, ft_noise, noise_row, k, mocap_c, mocap_state,
         mocap_pending, mocap_draws, mocap_row, frames, est_x, est_hist, est_lpf, est_coef, est_gains, has_pose, lag,
         p_m, q_m, innovation, dt, g, fly_slots, params, state, ap, attitude, rate, target_q, target_w, target_thrust,
         alloc_c, tol, result):
    """A physics step of every AM in one call: `sense` for `sense_slots`, then `fly` for
    `fly_slots` on the estimates just made."""
    sense(sense_slots, t, values, full, constants, dev_state, imu_noise, ft_noise, noise_row, k, mocap_c, mocap_state,
          mocap_pending, mocap_draws, mocap_row, frames, est_x, est_hist, est_lpf, est_coef, est_gains, has_pose, lag,
          p_m, q_m, innovation, dt, g)
    fly(fly_slots, frames, dev_state, est_x, params, state, ap, attitude, rate, target_q, target_w, target_thrust,
        alloc_c, tol, result)
