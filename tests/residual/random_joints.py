"""Random flexible joints for a sweep beyond the tested conditions (plain numpy, independent of
``cdam_core``): each seed draws its own plant (inertias, a cable resonance between 6 and 40 Hz,
dampings, a vertical or horizontal plane), sampling (250, 500 or 1000 Hz), control (open-loop
torque, or a PD loop on the measured motor or link angle with gains scaled to the plant),
encoders (ideal, 4096 to 262144 counts, white noise after the quantisation), excitation (a
multisine, a logarithmic chirp or low-passed noise, up to a quarter to a half of the
resonance) and, on some seeds, motor dry friction (a tenth of the torque's spread). The torque
is held over each sample; classical RK4, four steps per sample. ``record(draw(seed))`` returns
``(record, amplitude, Fc)`` with the record ``None`` when the drawn loop is unstable.
``benchmarks/joint_sweep.py`` runs the analysis on them.

Motor:  Im thm'' + Dm thm' + Fc tanh(thm' / 1 mrad/s) + tau_l = tau_m
Cable:  tau_l = Ks (thm - q) + Kd (thm' - q')
Link:   I q'' + Dl q' + G sin q = tau_l
"""
import math

import numpy as np
from scipy.signal import butter, sosfilt


def logu(rng, a, b):
    return float(np.exp(rng.uniform(np.log(a), np.log(b))))


def draw(seed):
    rng = np.random.default_rng(1000 + seed)
    fs = float(rng.choice([250.0, 500.0, 1000.0]))
    Im = logu(rng, 0.005, 0.05)
    I = Im * logu(rng, 2.0, 20.0)
    fr = rng.uniform(6.0, min(40.0, fs / 8))
    w = 2 * np.pi * fr
    Ks = w * w / (1 / Im + 1 / I)
    zeta = logu(rng, 0.01, 0.1)
    Kd = 2 * zeta * Ks / w
    Dm = Im * logu(rng, 1.0, 5.0)
    Dl = I * logu(rng, 0.5, 3.0)
    plane = str(rng.choice(["horizontal", "vertical"]))
    G = I * logu(rng, 10.0, 50.0) if plane == "vertical" else 0.0
    control = str(rng.choice(["open", "motor", "link"]))
    excitation = str(rng.choice(["multisine", "chirp", "noise"]))
    mc = int(rng.choice([0, 16384, 65536]))
    lc = int(rng.choice([0, 4096, 16384, 262144]))
    ln = float(rng.choice([0.0, 1e-4, 3e-4]))
    Fc = float(rng.choice([0.0, 1.0])) * 1.0   # scaled later to the torque
    return dict(seed=seed, fs=fs, Im=Im, I=I, Ks=Ks, Kd=Kd, Dm=Dm, Dl=Dl, G=G, fr=fr,
                plane=plane, control=control, excitation=excitation, motor_counts=mc,
                link_counts=lc, link_noise=ln, Fc_flag=Fc, fc=rng.uniform(1.0, 3.0),
                fmax=rng.uniform(0.25, 0.5) * fr)


def reference(p, t, rng):
    fs = p["fs"]
    fmax = p["fmax"]
    if p["excitation"] == "multisine":
        f = np.sort(rng.uniform(0.1, fmax, 9))
        ph = rng.uniform(0, 2 * np.pi, f.size)
        r = np.sum(np.sin(2 * np.pi * f[None] * t[:, None] + ph) / (1 + f), axis=1)
    elif p["excitation"] == "chirp":
        f0, f1, T = 0.1, fmax, t[-1]
        k = (f1 / f0) ** (1 / T)
        r = np.sin(2 * np.pi * f0 * (k ** t - 1) / np.log(k)) + 0.3 * np.sin(2 * np.pi * 0.23 * t)
    else:
        e = rng.normal(size=t.size)
        sos = butter(2, fmax / (fs / 2), output="sos")
        r = sosfilt(sos, e)
    return r / np.std(r)


def simulate(p, amp, Fc, seed):
    rng = np.random.default_rng(seed)
    fs = p["fs"]
    dt = 1 / fs
    n = int(20 * fs)
    t = np.arange(n) * dt
    ref = reference(p, t, rng)
    sub = 4
    h = dt / sub
    Im, I, Ks, Kd, Dm, Dl, G = (p[k] for k in ("Im", "I", "Ks", "Kd", "Dm", "Dl", "G"))
    J = Im + I
    wc = 2 * np.pi * p["fc"]
    if p["control"] == "motor":
        kp, kd = J * wc * wc, 2 * 0.7 * J * wc
    else:
        wc = min(wc, 2 * np.pi * p["fr"] / 10) * p.get("gain_scale", 1.0)
        kp, kd = J * wc * wc, 2 * 0.7 * J * wc

    def f(x, u):
        thm, q, vm, vq = x
        tl = Ks * (thm - q) + Kd * (vm - vq)
        am = (u - Dm * vm - Fc * math.tanh(vm / 1e-3) - tl) / Im
        aq = (tl - Dl * vq - G * math.sin(q)) / I
        return np.array([vm, vq, am, aq])

    def meas(x, c, nz):
        if c:
            res = 2 * np.pi / c
            x = np.round(x / res) * res
        return x + (rng.normal(0, nz) if nz else 0.0)

    x = np.zeros(4)
    tau = np.zeros(n)
    tm, qm = np.zeros(n), np.zeros(n)
    prev = None
    for k in range(n):
        tm[k] = meas(x[0], p["motor_counts"], 0.0)
        qm[k] = meas(x[1], p["link_counts"], p["link_noise"])
        if p["control"] == "open":
            u = amp * ref[k]
        else:
            y = tm[k] if p["control"] == "motor" else qm[k]
            r = amp * ref[k]
            vel = 0.0 if prev is None else (y - prev) / dt
            prev = y
            u = kp * (r - y) - kd * vel + (G * math.sin(r) if G else 0.0)
        tau[k] = u
        for _ in range(sub):
            k1 = f(x, u)
            k2 = f(x + 0.5 * h * k1, u)
            k3 = f(x + 0.5 * h * k2, u)
            k4 = f(x + h * k3, u)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x)) or abs(x[1]) > 100:
            return None
    return {"t": t, "tau_m": tau, "theta_m": tm, "q": qm}


def record(p):
    # amplitude: the link's angle about 0.5 rad rms (a reference of 0.5 rad under control)
    if p["control"] == "open":
        r0 = simulate(p, 1.0, 0.0, p["seed"])
        if r0 is None:
            return None, 1.0, 0.0
        s = np.std(r0["q"] - np.polyval(np.polyfit(r0["t"], r0["q"], 1), r0["t"]))
        amp = 0.5 / s
    else:
        amp = 0.5
    Fc = 0.0
    if p["Fc_flag"]:
        r0 = simulate(p, amp, 0.0, p["seed"])
        if r0 is None:
            return None, amp, 0.0
        Fc = 0.1 * float(np.std(r0["tau_m"]))
    rec = simulate(p, amp, Fc, p["seed"])
    return rec, amp, Fc


def stable_record(seed):
    """(parameters, record, amplitude, Fc) of seed ``seed``; a link PD loop that the drawn
    gains make unstable is redrawn at half the gains (up to three times); record None if it
    stays unstable."""
    p = draw(seed)
    rec, amp, Fc = record(p)
    while rec is None and p.get("gain_scale", 1.0) > 0.2 and p["control"] == "link":
        p["gain_scale"] = p.get("gain_scale", 1.0) / 2
        rec, amp, Fc = record(p)
    return p, rec, amp, Fc
