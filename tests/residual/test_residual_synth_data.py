"""Synthetic records with known parameters and hidden effects for the residual tests.

Written independently of cdam_core.residual: a fixed-step RK4 integrator (one step per 1 ms
sample, control and disturbances held over the step), PD position control tracking a seeded
multisine, noise on the measured positions and a random process force. The simulator of issue 3
replaces these later; the tests here check the generator itself.
"""
import numpy as np
import pytest

DT = 1e-3
RIGID = {"M": 2.0, "Fv": 5.0, "offset": 0.5}
FLEX = {"Im": 0.02, "Dm": 0.05, "Ks": 20.0, "Kd": 0.2, "I": 0.05, "Dl": 0.02, "G": 0.8}
NOISE = {"q": 5e-6, "force": 0.05}   # default noise: position std (m or rad), process force std


def _reference(rng, t, amp, freqs):
    ph = rng.uniform(0, 2 * np.pi, len(freqs))
    r = sum(amp * np.sin(2 * np.pi * f * t + p) for f, p in zip(freqs, ph))
    rd = sum(amp * 2 * np.pi * f * np.cos(2 * np.pi * f * t + p) for f, p in zip(freqs, ph))
    return r, rd


def _rk4(f, x, h):
    k1 = f(x)
    k2 = f(x + 0.5 * h * k1)
    k3 = f(x + 0.5 * h * k2)
    k4 = f(x + h * k3)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def rigid_axis_record(seed=1, noise=1.0, duration=10.0, Fc=0.0, dFv_pos=0.0, delay=0.0,
                      ext_gain=0.0, periodic=None):
    """PD-controlled rigid axis M q'' + Fv q' + offset (+ effects) = tau_applied + disturbances.

    Effects: Coulomb Fc sign(v); extra viscous dFv_pos for v > 0; command delay (s);
    a measured external force (returned as ``ext``) acting with gain ``ext_gain``; an unmeasured
    periodic force ``periodic = (amplitude N, frequency Hz)``.
    """
    rng = np.random.default_rng(seed)
    n = int(round(duration / DT)) + 1
    t = np.arange(n) * DT
    r, rd = _reference(rng, t, 0.04, [0.3, 0.7, 1.3, 2.1, 3.4])
    ext = np.convolve(rng.normal(0, 3.0, n), np.ones(100) / 100 ** 0.5, mode="same") * 0.3
    w = rng.normal(0, NOISE["force"] * noise, n)
    qn = rng.normal(0, NOISE["q"] * noise, n)
    nd = int(round(delay / DT))
    x = np.zeros(2)
    q = np.empty(n)
    tau = np.empty(n)
    M, Fv, off = RIGID["M"], RIGID["Fv"], RIGID["offset"]
    for k in range(n):
        q[k] = x[0] + qn[k]
        tau[k] = 400.0 * (r[k] - q[k]) + 40.0 * (rd[k] - x[1])
        u = tau[k - nd] if k >= nd else 0.0
        dist = w[k] + ext_gain * ext[k]
        if periodic:
            dist += periodic[0] * np.sin(2 * np.pi * periodic[1] * t[k])

        def f(s):
            v = s[1]
            fr = Fv * v + off + Fc * np.sign(v) + (dFv_pos * v if v > 0 else 0.0)
            return np.array([v, (u + dist - fr) / M])
        x = _rk4(f, x, DT)
    return {"t": t, "tau": tau, "q": q, "ext": ext}


def flexible_joint_record(seed=1, noise=1.0, duration=6.0, K3=0.0, backlash=0.0, Fc_link=0.0):
    """PD on the motor angle of one cable-driven joint, PAPER.md (3)-(5), hanging link.

    Effects: cubic cable spring K3 d^3, cable dead band of total width ``backlash`` (rad),
    Coulomb friction on the link.
    """
    rng = np.random.default_rng(seed)
    n = int(round(duration / DT)) + 1
    t = np.arange(n) * DT
    r, rd = _reference(rng, t, 0.25, [0.2, 0.5, 0.9, 1.7, 2.6])
    w = rng.normal(0, NOISE["force"] * 0.02 * noise, n)
    qn = rng.normal(0, NOISE["q"] * noise, (n, 2))
    p = FLEX
    x = np.zeros(4)   # thm, thm', q, q'
    thm = np.empty(n)
    q = np.empty(n)
    tau = np.empty(n)
    for k in range(n):
        thm[k], q[k] = x[0] + qn[k, 0], x[2] + qn[k, 1]
        tau[k] = 2.0 * (r[k] - thm[k]) + 0.2 * (rd[k] - x[1])
        u = tau[k] + w[k]

        def f(s):
            d = s[0] - s[2]
            if backlash > 0:
                d = np.sign(d) * max(abs(d) - backlash / 2, 0.0)
            tl = p["Ks"] * d + K3 * (s[0] - s[2]) ** 3 + p["Kd"] * (s[1] - s[3])
            a_m = (u - p["Dm"] * s[1] - tl) / p["Im"]
            a_l = (tl - p["Dl"] * s[3] - p["G"] * np.sin(s[2]) - Fc_link * np.sign(s[3])) / p["I"]
            return np.array([s[1], a_m, s[3], a_l])
        x = _rk4(f, x, DT)
    return {"t": t, "tau_m": tau, "theta_m": thm, "q": q}


def test_rk4_matches_closed_form_oscillator():
    # x'' = -w^2 x: RK4 at 1 ms must match cos(w t) to 1e-9 over 2 s
    w = 2 * np.pi * 3
    x = np.array([1.0, 0.0])
    for _ in range(2000):
        x = _rk4(lambda s: np.array([s[1], -w ** 2 * s[0]]), x, DT)
    assert x[0] == pytest.approx(np.cos(w * 2.0), abs=1e-9)


def test_rigid_record_is_seeded_and_tracks_reference():
    a = rigid_axis_record(seed=3, duration=2.0)
    b = rigid_axis_record(seed=3, duration=2.0)
    c = rigid_axis_record(seed=4, duration=2.0)
    assert np.array_equal(a["q"], b["q"]) and not np.array_equal(a["q"], c["q"])
    assert np.all(np.abs(a["q"]) < 0.5)
