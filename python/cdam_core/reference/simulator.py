"""Numpy reference of the simulator: right-hand side, RK4, controller and closed loop.

The twin of ``cpp/include/cdam/sim/`` (never calls ``_core``). Written for clarity; the C++ core
must agree with it to 1e-12 on f(x, u) and 1e-9 on a 1 s closed-loop trajectory.

State x (NX = 21): p = (X, Y, Z) world [0:3], quaternion (w, x, y, z) body->world [3:7],
link angles q1, q2 [7:9], motor angles theta_m1, theta_m2 (after the gearbox) [9:11],
v world [11:14], omega body [14:17], q' [17:19], theta_m' [19:21].
Applied input u (NU = 6): rotor speeds O1..O4 (rad/s), motor torques tau_m1, tau_m2 (N m).

Equations (documented in full in ``cdam/sim/coupling.hpp``): Kane's equations of the body, the
two links and the payload point mass with generalised speeds (v, omega, q'), which gives
M(x) [v'; omega'; q''] = Q - h with M symmetric positive definite (the full coupling: the arm's
reaction on the body and the body's motion on the arm); the motor sides are eq. (3):
Im theta_m'' + Dm theta_m' + tau_l + Fc tanh(theta_m'/eps) = tau_m, with the cable torque
eq. (4) tau_l = Ks dz + K3 dz^3 + Kd (theta_m' - q'), dz = dead-zone(theta_m - q, backlash/2).
"""
from __future__ import annotations

import math

import numpy as np

# The parameter layout, written out here so that the twin shares no code with cdam_core.sim
# (tests/sim check that it equals cdam_core.sim.parameters' layout).
PLANT_NAMES = ('m_body', 'Jx', 'Jy', 'Jz', 'Kx', 'Ky', 'Kz', 'Kphi', 'Ktheta', 'Kpsi', 'g', 'CT',
               'CQ', 'L', 'Jm', 'omega_min', 'omega_max', 'd_base', 'm1', 'l1', 'lc1', 'I1xx',
               'I1yy', 'I1zz', 'm2', 'l2', 'lc2', 'I2xx', 'I2yy', 'I2zz', 'Im1', 'Im2', 'Dm1',
               'Dm2', 'Ks1', 'Ks2', 'Kd1', 'Kd2', 'Dl1', 'Dl2', 'Fc1', 'Fc2', 'fric_eps',
               'backlash1', 'backlash2', 'K3_1', 'K3_2', 'payload', 'ground_k', 'rotor_radius',
               'thrust_loss')
CONTROL_NAMES = ('m_ctrl', 'kp_pos', 'kp_vel', 'ki_vel', 'v_max', 'tilt_max', 'kp_z', 'kp_vz',
                 'ki_vz', 'kp_att_rp', 'kp_att_y', 'kp_rate_rp', 'ki_rate_rp', 'kd_rate_rp',
                 'kp_rate_y', 'ki_rate_y', 'rate_max', 'tau_max', 'kp_joint', 'ki_joint',
                 'kd_joint', 'tau_m_max', 'current_lsb', 'kt', 'delay_rotor', 'delay_joint')


def total_mass(p: dict, with_payload: bool = True) -> float:
    """Body + links (+ payload) mass in kg."""
    return p["m_body"] + p["m1"] + p["m2"] + (p["payload"] if with_payload else 0.0)

NX, NU, NSP, NLOG, NCS = 21, 6, 8, 10, 11
EY = np.array([0.0, 1.0, 0.0])
EZ = np.array([0.0, 0.0, 1.0])


def _p(vec):
    return dict(zip(PLANT_NAMES, np.asarray(vec, dtype=float).tolist()))


def _c(vec):
    return dict(zip(CONTROL_NAMES, np.asarray(vec, dtype=float).tolist()))


def quat_to_rot(qt):
    """Rotation matrix body -> world of a unit quaternion (w, x, y, z)."""
    w, x, y, z = qt
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def quat_to_euler(qt):
    """Z-Y-X Euler angles (phi, theta, psi) of quaternions (..., 4)."""
    qt = np.asarray(qt, dtype=float)
    w, x, y, z = qt[..., 0], qt[..., 1], qt[..., 2], qt[..., 3]
    phi = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    theta = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    psi = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([phi, theta, psi], axis=-1)


def euler_to_quat(phi, theta, psi):
    """Quaternion (w, x, y, z) of Z-Y-X Euler angles."""
    cr, sr = math.cos(phi / 2), math.sin(phi / 2)
    cp, sp = math.cos(theta / 2), math.sin(theta / 2)
    cy, sy = math.cos(psi / 2), math.sin(psi / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def cross(a, b):
    """a x b of two 3-vectors (faster than np.cross for single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def skew(r):
    return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])


def _e(a):
    return np.array([-math.sin(a), 0.0, -math.cos(a)])


def _de(a):
    return np.array([-math.cos(a), 0.0, math.sin(a)])


def _roty(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def arm_bodies(P, q, qd):
    """Arm bodies in the body frame: list of (mass, r, dr/dq (3x2), r'' velocity part, r',
    selector s (angular rate = s . q'), inertia in body frame or None)."""
    a1, a2 = q[0], q[0] + q[1]
    a1d, a2d = qd[0], qd[0] + qd[1]
    r0 = np.array([0.0, 0.0, -P["d_base"]])
    out = []
    # link 1
    J = np.zeros((3, 2))
    J[:, 0] = P["lc1"] * _de(a1)
    r = r0 + P["lc1"] * _e(a1)
    rd = P["lc1"] * _de(a1) * a1d
    quad = -P["lc1"] * _e(a1) * a1d * a1d
    R1 = _roty(a1)
    I1 = R1 @ np.diag([P["I1xx"], P["I1yy"], P["I1zz"]]) @ R1.T
    out.append((P["m1"], r, J, quad, rd, np.array([1.0, 0.0]), I1))
    # link 2 and the payload at its tip
    R2 = _roty(a2)
    I2 = R2 @ np.diag([P["I2xx"], P["I2yy"], P["I2zz"]]) @ R2.T
    for m, lc, inertia in ((P["m2"], P["lc2"], I2), (P["payload"], P["l2"], None)):
        J = np.zeros((3, 2))
        J[:, 0] = P["l1"] * _de(a1) + lc * _de(a2)
        J[:, 1] = lc * _de(a2)
        r = r0 + P["l1"] * _e(a1) + lc * _e(a2)
        rd = P["l1"] * _de(a1) * a1d + lc * _de(a2) * a2d
        quad = -P["l1"] * _e(a1) * a1d * a1d - lc * _e(a2) * a2d * a2d
        out.append((m, r, J, quad, rd, np.array([1.0, 1.0]), inertia))
    return out


def cable_torque(P, k, defl, defl_d):
    """Eq. (4) with backlash (dead zone of total width) and a cubic hardening term."""
    h = 0.5 * P[f"backlash{k}"]
    dz = math.copysign(max(abs(defl) - h, 0.0), defl)
    return P[f"Ks{k}"] * dz + P[f"K3_{k}"] * (dz * dz * dz) + P[f"Kd{k}"] * defl_d


def thrust_factors(P, t, Z):
    """(collective thrust factor, per-rotor thrust factor) from ground effect and thrust loss."""
    loss = max(1.0 - P["thrust_loss"] * t, 0.0)
    z = max(Z, 0.05)
    r = P["rotor_radius"] / (4.0 * z)
    ge = 1.0 + P["ground_k"] * (r * r)
    return ge * loss, loss


def rhs(plant, t, x, u):
    """dx/dt of the coupled rigid-flexible system (the numpy twin of ``cdam::sim::rhs``)."""
    P = _p(plant)
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    qt = x[3:7]
    q, th, v, w, qd, thd = x[7:9], x[9:11], x[11:14], x[14:17], x[17:19], x[19:21]
    R = quat_to_rot(qt)
    g = P["g"]
    # rotors, eq. (2) with the X mixer
    om = u[0:4]
    s = om * om
    a = P["L"] / math.sqrt(2.0)
    fT, fr = thrust_factors(P, t, x[2])
    T = P["CT"] * s.sum() * fT
    tau = np.array([a * P["CT"] * (-s[0] - s[1] + s[2] + s[3]) * fr,
                    a * P["CT"] * (-s[0] + s[1] + s[2] - s[3]) * fr,
                    P["CQ"] * (s[0] - s[1] + s[2] - s[3])])
    omr = om[0] - om[1] + om[2] - om[3]
    tau = tau - P["Jm"] * omr * cross(w, EZ)
    tau = tau - np.array([P["Kphi"], P["Ktheta"], P["Kpsi"]]) * w
    # joints, eqs. (3)-(4)
    tl = np.array([cable_torque(P, k + 1, th[k] - q[k], thd[k] - qd[k]) for k in range(2)])
    # generalised mass matrix and forces (Kane)
    M = np.zeros((8, 8))
    Q = np.zeros(8)
    M[0:3, 0:3] += P["m_body"] * np.eye(3)
    M[3:6, 3:6] += np.diag([P["Jx"], P["Jy"], P["Jz"]])
    h = np.zeros(8)
    h[3:6] = cross(w, np.array([P["Jx"], P["Jy"], P["Jz"]]) * w)
    Q[0:3] = R @ EZ * T - np.array([P["Kx"], P["Ky"], P["Kz"]]) * v - P["m_body"] * g * EZ
    Q[3:6] = tau
    Q[6:8] = tl - np.array([P["Dl1"], P["Dl2"]]) * qd
    for m, r, J, quad, rd, sel, inertia in arm_bodies(P, q, qd):
        A = np.zeros((3, 8))
        A[:, 0:3] = np.eye(3)
        A[:, 3:6] = -R @ skew(r)
        A[:, 6:8] = R @ J
        b = R @ (cross(w, cross(w, r)) + 2 * cross(w, rd) + quad)
        M += m * A.T @ A
        h += m * A.T @ b
        Q += A.T @ (-m * g * EZ)
        if inertia is not None:
            B = np.zeros((3, 8))
            B[:, 3:6] = np.eye(3)
            B[:, 6:8] = np.outer(EY, sel)
            wk = w + (sel @ qd) * EY
            c = cross(w, (sel @ qd) * EY)
            M += B.T @ inertia @ B
            h += B.T @ (inertia @ c + cross(wk, inertia @ wk))
    acc = np.linalg.solve(M, Q - h)
    fric = np.array([P["Fc1"], P["Fc2"]]) * np.tanh(thd / P["fric_eps"])
    thdd = (u[4:6] - np.array([P["Dm1"], P["Dm2"]]) * thd - tl - fric) / np.array([P["Im1"], P["Im2"]])
    wq = np.concatenate([[0.0], w])
    qdot = 0.5 * _quat_mul(qt, wq)
    return np.concatenate([v, qdot, qd, thd, acc, thdd])


def _quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
                     w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
                     w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def rk4_step(plant, t, x, u, h):
    """One classical RK4 step of length h with u held."""
    k1 = rhs(plant, t, x, u)
    k2 = rhs(plant, t + h / 2, x + h / 2 * k1, u)
    k3 = rhs(plant, t + h / 2, x + h / 2 * k2, u)
    k4 = rhs(plant, t + h, x + h * k3, u)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def _normalise(x):
    x = x.copy()
    x[3:7] /= np.linalg.norm(x[3:7])
    return x


def integrate_open_loop(plant, x0, U, dt, substeps):
    """States (N+1, NX) from x0 under inputs U (N, NU), each held for one step of dt split into
    ``substeps`` RK4 steps; the quaternion is renormalised after every step of dt."""
    X = np.empty((len(U) + 1, NX))
    X[0] = x = np.asarray(x0, dtype=float)
    h = dt / substeps
    for k, u in enumerate(np.asarray(U, dtype=float)):
        t = k * dt
        for j in range(substeps):
            x = rk4_step(plant, t + j * h, x, u, h)
        X[k + 1] = x = _normalise(x)
    return X


def hover_state(plant, Z=1.0):
    """The hover state: level, at (0, 0, Z), arm hanging, cables relaxed, at rest."""
    x = np.zeros(NX)
    x[2] = Z
    x[3] = 1.0
    return x


def mixer(P, T, tau):
    """X-frame inverse of eq. (2): squared rotor speeds for (T, tau_x, tau_y, tau_z), clamped to
    [omega_min^2, omega_max^2]."""
    a = P["L"] / math.sqrt(2.0)
    b0 = T / P["CT"]
    b1 = tau[0] / (a * P["CT"])
    b2 = tau[1] / (a * P["CT"])
    b3 = tau[2] / P["CQ"]
    s = 0.25 * np.array([b0 - b1 - b2 + b3, b0 - b1 + b2 - b3, b0 + b1 + b2 + b3, b0 + b1 - b2 - b3])
    return np.clip(s, P["omega_min"] ** 2, P["omega_max"] ** 2)


def mixer_forward(P, s):
    """Nominal eq. (2), X frame: (T, tau_x, tau_y, tau_z) from squared rotor speeds."""
    a = P["L"] / math.sqrt(2.0)
    return np.array([P["CT"] * s.sum(), a * P["CT"] * (-s[0] - s[1] + s[2] + s[3]),
                     a * P["CT"] * (-s[0] + s[1] + s[2] - s[3]), P["CQ"] * (s[0] - s[1] + s[2] - s[3])])


def _clamp(v, lim):
    return min(max(v, -lim), lim)


def _wrap(a):
    return math.atan2(math.sin(a), math.cos(a))


def controller(P, C, x, sp, cs, dt):
    """One 1 kHz tick of the Pixhawk-like cascades and the STM32 joint PID.

    sp = (X, Y, Z, phi offset, theta offset, psi, q1, q2) setpoints; cs (NCS = 11) the
    controller state [I_vx, I_vy, I_vz, I_p, I_q, I_r, I_j1, I_j2, w_prev(3)], updated in place.
    Returns (squared rotor speeds (4), motor torques (2)).
    """
    g = P["g"]
    eta = quat_to_euler(x[3:7])
    phi, theta, psi = eta
    v, w, th, thd = x[11:14], x[14:17], x[9:11], x[19:21]
    # position -> acceleration -> tilt
    acc = [0.0, 0.0]
    for i in range(2):
        vsp = _clamp(C["kp_pos"] * (sp[i] - x[i]), C["v_max"])
        e = vsp - v[i]
        cs[i] = _clamp(cs[i] + e * dt, 2.0)
        acc[i] = C["kp_vel"] * e + C["ki_vel"] * cs[i]
    cy, sy = math.cos(psi), math.sin(psi)
    tmax = C["tilt_max"]
    theta_d = _clamp(_clamp((acc[0] * cy + acc[1] * sy) / g, tmax) + sp[4], tmax)
    phi_d = _clamp(_clamp((acc[0] * sy - acc[1] * cy) / g, tmax) + sp[3], tmax)
    # altitude
    vzsp = _clamp(C["kp_z"] * (sp[2] - x[2]), 1.5)
    ez = vzsp - v[2]
    cs[2] = _clamp(cs[2] + ez * dt, 5.0)
    az = C["kp_vz"] * ez + C["ki_vz"] * cs[2]
    m = C["m_ctrl"] if C["m_ctrl"] > 0 else total_mass(P, with_payload=False)
    T = m * (g + az) / max(math.cos(phi) * math.cos(theta), 0.5)
    T = min(max(T, 0.0), 4.0 * P["CT"] * P["omega_max"] ** 2)
    # attitude -> rates -> torques
    e_eta = (phi_d - phi, theta_d - theta, _wrap(sp[5] - psi))
    kp_att = (C["kp_att_rp"], C["kp_att_rp"], C["kp_att_y"])
    kp_r = (C["kp_rate_rp"], C["kp_rate_rp"], C["kp_rate_y"])
    ki_r = (C["ki_rate_rp"], C["ki_rate_rp"], C["ki_rate_y"])
    kd_r = (C["kd_rate_rp"], C["kd_rate_rp"], 0.0)
    J = (P["Jx"], P["Jy"], P["Jz"])
    tau = np.zeros(3)
    for i in range(3):
        wsp = _clamp(kp_att[i] * e_eta[i], C["rate_max"])
        e = wsp - w[i]
        cs[3 + i] = _clamp(cs[3 + i] + e * dt, 1.0)
        dw = (w[i] - cs[8 + i]) / dt
        tau[i] = _clamp(J[i] * (kp_r[i] * e + ki_r[i] * cs[3 + i] - kd_r[i] * dw), C["tau_max"])
        cs[8 + i] = w[i]
    s = mixer(P, T, tau)
    # joints
    taum = np.zeros(2)
    for k in range(2):
        e = sp[6 + k] - th[k]
        cs[6 + k] = _clamp(cs[6 + k] + e * dt, 0.5)
        tm = _clamp(C["kp_joint"] * e + C["ki_joint"] * cs[6 + k] - C["kd_joint"] * thd[k],
                    C["tau_m_max"])
        if C["current_lsb"] > 0:
            lsb = C["kt"] * C["current_lsb"]
            tm = lsb * math.floor(tm / lsb + 0.5)
        taum[k] = tm
    return s, taum


def simulate_closed_loop(plant, control, x0, setpoints, dt=1e-3, substeps=1):
    """Closed-loop flight: setpoints (N, 8) at 1/dt; returns (states (N, NX) at the ticks,
    log (N, 10) = [T, tau_phi, tau_theta, tau_psi, tau_m1, tau_m2, O1..O4] commanded at the
    ticks). Delays (``delay_rotor``, ``delay_joint`` ticks) apply the command of an earlier tick;
    before the first tick the first command is used."""
    P, C = _p(plant), _c(control)
    SP = np.asarray(setpoints, dtype=float)
    N = len(SP)
    X = np.empty((N, NX))
    LOG = np.empty((N, NLOG))
    cs = np.zeros(NCS)
    cs[8:11] = np.asarray(x0, dtype=float)[14:17]
    x = np.asarray(x0, dtype=float).copy()
    dr, dj = int(C["delay_rotor"]), int(C["delay_joint"])
    cmd_om = np.empty((N, 4))
    cmd_tm = np.empty((N, 2))
    h = dt / substeps
    for k in range(N):
        X[k] = x
        s, taum = controller(P, C, x, SP[k], cs, dt)
        om = np.sqrt(s)
        cmd_om[k], cmd_tm[k] = om, taum
        LOG[k, 0:4] = mixer_forward(P, s)
        LOG[k, 4:6] = taum
        LOG[k, 6:10] = om
        u = np.concatenate([cmd_om[max(k - dr, 0)], cmd_tm[max(k - dj, 0)]])
        t = k * dt
        for j in range(substeps):
            x = rk4_step(plant, t + j * h, x, u, h)
        x = _normalise(x)
    return X, LOG
