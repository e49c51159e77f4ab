"""The compiled numeric core: the paper's equations (Sec. II-III), one function each.

Everything here is compiled by numba (`amcore.jit.kernel`) and reads like the paper:
vectors and matrices with the paper's names, one function per equation. Pinocchio computes
the rigid-body terms (M^-1, C, the CoM Jacobian, {e}'s placement and Jacobians) outside;
the functions below turn them into the decoupled dynamics and the control law.

    decoupled             eq. new_coord, new_dynamics: T, T^-1, Tdot V, Lambda_w, Gamma_xi xi
    task                  eq. jacobian_xi: y, J_y, ydot, Jdot xi, J_e T^-1
    lowpass_step          the measured wrench's 2nd-order filter (amcore.filters)
    com_law               eq. Com_controller: f_d and its first two time derivatives
    desired_attitude      eq. Rd: R_d, Omega_d, Omegadot_d
    orientation_law       eq. ori_error, ori_vel_error, ori_controller: u_2
    impedance_law         eq. u3: u_3, with the singularity guard
    control_law           all of them, in order, for one step; its results packed in one array
    attitude_mode_torques attitude mode's body torque estimate and joint torques (amcore.offboard),
                          also reading its terms from control_law's result (_of_packed)
    adapted_reference     the robust options' trim, heading turn and lateral shift (amcore.adapt)

This module imports numpy and numba only (no I/O). Small dense linear algebra is written
out as loops (numba compiles them; at these sizes a call into BLAS or LAPACK costs more
than the arithmetic, and neither is available to numba without SciPy).
"""
from __future__ import annotations

import numpy as np

from .jit import kernel

E3 = np.array([0.0, 0.0, 1.0])


# ----------------------------------------------------------------------------- linear algebra
@kernel
def mv(A, x):
    """A x."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        out[i] = s
    return out


@kernel
def mtv(A, x):
    """A^T x."""
    out = np.zeros(A.shape[1])
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[j] += A[i, j] * x[i]
    return out


@kernel
def mm(A, B):
    """A B."""
    out = np.zeros((A.shape[0], B.shape[1]))
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            a = A[i, k]
            for j in range(B.shape[1]):
                out[i, j] += a * B[k, j]
    return out


@kernel
def mmt(A, B):
    """A B^T."""
    out = np.zeros((A.shape[0], B.shape[0]))
    for i in range(A.shape[0]):
        for j in range(B.shape[0]):
            s = 0.0
            for k in range(A.shape[1]):
                s += A[i, k] * B[j, k]
            out[i, j] = s
    return out


@kernel
def dot(a, b):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@kernel
def cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@kernel
def hat(r):
    """hat(r) x = r x x (eq. hat)."""
    return np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])


@kernel
def vee(S):
    """The inverse of hat, applied to S's antisymmetric part."""
    return 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


@kernel
def outer(a, b):
    """a b^T."""
    out = np.empty((a.shape[0], b.shape[0]))
    for i in range(a.shape[0]):
        for j in range(b.shape[0]):
            out[i, j] = a[i] * b[j]
    return out


@kernel
def columns(a, b, c):
    """The 3x3 matrix [a, b, c] of three column vectors."""
    out = np.empty((3, 3))
    out[:, 0] = a
    out[:, 1] = b
    out[:, 2] = c
    return out


@kernel
def solve(A, b):
    """x with A x = b (Gaussian elimination with partial pivoting); raises if A is singular."""
    n = A.shape[0]
    M = A.copy()
    x = b.copy()
    for c in range(n):
        p = c
        for r in range(c + 1, n):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        if M[p, c] == 0.0:
            raise ZeroDivisionError("singular matrix")
        if p != c:
            for j in range(n):
                M[c, j], M[p, j] = M[p, j], M[c, j]
            x[c], x[p] = x[p], x[c]
        for r in range(c + 1, n):
            f = M[r, c] / M[c, c]
            for j in range(c, n):
                M[r, j] -= f * M[c, j]
            x[r] -= f * x[c]
    for c in range(n - 1, -1, -1):
        s = x[c]
        for j in range(c + 1, n):
            s -= M[c, j] * x[j]
        x[c] = s / M[c, c]
    return x


@kernel
def inv(A):
    """A^-1 (Gauss-Jordan elimination with partial pivoting); raises if A is singular."""
    n = A.shape[0]
    M = np.empty((n, 2 * n))
    M[:, 0:n] = A
    M[:, n:] = 0.0
    for i in range(n):
        M[i, n + i] = 1.0
    for c in range(n):
        p = c
        for r in range(c + 1, n):
            if abs(M[r, c]) > abs(M[p, c]):
                p = r
        if M[p, c] == 0.0:
            raise ZeroDivisionError("singular matrix")
        if p != c:
            for j in range(2 * n):
                M[c, j], M[p, j] = M[p, j], M[c, j]
        pivot = M[c, c]
        for j in range(2 * n):
            M[c, j] /= pivot
        for r in range(n):
            if r != c:
                f = M[r, c]
                for j in range(2 * n):
                    M[r, j] -= f * M[c, j]
    return M[:, n:].copy()


@kernel
def sigma_min(A):
    """The smallest singular value of a square A (one-sided Jacobi SVD: rotations that make
    A's columns orthogonal; their norms are then the singular values, each to relative
    accuracy ~ eps, small ones included)."""
    U = A.copy()
    n = U.shape[1]
    for _ in range(60):
        off = 0.0
        for p in range(n - 1):
            for q in range(p + 1, n):
                a = 0.0
                b = 0.0
                g = 0.0
                for i in range(U.shape[0]):
                    a += U[i, p] * U[i, p]
                    b += U[i, q] * U[i, q]
                    g += U[i, p] * U[i, q]
                if g == 0.0 or abs(g) <= 1e-15 * np.sqrt(a * b):
                    continue
                off = max(off, abs(g) / np.sqrt(a * b))
                zeta = (b - a) / (2.0 * g)
                t = np.sign(zeta) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta)) if zeta != 0.0 else 1.0
                c = 1.0 / np.sqrt(1.0 + t * t)
                s = c * t
                for i in range(U.shape[0]):
                    up, uq = U[i, p], U[i, q]
                    U[i, p] = c * up - s * uq
                    U[i, q] = s * up + c * uq
        if off <= 1e-15:
            break
    smallest = np.inf
    for j in range(n):
        smallest = min(smallest, np.sqrt(dot(U[:, j], U[:, j])))
    return smallest


# ----------------------------------------------------------------------------- reference trajectories
def _smoothstep_horner() -> np.ndarray:
    """Row k: the coefficients of d^k s / d tau^k, highest power first (zero-padded), for
    s(tau) = 35 tau^4 - 84 tau^5 + 70 tau^6 - 20 tau^7 (amcore.mission.SmoothPath)."""
    c = np.array([0.0, 0.0, 0.0, 0.0, 35.0, -84.0, 70.0, -20.0])  # tau^0 .. tau^7
    rows = np.zeros((8, 8))
    for k in range(8):
        rows[k, :c.size] = c[::-1]
        c = c[1:] * np.arange(1, c.size)
    return rows


SMOOTHSTEP_HORNER = _smoothstep_horner()


@kernel
def smoothstep(tau, order):
    """d^order s / d tau^order of the minimum-snap rest-to-rest profile at tau, clamped to
    [0, 1] (Horner's scheme, as np.polyval)."""
    if tau <= 0.0 or tau >= 1.0:
        return (1.0 if tau >= 1.0 else 0.0) if order == 0 else 0.0
    if order >= 8:
        return 0.0
    y = 0.0
    for c in SMOOTHSTEP_HORNER[order, :8 - order]:
        y = y * tau + c
    return y


@kernel
def smooth_path(t, start, t0, duration, p0, delta, orders):
    """Rows p, p', ..., p^(orders) at time t of a sequence of rest-to-rest moves (move i from
    p0[i] to p0[i] + delta[i] over [t0[i], t0[i] + duration[i]]), holding between and after
    them: the last move that has started gives the value, row k = (s^(k)(tau) / T^k) delta."""
    out = np.zeros((orders + 1, start.shape[0]))
    i = -1
    for j in range(t0.shape[0]):
        if t < t0[j]:
            break
        i = j
    if i < 0:
        out[0] = start
        return out
    T = duration[i]
    tau = (t - t0[i]) / T
    out[0] = p0[i] + delta[i] * smoothstep(tau, 0)
    for k in range(1, orders + 1):
        out[k] = delta[i] * (smoothstep(tau, k) / T ** float(k))
    return out


# ----------------------------------------------------------------------------- the state, as pinocchio takes it
@kernel
def quaternion_xyzw(R):
    """The unit quaternion (x, y, z, w) of a rotation matrix, built as Eigen (and so pinocchio)
    builds it from a matrix."""
    q = np.zeros(4)
    t = R[0, 0] + R[1, 1] + R[2, 2]
    if t > 0.0:
        t = np.sqrt(t + 1.0)
        q[3] = 0.5 * t
        t = 0.5 / t
        q[0] = (R[2, 1] - R[1, 2]) * t
        q[1] = (R[0, 2] - R[2, 0]) * t
        q[2] = (R[1, 0] - R[0, 1]) * t
    else:
        i = 1 if R[1, 1] > R[0, 0] else 0
        i = 2 if R[2, 2] > R[i, i] else i
        j, k = (i + 1) % 3, (i + 2) % 3
        t = np.sqrt(R[i, i] - R[j, j] - R[k, k] + 1.0)
        q[i] = 0.5 * t
        t = 0.5 / t
        q[3] = (R[k, j] - R[j, k]) * t
        q[j] = (R[j, i] + R[i, j]) * t
        q[k] = (R[k, i] + R[i, k]) * t
    return q / np.sqrt(dot(q, q))


@kernel
def free_flyer_configuration(p_WB, quat_xyzw, q, v_B, w_B, qdot):
    """pinocchio's configuration [p_WB, quaternion (x, y, z, w), q] and velocity V = [v_b, w_b,
    qdot] of eq. dynamics, as two views of one array."""
    nq = 7 + q.shape[0]
    qv = np.empty(nq + 6 + qdot.shape[0])
    qv[0:3] = p_WB
    for i in range(4):
        qv[3 + i] = quat_xyzw[i]
    qv[7:nq] = q
    qv[nq:nq + 3] = v_B
    qv[nq + 3:nq + 6] = w_B
    qv[nq + 6:] = qdot
    return qv[0:nq], qv[nq:]


@kernel
def free_flyer_configuration_of_R(p_WB, R_WB, q, v_B, w_B, qdot):
    """free_flyer_configuration with the quaternion recovered from R_WB (quaternion_xyzw), in
    one call."""
    return free_flyer_configuration(p_WB, quaternion_xyzw(R_WB), q, v_B, w_B, qdot)


# ----------------------------------------------------------------------------- eq. new_coord, new_dynamics
@kernel
def decoupled(m, R, p_WB, w_B, V, Jcom, M_inv, C):
    """The inertially decoupled coordinates xi = T V (eq. new_coord) and the terms of eq.
    new_dynamics that the law needs, from pinocchio's CoM Jacobian, M^-1 and C.

    With r_b the CoM offset in {b} and J_b = d r_b / d q, pinocchio's CoM Jacobian is
    R [I, -hat(r_b), J_b] (T's first block row), and

        T     = [[R, -R hat(r_b), R J_b], [0, I, 0], [0, N_1, I]]
        T^-1  = [[R^T, hat(r_b) + J_b N_1, -J_b], [0, I, 0], [0, -N_1, I]]

    Lambda_xi^-1 = T M^-1 T^T is block diagonal and T's middle block row is [0, I, 0], so
    Lambda_w = ((M^-1)_ww)^-1, and T^-1's middle block column is (Lambda_w (M^-1)_(w,:))^T.
    Tdot V: the first block row's rate, with s = R^T rdot_c, is R (w x s + [0, -hat(rdot_b),
    Jdot_b] V) and m [0, -hat(rdot_b), Jdot_b] is Mdot's first block row (Mdot = C + C^T,
    pinocchio's C being skew-consistent); the last, N_1dot w = [0, N_1, I] M^-1 Mdot c with
    c = T^-1 [0; w; 0]. Gamma_xi xi = T^-T (C V - M T^-1 Tdot V), where T^-T M T^-1 Tdot V =
    Lambda_xi Tdot V = [m R a; 0; Z Mdot c] and Z = (T^-1[:, 6:])^T.

    Returns (T, T_inv, Tdot_V, Lambda_w, Gamma_xi_xi, r_c, rdot_c, r_b, J_b, N_1).
    """
    nv = V.shape[0]
    B = mm(R.T, Jcom)  # [I, -hat(r_b), J_b]
    r_b = vee(-B[:, 3:6])
    J_b = B[:, 6:]
    Lambda_w = inv(M_inv[3:6, 3:6])
    K = mm(Lambda_w, M_inv[3:6, :])  # T^-1's middle block column, transposed
    N_1 = -K[:, 6:].T

    T = np.eye(nv)
    T[0:3, :] = Jcom
    T[6:, 3:6] = N_1
    T_inv = np.eye(nv)
    T_inv[0:3, 0:3] = R.T
    T_inv[:, 3:6] = K.T
    T_inv[0:3, 6:] = -J_b

    Mdot = C + C.T
    w = w_B
    s = mv(B, V)
    a = cross(w, s) + mv(Mdot, V)[0:3] / m
    c = mtv(K, w)  # T^-1 [0; w; 0]
    Mdot_c = mv(Mdot, c)
    N1dot_w = mv(T[6:, :], mv(M_inv, Mdot_c))
    Tdot_V = np.zeros(nv)
    Tdot_V[0:3] = mv(R, a)
    Tdot_V[6:] = N1dot_w

    Lambda_xi_Tdot_V = np.zeros(nv)
    Lambda_xi_Tdot_V[0:3] = m * Tdot_V[0:3]
    Lambda_xi_Tdot_V[6:] = mtv(T_inv[:, 6:], Mdot_c)  # Z Mdot c = A N_1dot w
    Gamma_xi_xi = mtv(T_inv, mv(C, V)) - Lambda_xi_Tdot_V

    r_c = p_WB + mv(R, r_b)
    rdot_c = mv(R, s)
    return T, T_inv, Tdot_V, Lambda_w, Gamma_xi_xi, r_c, rdot_c, r_b, J_b, N_1


# ----------------------------------------------------------------------------- eq. jacobian_xi
@kernel
def task(H_TW, H_WE, J_e, Jdot_e, V, T_inv, Tdot_V, axes):
    """The task variable y in {t}, ydot = J_y V = J xi, and the drift Jdot xi of eq. jacobian_xi.

    axes: one row per component, (k, -1, -1) for the position along {t}'s axis k, (i, j, k)
    for the planar angle theta_k = atan2(u_j, u_i) of u = R_TE e_i (amcore.task). Each
    component's rate weights {e}'s body twist, ydot_r = W_r J_e V, with W_r = [e_k^T R_TE, 0]
    or [0, a^T R_TE], a = (e_k - u_k u) / (1 - u_k^2). The drift is
        Jdot xi = Jdot_y V - J_y T^-1 Tdot V = W (acc_e - J_e T^-1 Tdot V) + Wdot J_e V,
    with acc_e {e}'s classical acceleration at zero Vdot (the spatial one misses w x v).

    Returns (y, J_y, ydot, Jdot_y V, Jdot_xi, J_e_xi, W, Wdot) with J_e_xi = J_e T^-1.
    """
    n = axes.shape[0]
    twist = mv(J_e, V)  # {e}'s twist in {e}: [v_e; w_e]
    v_e, w_e = twist[0:3], twist[3:6]
    spatial_acc = mv(Jdot_e, V)
    acc_e = spatial_acc[0:3] + cross(w_e, v_e)
    alpha_e = spatial_acc[3:6]
    J_e_xi = mm(J_e, T_inv)
    from_Tdot = mv(J_e_xi, Tdot_V)  # J_e T^-1 Tdot V
    H_TE = mm(H_TW, H_WE)
    R_TE = H_TE[0:3, 0:3]
    p_TE = H_TE[0:3, 3]
    w_t = mv(R_TE, w_e)  # w_e in {t}

    y = np.zeros(n)
    ydot = np.zeros(n)
    Jdot_y_V = np.zeros(n)
    Jdot_xi = np.zeros(n)
    W = np.zeros((n, 6))
    Wdot = np.zeros((n, 6))
    for r in range(n):
        i, j, k = axes[r, 0], axes[r, 1], axes[r, 2]
        if j < 0:  # position along {t}'s axis k
            e_k_R = R_TE[i, :]  # e_k^T R_TE
            y[r] = p_TE[i]
            W[r, 0:3] = e_k_R
            ydot[r] = dot(e_k_R, v_e)
            Jdot_y_V[r] = dot(e_k_R, acc_e)
            Jdot_xi[r] = dot(e_k_R, acc_e - from_Tdot[0:3])
            continue
        u = R_TE[:, i]  # e_i of {e}, in {t}
        y[r] = np.arctan2(u[j], u[i])
        u_d = cross(w_t, u)
        D = 1.0 - u[k] * u[k]
        a = -u[k] * u
        a[k] += 1.0
        a_d = (-u_d[k] * u - u[k] * u_d) / D + a * (2.0 * u[k] * u_d[k] / D**2)
        aR = mtv(R_TE, a / D)  # W_r's angular part: a^T R_TE / (1 - u_k^2)
        adR = mtv(R_TE, a_d)
        W[r, 3:6] = aR
        Wdot[r, 3:6] = adR
        Wdot_twist = dot(adR, w_e)  # Wdot_r J_e V
        ydot[r] = dot(aR, w_e)
        Jdot_y_V[r] = dot(aR, alpha_e) + Wdot_twist
        Jdot_xi[r] = dot(aR, alpha_e - from_Tdot[3:6]) + Wdot_twist
    J_y = mm(W, J_e)
    return y, J_y, ydot, Jdot_y_V, Jdot_xi, J_e_xi, W, Wdot


# ----------------------------------------------------------------------------- the wrench filter
@kernel
def lowpass_step(x, xdot, u, Phi):
    """One exact zero-order-hold step of xddot = w^2 (u - x) - 2 zeta w xdot (amcore.filters),
    with Phi = exp(A dt) of its state matrix: the new (x, xdot)."""
    e = x - u
    return u + Phi[0, 0] * e + Phi[0, 1] * xdot, Phi[1, 0] * e + Phi[1, 1] * xdot


# ----------------------------------------------------------------------------- eq. Com_controller
@kernel
def saturation(e, limit):
    """sat(e) = e min(1, limit / |e|) and P = d sat / d e (the identity where not saturated).
    Derivatives of sat(e) are taken as P e^(k): exact for the first, the saturation's curvature
    is dropped in higher ones (feed-forward only)."""
    norm = np.sqrt(dot(e, e))
    if norm <= limit:
        return e.copy(), np.eye(3), False
    s = limit / norm
    u = e / norm
    P = s * (np.eye(3) - outer(u, u))
    return s * e, P, True


@kernel
def com_law(m, g, K_t, D_t, e, e_d, r_d2, r_d3, r_d4, R, w, F, F_d, F_dd, com_err_max, compensated):
    """eq. Com_controller, f_d = m (r_c,d'' + g e_3) - K_t sat(r~_c) - D_t r~_c' - F_rc, its
    thrust u_1 = f_d . b_3 and f_d's first two time derivatives (for eq. Rd).

    With an F/T sensor (compensated) f_d's derivatives use the model's CoM acceleration
    r_c'' = (u_1 b_3 + F_rc) / m - g e_3 and its rate; without one the CoM acceleration is
    unknown under contact and only what is measured or known stays (amcore.control).
    F, F_d, F_dd: the filtered force F_rc and its derivatives (zero where not compensated).
    Returns (f_d, f_d', f_d'', u_1, saturated).
    """
    e_sat, P, saturated = saturation(e, com_err_max)
    f_d = m * (r_d2 + g * E3) - mv(K_t, e_sat) - mv(D_t, e_d) - F
    b3 = R[:, 2]
    b3_d = mv(R, cross(w, E3))
    u1 = dot(f_d, b3)
    e_dd = (u1 * b3 + F) / m - g * E3 - r_d2 if compensated else np.zeros(3)
    f_d_d = m * r_d3 - mv(K_t, mv(P, e_d)) - mv(D_t, e_dd) - F_d
    u1_d = dot(f_d_d, b3) + dot(f_d, b3_d)
    e_ddd = (u1_d * b3 + u1 * b3_d + F_d) / m - r_d3 if compensated else np.zeros(3)
    f_d_dd = m * r_d4 - mv(K_t, mv(P, e_dd)) - mv(D_t, e_ddd) - F_dd
    return f_d, f_d_d, f_d_dd, u1, saturated


# ----------------------------------------------------------------------------- eq. Rd
@kernel
def unit_derivs(a, a_d, a_dd):
    """u = a / |a| and its first two time derivatives."""
    nn = dot(a, a)
    n = np.sqrt(nn)
    s1 = dot(a, a_d) / (n * nn)
    s2 = (dot(a_d, a_d) + dot(a, a_dd)) / (n * nn) - 3.0 * dot(a, a_d) ** 2 / (n * nn * nn)
    return a / n, a_d / n - a * s1, a_dd / n - 2.0 * a_d * s1 - a * s2


@kernel
def cross_derivs(a, a_d, a_dd, b, b_d, b_dd):
    """a x b and its first two time derivatives."""
    return (cross(a, b), cross(a_d, b) + cross(a, b_d),
            cross(a_dd, b) + 2.0 * cross(a_d, b_d) + cross(a, b_dd))


@kernel
def desired_attitude(f_d, f_d_d, f_d_dd, b1, b1_d, b1_dd):
    """eq. Rd: R_d = [b_2d x b_3d, b_2d, b_3d] with b_3d = f_d / |f_d| and b_2d = (b_3d x b_1d)
    / |b_3d x b_1d|; Omega_d = vee(R_d^T Rdot_d) and Omegadot_d = vee(R_d^T Rddot_d) (the
    symmetric hat(Omega_d)^2 drops out of vee). Raises if |f_d| or |b_3d x b_1d| vanishes.
    Returns (R_d, Omega_d, Omegadot_d)."""
    if dot(f_d, f_d) < 1e-12:
        raise FloatingPointError("eq. Rd needs |f_d| > 0")
    b3, b3_d, b3_dd = unit_derivs(f_d, f_d_d, f_d_dd)
    c, c_d, c_dd = cross_derivs(b3, b3_d, b3_dd, b1, b1_d, b1_dd)
    if dot(c, c) < 1e-12:
        raise FloatingPointError("eq. Rd: heading b_1d is parallel to b_3d")
    b2, b2_d, b2_dd = unit_derivs(c, c_d, c_dd)
    b1d, b1d_d, b1d_dd = cross_derivs(b2, b2_d, b2_dd, b3, b3_d, b3_dd)
    R_d = columns(b1d, b2, b3)
    Rdot_d = columns(b1d_d, b2_d, b3_d)
    Rddot_d = columns(b1d_dd, b2_dd, b3_dd)
    Omega_d = vee(mm(R_d.T, Rdot_d))
    Omegadot_d = vee(mm(R_d.T, Rddot_d))
    return R_d, Omega_d, Omegadot_d


# ----------------------------------------------------------------------------- eq. ori_controller
@kernel
def orientation_law(R, w, R_d, Omega_d, Omegadot_d, k_R, k_w, Lambda_wb_d_inv, Lambda_w, G_w, F_w):
    """eq. ori_error e_R = vee(R_d^T R_b - R_b^T R_d) / 2, eq. ori_vel_error e_w = w_b - w_b,d
    with w_b,d = R_b^T R_d Omega_d, and eq. ori_controller

        u_2 = Lambda_w (wdot_b,d - Lambda_wb,d^-1 (k_R e_R + k_w e_w)) + (Gamma_xi xi)_w - F_w,

    where d/dt w_b,d = -w_b x w_b,d + R_b^T R_d Omegadot_d. G_w = (Gamma_xi xi)_w; F_w = the
    measured wrench's w-block of F_xi (zero where not compensated).
    Returns (u_2, e_R, e_w, w_bd, wdot_bd)."""
    Q = mm(R.T, R_d)  # R_b^T R_d
    e_R = 0.5 * vee(Q.T - Q)
    w_bd = mv(Q, Omega_d)
    e_w = w - w_bd
    wdot_bd = -cross(w, w_bd) + mv(Q, Omegadot_d)
    u2 = mv(Lambda_w, wdot_bd - mv(Lambda_wb_d_inv, k_R * e_R + k_w * e_w)) + G_w - F_w
    return u2, e_R, e_w, w_bd, wdot_bd


# ----------------------------------------------------------------------------- eq. u3
@kernel
def expm_small(A):
    """exp(A) of a small square matrix: scaling and squaring with a 12-term Taylor series
    (relative error ~1e-15 once ||A / 2^s||_1 <= 0.5)."""
    n = A.shape[0]
    norm = 0.0
    for j in range(n):
        col = 0.0
        for i in range(n):
            col += abs(A[i, j])
        norm = max(norm, col)
    s = 0
    while norm > 0.5:
        norm *= 0.5
        s += 1
    X = A / 2.0**s
    E = np.eye(n)
    term = np.eye(n)
    for k in range(1, 13):
        term = mm(term, X) / k
        E = E + term
    for _ in range(s):
        E = mm(E, E)
    return E


@kernel
def discrete_damping(Lambda_y, D_y, dt):
    """D_y,dt = Lambda_y (I - exp(-Lambda_y^-1 D_y dt)) / dt (beyond the paper): the damping
    that, held over one control period dt, takes the task velocity of the mode Lambda_y y'' =
    -D_y y' where the continuous damper takes it in that time (exp(-Lambda_y^-1 D_y dt)),
    instead of overshooting it when Lambda_y^-1 D_y dt nears 2. Equals D_y as dt -> 0;
    symmetric as D_y is (Lambda_y f(Lambda_y^-1 D_y) is)."""
    n = D_y.shape[0]
    E = expm_small(-mm(inv(Lambda_y), D_y) * dt)
    return mm(Lambda_y, np.eye(n) - E) / dt


@kernel
def impedance_law(J_y, M_inv, T, Jdot_xi, y, ydot, y_d, y_d1, y_d2, y_err_max, K_y, D_y, u1_b3, mg_e3,
                  u2, G, sigma_damping, damping_max, r_extra, damping_dt=0.0):
    """eq. u3: the joint-space input that makes the task error obey eq. desired_task_behavior,
        Lambda_y y~'' + D_y y~' + K_y y~ = F_y.

    With J = J_y T^-1 and Lambda_xi^-1 = T M^-1 T^T: Lambda_y^-1 = J Lambda_xi^-1 J^T =
    J_y M^-1 J_y^T and Jbar = (J^{Lambda+})^T = Lambda_y J Lambda_xi^-1 = Lambda_y J_y M^-1 T^T.
    Its blocks [Jbar_1, Jbar_2, Jbar_3] act on u - Gamma_xi xi; with u_1 b_3 and u_2 fixed,
        Jbar_3 (u_3 - G_3) = -r,
        r = Lambda_y (Jdot xi - y_d'') + Jbar_1 (u_1 b_3 - m g e_3) + Jbar_2 (u_2 - G_w)
            + D_y y~' + K_y sat(y~).
    Singularity guard (beyond the paper): sat(y~) clips each error at y_err_max, and once
    sigma_min(Jbar_3) < sigma_damping, Jbar_3 is inverted by damped least squares.
    r_extra: an added term of r (the optional 1/2 Lambda_y' y~', amcore.control).
    damping_dt > 0 (beyond the paper, [options].discrete_damping): D_y replaced by
    `discrete_damping(Lambda_y, D_y, damping_dt)`, damping_dt the control period [s].
    Returns (u_3, Lambda_y, Jbar, y_err, sigma_min, damping, y_err_saturated).
    """
    n = y.shape[0]
    JyMi = mm(J_y, M_inv)
    Lambda_y = inv(mmt(JyMi, J_y))
    Jbar = mm(Lambda_y, mmt(JyMi, T))
    y_err = y - y_d
    y_err_sat = np.minimum(np.maximum(y_err, -y_err_max), y_err_max)
    yd_err = ydot - y_d1
    D = discrete_damping(Lambda_y, D_y, damping_dt) if damping_dt > 0.0 else D_y
    r = (mv(Lambda_y, Jdot_xi - y_d2) + mv(Jbar[:, 0:3], u1_b3 - mg_e3)
         + mv(Jbar[:, 3:6], u2 - G[3:6]) + mv(D, yd_err) + mv(K_y, y_err_sat) + r_extra)
    J3 = Jbar[:, 6:]
    sigma = sigma_min(J3)
    damping = 0.0
    if sigma >= sigma_damping:
        u3_G3 = solve(J3, r)
    else:
        damping = damping_max**2 * (1.0 - (sigma / sigma_damping) ** 2)
        u3_G3 = mtv(J3, solve(mmt(J3, J3) + damping * np.eye(n), r))
    u3 = G[6:] - u3_G3
    return u3, Lambda_y, Jbar, y_err, sigma, damping, bool(np.any(y_err_sat != y_err))


# ----------------------------------------------------------------------------- one step
@kernel
def control_law(m, g, R, p_WB, w_B, V, Jcom, M_inv, C, H_WE, J_e, Jdot_e,
                H_TW, axes, r_c_d, r_c_d1, r_c_d2, r_c_d3, r_c_d4, psi, psi_d1, psi_d2, y_d, y_d1, y_d2,
                wrench_E, filter_x, filter_xdot, Phi, filter_omega, filter_zeta,
                K_t, D_t, k_R, k_w, Lambda_wb_d_inv, K_y, D_y, com_err_max, y_err_max, sigma_damping, damping_max,
                compensated, force_rate_feedforward, r_extra, uncompensated_axis, damping_dt=0.0):
    """eqs. new_coord .. u3 in order, at one measured state. filter_x, filter_xdot: the wrench
    filter's state (world-aligned [f; m] at {e}), or empty arrays on the first step; Phi: its
    transition over this step's dt. uncompensated_axis: a unit vector in {w} along which the
    measured force is left out of F_rc in eq. Com_controller (beyond the paper: the task
    frame's y, along the face; amcore.control), or zero (the paper's: all of it). Returns one array: tau = T^T u first, then everything
    `amcore.control.Diagnostics` reads, in the order of `amcore.control.PACKED`."""
    T, T_inv, Tdot_V, Lambda_w, G, r_c, rdot_c, _, _, _ = decoupled(m, R, p_WB, w_B, V, Jcom, M_inv, C)
    y, J_y, ydot, _, Jdot_xi, J_e_xi, _, _ = task(H_TW, H_WE, J_e, Jdot_e, V, T_inv, Tdot_V, axes)

    # the measured wrench, world-aligned at {e}, low-pass filtered (exact derivatives)
    R_WE = H_WE[0:3, 0:3]
    raw_W = np.concatenate((mv(R_WE, wrench_E[0:3]), mv(R_WE, wrench_E[3:6])))
    if filter_x.shape[0] == 0:  # the first step
        x_W, xdot_W = raw_W, np.zeros(6)
    elif Phi[0, 1] == 0.0:  # dt = 0 (Phi = I): the state holds
        x_W, xdot_W = filter_x, filter_xdot
    else:
        x_W, xdot_W = lowpass_step(filter_x, filter_xdot, raw_W, Phi)
    wrench_E_f = np.concatenate((mtv(R_WE, x_W[0:3]), mtv(R_WE, x_W[3:6])))
    F_xi = mtv(J_e_xi, wrench_E_f)  # (J_e T^-1)^T F_e
    s = 1.0 if compensated else 0.0
    F = s * x_W[0:3]
    if force_rate_feedforward:
        F_d = s * xdot_W[0:3]
        F_dd = s * (filter_omega**2 * (raw_W[0:3] - x_W[0:3]) - 2.0 * filter_zeta * filter_omega * xdot_W[0:3])
    else:  # F_e treated as slowly varying in f_d's derivatives
        F_d = np.zeros(3)
        F_dd = np.zeros(3)
    if dot(uncompensated_axis, uncompensated_axis) > 0.0:
        a = uncompensated_axis
        F = F - dot(a, F) * a
        F_d = F_d - dot(a, F_d) * a
        F_dd = F_dd - dot(a, F_dd) * a

    e = r_c - r_c_d
    f_d, f_d_d, f_d_dd, u1, com_saturated = com_law(m, g, K_t, D_t, e, rdot_c - r_c_d1, r_c_d2, r_c_d3, r_c_d4,
                                                    R, w_B, F, F_d, F_dd, com_err_max, compensated)
    c, sn = np.cos(psi), np.sin(psi)
    b1 = np.array([c, sn, 0.0])
    b1_d = psi_d1 * np.array([-sn, c, 0.0])
    b1_dd = psi_d2 * np.array([-sn, c, 0.0]) - psi_d1**2 * b1
    R_d, Omega_d, Omegadot_d = desired_attitude(f_d, f_d_d, f_d_dd, b1, b1_d, b1_dd)
    u2, e_R, e_w, w_bd, wdot_bd = orientation_law(R, w_B, R_d, Omega_d, Omegadot_d, k_R, k_w, Lambda_wb_d_inv,
                                                  Lambda_w, G[3:6], s * F_xi[3:6])
    u1_b3 = u1 * R[:, 2]
    u3, Lambda_y, Jbar, y_err, sigma, damping, y_saturated = impedance_law(
        J_y, M_inv, T, Jdot_xi, y, ydot, y_d, y_d1, y_d2, y_err_max, K_y, D_y, u1_b3, m * g * E3, u2, G,
        sigma_damping, damping_max, r_extra, damping_dt)
    u = np.concatenate((u1_b3, u2, u3))
    tau = mtv(T, u)  # T^T u
    F_y = mv(Jbar, F_xi)
    flags = np.array([sigma, damping, 1.0 if com_saturated else 0.0, 1.0 if y_saturated else 0.0])
    q = quaternion_xyzw(R_d)
    q_d = np.array([q[3], q[0], q[1], q[2]]) * (1.0 if q[3] >= 0.0 else -1.0)  # R_d as (w, x, y, z), w >= 0
    return np.concatenate((
        tau, r_c, rdot_c, e, e_R, e_w, R_d.ravel(), q_d, w_bd, wdot_bd, Omega_d, f_d,
        y, y_err, ydot, F_y, x_W, wrench_E_f, x_W, xdot_W, u, Lambda_y.ravel(), flags,
        Lambda_w.ravel(), G, T_inv.ravel(), M_inv.ravel(), J_y.ravel(), J_e_xi.ravel()))


# ----------------------------------------------------------------------------- attitude mode
# amcore.offboard's item 1 (its module doc has the derivation): the body torque of the last
# control period from row 2 of eq. new_dynamics, and eq. u_bar's joint torques for it.
@kernel
def offboard_rest(G_w, F_wb, K, thrust, tau_q):
    """r = Gamma_wb w_b + Gamma_wb,rho rho - s F_wb^ - K_f f^- - K_q tau_q^-, with K = T^-T's
    middle block row (u_2 = K tau: K_f its thrust column, K_q its joint columns) and F_wb^ zero
    where the wrench is not compensated."""
    return G_w - F_wb - K[:, 2] * thrust - mv(K[:, 6:], tau_q)


@kernel
def body_torque_from_rate(Lambda_w, w, w_prev, dt, r):
    """tau_b^ = Lambda_wb (w_b - w_b^-) / dt + r: row 2 of eq. new_dynamics with the angular
    acceleration as the backward difference of the measured (or low-passed) body rate."""
    return mv(Lambda_w, (w - w_prev) / dt) + r


@kernel
def joint_torques_for_body_torque(J_y, M_inv, Lambda_y, damping, tau_b_p, tau_q_p, tau_b):
    """tau_q solving eq. u_bar with the body torque tau_b in place of torque mode's tau_b^p:
    tau_q^p - (J_y M^-1)_q^-1 (J_y M^-1)_w (tau_b - tau_b^p), by the damped least squares of
    eq. u3 in Lambda_y's metric where the step damped (damping > 0)."""
    JyMi = mm(J_y, M_inv)
    A = JyMi[:, 6:]
    rhs = mv(JyMi[:, 3:6], tau_b - tau_b_p)
    if damping > 0.0:
        A = mm(Lambda_y, A)
        rhs = mv(Lambda_y, rhs)
        return tau_q_p - mtv(A, solve(mmt(A, A) + damping * np.eye(A.shape[0]), rhs))
    return tau_q_p - solve(A, rhs)


@kernel
def attitude_mode_torques(Lambda_w, G, T_inv, J_e_xi, wrench_E_f, s, J_y, M_inv, Lambda_y, damping, thrust,
                          tau_b_p, tau_q_p, thrust_prev, tau_q_prev, w, w_prev, dt, Phi, w_filter, r_filter):
    """amcore.offboard's item 1 on a control step with a measurement before it (dt > 0):
    tau_b^, then the joint torques for it. f, tau_b^p, tau_q^p: torque mode's answer (eq. u3,
    the thrust sent as it is); s = 1 with force compensation (F_wb^ = ((J_e T^-1)^T F_e)_w from the
    filtered F/T reading), else 0; f^-, tau_q^-: the last thrust and joint torques (sent or
    reported); w, w_prev: the body rate now and at the last step.

    Phi: the low-pass's transition over dt (offboard_torque_cutoff_hz > 0; a 0x0 array for
    the plain backward difference); w_filter, r_filter: the filters' states, rows (x, xdot),
    of w_b and of r (r_filter with no rows until the filter starts, on its input).
    Returns (tau, u = T^-T tau, w_filter, r_filter) with tau = [0, 0, f, tau_b^, tau_q]."""
    K = T_inv[:, 3:6].T
    r = offboard_rest(G[3:6], s * mtv(J_e_xi[:, 3:6], wrench_E_f), K, thrust_prev, tau_q_prev)
    if Phi.shape[0] == 0:
        tau_b = body_torque_from_rate(Lambda_w, w, w_prev, dt, r)
        w_new, r_new = w_filter, r_filter
    else:
        w_new = np.empty((2, 3))
        w_new[0], w_new[1] = lowpass_step(w_filter[0], w_filter[1], w, Phi)
        r_new = np.zeros((2, 3))
        if r_filter.shape[0] == 0:
            r_new[0] = r
        else:
            r_new[0], r_new[1] = lowpass_step(r_filter[0], r_filter[1], r, Phi)
        tau_b = body_torque_from_rate(Lambda_w, w_new[0], w_filter[0], dt, r_new[0])
    tau = np.zeros(T_inv.shape[0])
    tau[2] = thrust
    tau[3:6] = tau_b
    tau[6:] = joint_torques_for_body_torque(J_y, M_inv, Lambda_y, damping, tau_b_p, tau_q_p, tau_b)
    return tau, mtv(T_inv, tau), w_new, r_new


@kernel
def attitude_mode_torques_of_packed(packed, at, n, s, thrust, tau_b_p, tau_q_p, thrust_prev, tau_q_prev, w, w_prev,
                                    dt, Phi, w_filter, r_filter):
    """`attitude_mode_torques` with the terms torque mode's step evaluated read from its
    `control_law` result `packed` (task dimension n), not handed over one by one: `at` holds
    the offsets in it of Lambda_w, Gamma_xi_xi, T_inv, J_e_xi, wrench_E_filtered, J_y, M_inv,
    Lambda_y and the guard (whose second entry is the damping; amcore.control.PACKED)."""
    nv = n + 6
    return attitude_mode_torques(
        packed[at[0]:at[0] + 9].reshape((3, 3)), packed[at[1]:at[1] + nv],
        packed[at[2]:at[2] + nv * nv].reshape((nv, nv)), packed[at[3]:at[3] + 6 * nv].reshape((6, nv)),
        packed[at[4]:at[4] + 6], s, packed[at[5]:at[5] + n * nv].reshape((n, nv)),
        packed[at[6]:at[6] + nv * nv].reshape((nv, nv)), packed[at[7]:at[7] + n * n].reshape((n, n)),
        packed[at[8] + 1], thrust, tau_b_p, tau_q_p, thrust_prev, tau_q_prev, w, w_prev, dt, Phi, w_filter, r_filter)


# ----------------------------------------------------------------------------- the robust options' references
@kernel
def adapted_reference(r, dr, turn, dpsi, dpsi_d1, pivot, shift, dy, dy_d1, dy_d2, R_WT, p_WT):
    """amcore.adapt's shaping of one step's reference and task frame, in its order
    (`amcore.adapt.adapted`; beyond the paper): r (5 x 3) the CoM path r_c .. r_c_d4 in {w}
    moved by the trim's dr; with `turn` (the heading admittance on), the path and the task frame
    (R_WT, p_WT) turned by dpsi about the vertical through pivot; with `shift` (the lateral
    admittance on), the path moved by dy and its two rates along the (turned) frame's y axis.
    Each part is skipped where its function in amcore.adapt returns its input unchanged.
    Returns (r, R_WT, p_WT, H_TW, e_y_W) of the adapted reference and frame."""
    out = r.copy()
    if dr[0] != 0.0 or dr[1] != 0.0 or dr[2] != 0.0:  # trim_reference
        out[0] = out[0] + dr
    R, p = R_WT.copy(), p_WT.copy()
    if turn:
        c, s = np.cos(dpsi), np.sin(dpsi)
        Rz = np.array(((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0)))
        if dpsi != 0.0 or dpsi_d1 != 0.0:  # turn_reference
            out[0] = pivot + mv(Rz, out[0] - pivot)
            for k in range(1, 5):
                out[k] = mv(Rz, out[k])
        if dpsi != 0.0:  # turn_frame
            R, p = mm(Rz, R_WT), pivot + mv(Rz, p_WT - pivot)
    e_y = R[:, 1].copy()
    if shift and (dy != 0.0 or dy_d1 != 0.0):  # shift_reference
        out[0] = out[0] + dy * e_y
        out[1] = out[1] + dy_d1 * e_y
        out[2] = out[2] + dy_d2 * e_y
    H = np.eye(4)  # TaskFrame.H_TW
    H[0:3, 0:3] = R.T
    H[0:3, 3] = -mtv(R, p)
    return out, R, p, H, e_y
