"""Causal columns of ``arm_coupling``, computed row by row from increments (what a board can do).

The zero-phase columns (:meth:`~cdam_core.models.greybox.effects.ArmCoupling.columns`) filter
whole records forward and backward and take central differences: row t needs row t + 1 and
beyond. The causal form here needs only rows up to t, and is written in increments so that
float32 arithmetic does not amplify rounding.

Signals and filters. For each measured angle or position a (phi, theta, psi, X, Y, Z at the
body's derivative band, q1, q2 at the joints': the same cut-offs as the zero-phase columns,
derivative_ratio x the parallel filter's) the increments d[k] = a[k] - a[k-1] (psi's wrapped to
(-pi, pi]: a board receives psi wrapped) and d2[k] = d[k] - d[k-1] (d[0] = d2[0] = 0) go
through the Butterworth low-pass forward only (scipy.signal.sosfilt, started at rest):
p = LP(d), s = LP(d2), and c[k] = p[k-1]. Since the filter is linear and time invariant,
p is the first and s the second backward difference of LP(a) started at rest on a[0]; but the
filter only ever sees increments, so its state is as small as they are.

The jet. Each signal at row k is the jet (v, p, c, s): v = a[k-1] the measured value, p the
filtered increment to row k, c the one to row k-1, s = p - c the second difference (computed
by its own filter, never as p - c). It is the local trajectory (v - c, v, v + p). Sums, products,
sin and cos of jets are jets of that trajectory, each part computed without cancellation:

    (A B).p = Ap Bv + Av Bp + Ap Bp          (A B).c = Ac Bv + Av Bc - Ac Bc
    (A B).s = Av Bs + Bv As + Ap Bp + Ac Bc
    sin A: p = 2 cos(v + p/2) sin(p/2),      c = 2 cos(v - c/2) sin(c/2),
           s = -2 sin v (sin^2(p/2) + sin^2(c/2)) + 2 cos v cos((p + c)/2) sin(s/2)
    cos A: p = -2 sin(v + p/2) sin(p/2),     c = -2 sin(v - c/2) sin(c/2),
           s = -2 cos v (sin^2(p/2) + sin^2(c/2)) - 2 sin v cos((p + c)/2) sin(s/2)

(exact identities: sin(v+p) + sin(v-c) - 2 sin v = sin v (cos p + cos c - 2) + cos v (sin p -
sin c)). The value at row k is v + p, the rate at k is p / dt (at k-1: c / dt), the
acceleration s / dt^2. A force column, the second difference of w (products of sines and
cosines of the angles) over dt^2, is w's jet's s / dt^2: every term of s is of the size of
the result (increments squared, or s itself), so its float32 rounding is a few eps of the
column's own terms instead of eps |w| / dt^2 (1e6 |w| at 1 kHz) for w[k] - 2 w[k-1] + w[k-2]
computed from rounded w (see ``tests/models/test_arm_coupling_causal.py`` for the measured
bound: 6.6e-6 of each column's RMS in float32 against 3.2e-3 for the plain second
difference; the filters run in the output's increments, :func:`delta_sosfilt`, since scipy's
direct form II transposed in float32 alone errs by 6.7e-5 at 8 Hz and 1 kHz). The moment
columns use the same jets (values at row k, rates, accelerations, and the difference of a product of a cosine and a rate, Delta(C R) = C.p R_k + C.v (R_k - R_{k-1}) with
R_k - R_{k-1} from the s parts).

The board's firmware (fw/step_model.hpp, ``arm_coupling``) runs these formulas in float32 in
this order; this module is the float64 reference.
"""
from __future__ import annotations

import numpy as np
from scipy import signal as sps

__all__ = ["ARM_SIGNALS", "arm_sections", "arm_sos", "delta_sosfilt", "increments", "jets",
           "arm_columns", "COLUMN_NAMES"]

# the measured signals, in the order the firmware keeps them (angles, positions, joints)
ARM_SIGNALS = ("phi", "theta", "psi", "X", "Y", "Z", "q1", "q2")
BODY = ARM_SIGNALS[:6]
# columns per channel, in the order of ArmCoupling.columns (the parameters' suffixes)
COLUMN_NAMES = {"X": ("c0", "c1", "c2"), "Y": ("c0", "c1", "c2"), "Z": ("c0", "c1", "c2"),
                "tau_theta": ("c0", "c1", "c2", "dc1", "dc2", "p2", "I1", "I12"),
                "tau_phi": ("c0", "c1", "c2", "dc1", "dc2", "p2")}


def arm_sections(order: int, cutoff_hz: float, dt: float) -> np.ndarray:
    """The Butterworth low-pass of one band as the board holds it: per second-order section
    (b0, b1, b2, 1, alpha1, alpha2), float32 numbers, with alpha1 = a1 + 2 and alpha2 = 1 + a1
    + a2 (the denominator's distance from a double integrator: small numbers kept to float32's
    relative precision, where a1 near -2 and a2 near 1 would lose theirs; at 8 Hz and 1 kHz
    the poles lie within 0.05 of 1)."""
    fs = 1.0 / float(dt)
    if not 0 < cutoff_hz < 0.5 * fs:
        raise ValueError(f"cutoff_hz: {cutoff_hz:g} Hz is not below the Nyquist frequency "
                         f"{0.5 * fs:g} Hz")
    sos = sps.butter(int(order), float(cutoff_hz), fs=fs, output="sos")
    out = sos.copy()
    out[:, 4] = sos[:, 4] + 2.0
    out[:, 5] = (1.0 + sos[:, 4]) + sos[:, 5]
    return out.astype(np.float32).astype(np.float64)


def arm_sos(order: int, cutoff_hz: float, dt: float) -> np.ndarray:
    """The second-order sections (scipy's layout) of exactly the filter :func:`arm_sections`
    defines (a1 = alpha1 - 2, a2 = alpha2 - alpha1 + 1, exact in float64)."""
    sec = arm_sections(order, cutoff_hz, dt)
    sos = sec.copy()
    sos[:, 4] = sec[:, 4] - 2.0
    sos[:, 5] = (sec[:, 5] - sec[:, 4]) + 1.0
    return sos


def delta_sosfilt(sections: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The board's filter, in the input's precision (float32: the rounding tests), started
    at rest: per section N = (b0 x + b1 x1) + b2 x2, dy = ((dy1 - alpha1 dy1) - alpha2 y2) + N,
    y = y1 + dy, with y2 = y1 - dy1 (the same recursion as :func:`arm_sos`'s sections,
    y = -a1 y1 - a2 y2 + N, written in the output's increments)."""
    x = np.asarray(x)
    f = x.dtype.type
    c = sections.astype(x.dtype)
    y = x.copy()
    for q in range(c.shape[0]):
        b0, b1, b2, _, al1, al2 = c[q]
        out = np.empty_like(y)
        x1 = x2 = y1 = dy1 = f(0)
        for k, v in enumerate(y):
            n = (b0 * v + b1 * x1) + b2 * x2
            dy = ((dy1 - al1 * dy1) - al2 * (y1 - dy1)) + n
            y1 = y1 + dy
            dy1 = dy
            x2, x1 = x1, v
            out[k] = y1
        y = out
    return y


def increments(a, wrap: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(d, d2): first and second backward differences of a, zero at the start; ``wrap``: d
    wrapped to (-pi, pi] (an angle logged wrapped)."""
    a = _floats(a)
    d = np.zeros_like(a)
    d[1:] = a[1:] - a[:-1]
    if wrap:
        d = -((np.pi - d) % (2 * np.pi) - np.pi)
    d2 = np.zeros_like(a)
    d2[1:] = d[1:] - d[:-1]
    return d, d2


def _floats(a) -> np.ndarray:
    """float64, or float32 kept as it is (the board's arithmetic, for the rounding tests)."""
    a = np.asarray(a)
    return a if a.dtype == np.float32 else a.astype(np.float64)


class _Jet:
    __slots__ = ("v", "p", "c", "s")

    def __init__(self, v, p, c, s):
        self.v, self.p, self.c, self.s = v, p, c, s

    @property
    def now(self):
        return self.v + self.p

    def __add__(self, o):
        return _Jet(self.v + o.v, self.p + o.p, self.c + o.c, self.s + o.s)

    def __neg__(self):
        return _Jet(-self.v, -self.p, -self.c, -self.s)

    def __sub__(self, o):
        return self + (-o)

    def __mul__(self, o):
        return _Jet(self.v * o.v, (self.p * o.v + self.v * o.p) + self.p * o.p,
                    (self.c * o.v + self.v * o.c) - self.c * o.c,
                    ((self.v * o.s + o.v * self.s) + self.p * o.p) + self.c * o.c)


def _sincos(a: _Jet) -> tuple[_Jet, _Jet]:
    sv, cv = np.sin(a.v), np.cos(a.v)
    hp, hc = np.sin(0.5 * a.p), np.sin(0.5 * a.c)
    cp, cc = np.cos(0.5 * a.p), np.cos(0.5 * a.c)
    sq = hp * hp + hc * hc
    mid = np.cos(0.5 * (a.p + a.c)) * np.sin(0.5 * a.s)
    # sin(v + p/2) = sv cp + cv hp, cos(v + p/2) = cv cp - sv hp; (v - c/2) likewise
    sin = _Jet(sv, 2.0 * (cv * cp - sv * hp) * hp, 2.0 * (cv * cc + sv * hc) * hc,
               -2.0 * sv * sq + 2.0 * cv * mid)
    cos = _Jet(cv, -2.0 * (sv * cp + cv * hp) * hp, -2.0 * (sv * cc - cv * hc) * hc,
               -2.0 * cv * sq - 2.0 * sv * mid)
    return sin, cos


def jets(raw: dict, dt: float, body: np.ndarray, joint: np.ndarray) -> dict:
    """``{signal: jet}`` over a record: ``raw`` maps every name of ARM_SIGNALS to its measured
    samples (psi may be wrapped or unwrapped); ``body``, ``joint``: the bands'
    :func:`arm_sections`. float64 runs them through scipy's sosfilt (:func:`arm_sos`), float32
    the board's increment form (:func:`delta_sosfilt`)."""
    out = {}
    for name in ARM_SIGNALS:
        a = _floats(raw[name])
        d, d2 = increments(a, wrap=(name == "psi"))
        sec = body if name in BODY else joint
        if a.dtype == np.float32:
            p, s = delta_sosfilt(sec, d), delta_sosfilt(sec, d2)
        else:
            sos = sec.copy()
            sos[:, 4] = sec[:, 4] - 2.0
            sos[:, 5] = (sec[:, 5] - sec[:, 4]) + 1.0
            p, s = sps.sosfilt(sos, d), sps.sosfilt(sos, d2)
        c = np.concatenate([np.zeros(1, a.dtype), p[:-1]])
        v = np.concatenate([a[:1], a[:-1]])
        out[name] = _Jet(v, p, c, s)
    return out


def arm_columns(raw: dict, dt: float, body, joint, channels, g0: float) -> dict:
    """``{channel: {column name: samples}}`` (names of :data:`COLUMN_NAMES`) for each of
    ``channels``, from the measured signals ``raw`` (module doc); ``body``, ``joint``: the
    bands' :func:`arm_sections`."""
    J = jets(raw, dt, body, joint)
    sf, cf = _sincos(J["phi"])
    st, ct = _sincos(J["theta"])
    sp, cp = _sincos(J["psi"])
    q12 = J["q1"] + J["q2"]
    s1, c1 = _sincos(J["q1"])
    s12, c12 = _sincos(q12)
    _, c2 = _sincos(J["q2"])
    bx = (ct * cp, ct * sp, -st)
    by = (cp * st * sf - sp * cf, sp * st * sf + cp * cf, ct * sf)
    bz = (cf * st * cp + sf * sp, cf * st * sp - sf * cp, cf * ct)
    inv2 = 1.0 / (dt * dt)
    out = {}
    if any(ch in ("tau_phi", "tau_theta") for ch in channels):
        acc = (J["X"].s * inv2, J["Y"].s * inv2, J["Z"].s * inv2 + g0)

        def dot(b):
            return (b[0].now * acc[0] + b[1].now * acc[1]) + b[2].now * acc[2]

        ax, ay, az = dot(bx), dot(by), dot(bz)

    def d_cos_rate(C: _Jet, rate_p, rate_s):
        """Delta(C R) / dt with R_k = rate_p / dt, R_k - R_{k-1} = rate_s / dt."""
        return (C.p * rate_p + C.v * rate_s) * inv2

    th, p1, p2 = J["theta"], J["q1"], J["q2"]
    for ch in channels:
        if ch in ("X", "Y", "Z"):
            i = "XYZ".index(ch)
            w0 = -bz[i]
            w1 = -(s1 * bx[i]) - c1 * bz[i]
            w2 = -(s12 * bx[i]) - c12 * bz[i]
            out[ch] = {"c0": w0.s * inv2, "c1": w1.s * inv2, "c2": w2.s * inv2}
        elif ch == "tau_theta":
            out[ch] = {"c0": -ax,
                       "c1": -(c1.now * ax) + s1.now * az,
                       "c2": -(c12.now * ax) + s12.now * az,
                       "dc1": d_cos_rate(c1, 2.0 * th.p + p1.p, 2.0 * th.s + p1.s),
                       "dc2": d_cos_rate(c12, 2.0 * th.p + q12.p, 2.0 * th.s + q12.s),
                       "p2": d_cos_rate(c2, (2.0 * th.p + 2.0 * p1.p) + p2.p,
                                        (2.0 * th.s + 2.0 * p1.s) + p2.s),
                       "I1": p1.s * inv2, "I12": q12.s * inv2}
        elif ch == "tau_phi":
            ph = J["phi"]
            out[ch] = {"c0": ay, "c1": c1.now * ay, "c2": c12.now * ay,
                       "dc1": d_cos_rate(c1, ph.p, ph.s), "dc2": d_cos_rate(c12, ph.p, ph.s),
                       "p2": d_cos_rate(c2, ph.p, ph.s)}
        else:
            raise ValueError(f"channel: arm_coupling has no channel {ch!r}")
    return out
