"""An independent quadrotor flight generator for the quad_physics tests (plain numpy).

Written apart from ``cdam_core.models.flight.physics`` and ``cdam_core.sim``: the attitude is a
rotation matrix (R' = R [w]x, re-orthonormalised by SVD after each sub-step), the rigid body is
Euler's equation with the full inertia product J^-1 (tau - w x J w), the integrator is RK4 with
``SUB`` sub-steps per sample, and the quaternion of the output comes from the rotation matrix
(Shepperd's method), sign kept continuous. Rotor speeds are held over each sample (what a
logged speed does between two log rows); the controller (position PD -> thrust and attitude,
attitude PD -> torques, plus a random torque excitation, X mixer inverted) runs once per sample
on the noisy measured state. Geometry: Crazyflie numbering, M1 front-right, M2 rear-right, M3
rear-left, M4 front-left; rotor i at (sx_i, sy_i) a with a = arm / sqrt 2; M1 and M3 turn so
that their drag torque is -kQ w^2 about z, M2 and M4 +kQ w^2.
"""
import numpy as np

TRUTH = dict(mass=0.040, arm=0.050, kT=3.0e-8, kQ=4.0e-10, J=(1.6e-5, 2.0e-5, 3.0e-5),
             drag_xy=0.30, drag_z=0.45, g=9.80665)
SX = np.array([1.0, -1.0, -1.0, 1.0])      # rotor x sign (front +)
SY = np.array([-1.0, -1.0, 1.0, 1.0])      # rotor y sign (left +)
SZ = np.array([-1.0, 1.0, -1.0, 1.0])      # drag torque sign about z
SUB = 2
NOISE = dict(p=1e-3, v=5e-3, q=1e-3, w=1e-2)   # measurement noise std per state group


def ratios(truth=TRUTH):
    """The parameters the flights identify, computed from the truth."""
    a = truth["arm"] / np.sqrt(2.0)
    Jx, Jy, Jz = truth["J"]
    kT, kQ = truth["kT"], truth["kQ"]
    return {"kT/m": kT / truth["mass"], "drag_xy": truth["drag_xy"], "drag_z": truth["drag_z"],
            "b_x": a * kT / Jx, "b_y": a * kT / Jy, "b_z": kQ / Jz,
            "c_x": (Jy - Jz) / Jx, "c_y": (Jz - Jx) / Jy, "c_z": (Jx - Jy) / Jz}


def _hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _deriv(s, om2, tr):
    """s = (p, v, R (9), w) flattened; om2: the held squared rotor speeds."""
    v, R, w = s[3:6], s[6:15].reshape(3, 3), s[15:18]
    a = tr["arm"] / np.sqrt(2.0)
    J = np.array(tr["J"])
    T = tr["kT"] * om2.sum()
    tau = np.array([a * tr["kT"] * np.dot(SY, om2), -a * tr["kT"] * np.dot(SX, om2),
                    tr["kQ"] * np.dot(SZ, om2)])
    D = R @ np.diag([tr["drag_xy"], tr["drag_xy"], tr["drag_z"]]) @ R.T
    dv = R[:, 2] * T / tr["mass"] - np.array([0.0, 0.0, tr["g"]]) - D @ v
    dR = R @ _hat(w)
    dw = (tau - np.cross(w, J * w)) / J
    return np.concatenate([v, dv, dR.ravel(), dw])


def _orthonormal(R):
    u, _, vt = np.linalg.svd(R)
    return u @ vt


def quat_from_matrix(R):
    """(x, y, z, w) of a rotation matrix (Shepperd's method)."""
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        return np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s,
                         (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
    q = np.zeros(4)
    q[i] = 0.25 * s
    q[j] = (R[j, i] + R[i, j]) / s
    q[k] = (R[k, i] + R[i, k]) / s
    q[3] = (R[k, j] - R[j, k]) / s
    return q


def _mixer_inverse(T, tau, tr):
    """Squared rotor speeds giving thrust T and torques tau (the X mixer inverted)."""
    a = tr["arm"] / np.sqrt(2.0)
    M = np.vstack([tr["kT"] * np.ones(4), a * tr["kT"] * SY, -a * tr["kT"] * SX, tr["kQ"] * SZ])
    return np.linalg.solve(M, np.r_[T, tau])


def flight(seconds=30.0, dt=0.01, seed=0, truth=TRUTH, noise=NOISE, excite=1.0, lag=0.0,
           effect=None):
    """(U (N, 4) rotor speeds in rad/s, Y (N, 13) measured states, Ytrue (N, 13)).
    ``lag`` (s): the rotors' thrust and drag torque follow the logged speed squared through a
    first-order lag of this time constant (integrated with the body, exact exponential per
    sub-step); 0: at once. ``effect`` (t_s, plant): from t_s seconds on, the plant runs with
    the parameter dict ``plant`` (a thrust loss, a payload, ...) while the controller keeps
    ``truth``."""
    rng = np.random.default_rng(seed)
    n = int(round(seconds / dt))
    t = np.arange(n) * dt
    # smooth reference: a few sinusoids per axis, random phases
    freqs = rng.uniform(0.1, 0.6, (3, 3))
    amps = np.array([[0.6], [0.6], [0.3]]) * rng.uniform(0.3, 1.0, (3, 3))
    phase = rng.uniform(0, 2 * np.pi, (3, 3))
    ref = np.stack([np.sum(amps[k][:, None] * np.sin(2 * np.pi * freqs[k][:, None] * t +
                                                      phase[k][:, None]), axis=0)
                    for k in range(3)], axis=1) + np.array([0.0, 0.0, 1.0])
    yaw_ref = 0.5 * np.sin(2 * np.pi * 0.15 * t)
    J = np.array(truth["J"])
    # torque excitation: low-passed white noise (random per sample, first order 0.1 s)
    exc = np.zeros((n, 3))
    e = np.zeros(3)
    for k in range(n):
        e = 0.9 * e + 0.1 * rng.standard_normal(3)
        exc[k] = e
    exc *= excite * np.array([2.0, 2.0, 1.0]) * J * 40.0
    s = np.zeros(18)
    s[0:3] = ref[0]
    act = None                 # the lagged squared speeds acting on the body
    s[6:15] = np.eye(3).ravel()
    U = np.zeros((n, 4))
    Y = np.zeros((n, 13))
    Yt = np.zeros((n, 13))
    q_prev = np.array([0.0, 0.0, 0.0, 1.0])
    h = dt / SUB
    for k in range(n):
        R = s[6:15].reshape(3, 3)
        q = quat_from_matrix(R)
        if np.dot(q, q_prev) < 0:
            q = -q
        q_prev = q
        Yt[k] = np.r_[s[0:6], q, s[15:18]]
        meas = Yt[k] + np.r_[rng.normal(0, noise["p"], 3), rng.normal(0, noise["v"], 3),
                             rng.normal(0, noise["q"], 4), rng.normal(0, noise["w"], 3)]
        meas[6:10] /= np.linalg.norm(meas[6:10])
        Y[k] = meas
        # controller on the measured state
        p_m, v_m, q_m, w_m = meas[0:3], meas[3:6], meas[6:10], meas[10:13]
        x, y, z, w = q_m
        Rm = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                       [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                       [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
        acc = 6.0 * (ref[k] - p_m) - 4.0 * v_m + np.array([0.0, 0.0, truth["g"]])
        T = truth["mass"] * np.dot(acc, Rm[:, 2])
        zb = acc / np.linalg.norm(acc)
        xc = np.array([np.cos(yaw_ref[k]), np.sin(yaw_ref[k]), 0.0])
        yb = np.cross(zb, xc)
        yb /= np.linalg.norm(yb)
        Rd = np.column_stack([np.cross(yb, zb), yb, zb])
        E = 0.5 * (Rd.T @ Rm - Rm.T @ Rd)
        eR = np.array([E[2, 1], E[0, 2], E[1, 0]])
        tau = J * (-120.0 * eR - 18.0 * w_m) + exc[k]
        om2 = np.clip(_mixer_inverse(T, tau, truth), 200.0 ** 2, 3000.0 ** 2)
        U[k] = np.sqrt(om2)
        # plant: RK4 sub-steps with the rotor speeds held (the lagged ones per sub-step)
        if act is None:
            act = om2.copy()
        plant = truth if effect is None or t[k] < effect[0] else effect[1]
        for _ in range(SUB):
            if lag > 0:
                act = om2 + (act - om2) * np.exp(-h / lag)
            else:
                act = om2
            k1 = _deriv(s, act, plant)
            k2 = _deriv(s + 0.5 * h * k1, act, plant)
            k3 = _deriv(s + 0.5 * h * k2, act, plant)
            k4 = _deriv(s + h * k3, act, plant)
            s = s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
            s[6:15] = _orthonormal(s[6:15].reshape(3, 3)).ravel()
    return U, Y, Yt
