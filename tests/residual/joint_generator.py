"""A flexible-joint and rigid-axis data generator independent of ``cdam_core.sim``.

Plain numpy with its own integrator (classical RK4 on a fine grid, the torque held over each
sample as a DAC holds it, or with ``hold=False`` a continuous open-loop torque that the record
samples at each instant, as a measured current would be), and conditions the project's simulator does not have: a joint in a
horizontal or a vertical plane, open-loop torque or a PD position loop closed on the *measured*
motor or link angle (so the torque is correlated with the measurement noise), coarse and noisy
encoders, sampling from 250 Hz to 1 kHz, a timing skew between the two encoders, motor-side dry
friction, a hardening cable and a periodic disturbance torque on the link.

Motor:  Im thm'' + Dm thm' + Fc tanh(thm' / v_s) + tau_l = tau_m
Cable:  tau_l = Ks d + K3 d^3 + Kd d',  d = thm - q
Link:   I q'' + Dl q' + Fcl tanh(q' / v_s) + G sin q = tau_l + A sin(2 pi f t) + w(t)

(w: an unmeasured link torque given per sample, ``link_torque``; Fcl: link-side dry friction.)
The angles are measured from encoder zeros that need not be the hanging position (``zero``)
nor each other's (``motor_zero``: the deflection read with an offset), the torque with an
offset (``tau_bias``, a current sensor's).

The dry friction uses a steep tanh (v_s = 1 mrad/s) so RK4 stays smooth; the identified model's
plain sign differs from it only below v_s.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import math

import numpy as np

TRUTH = {"Im": 0.02, "Dm": 0.05, "Ks": 40.0, "Kd": 0.05, "I": 0.1, "Dl": 0.1}


@dataclass
class Joint:
    fs: float = 1000.0              # sampling rate, Hz
    duration: float = 20.0          # s
    plane: str = "horizontal"       # "vertical": G = m g l acts on the link
    G: float = 0.6                  # N m, used in the vertical plane
    control: str = "open"           # "open", "motor" or "link" (PD on the measured angle)
    motor_counts: int = 0           # encoder counts per revolution (0: ideal)
    link_counts: int = 0
    motor_noise: float = 0.0        # rad, white, added after quantisation
    link_noise: float = 0.0
    skew: float = 0.0               # s, the link encoder is latched this much earlier
    Fc: float = 0.0                 # motor dry friction, N m
    K3: float = 0.0                 # hardening cable, N m / rad^3
    periodic: tuple = ()            # (amplitude N m, frequency Hz) on the link
    Fc_link: float = 0.0            # link-side dry friction, N m (steep tanh as the motor's)
    link_torque: tuple = ()         # an unmeasured torque on the link, N m per sample (held)
    zero: float = 0.0               # rad, the encoders' zero from the hanging position
    motor_zero: float = 0.0         # rad, the motor encoder's zero off the link encoder's
    tau_bias: float = 0.0           # N m, the torque measurement's offset (a current sensor's)
    substeps: int = 4
    hold: bool = True               # False (open loop only): a continuous torque, sampled
    # ("chirp", f1): a logarithmic sweep from 0.1 Hz to f1 Hz over the record plus a 0.23 Hz
    # sine of 0.3 its amplitude, scaled to unit standard deviation, in place of the multisine
    excitation: tuple = ()
    gains: tuple = ()               # (kp, kd) of the PD loop in place of the defaults
    seed: int = 0
    params: dict = field(default_factory=lambda: dict(TRUTH))

    def truth(self) -> dict:
        out = dict(self.params)
        out["G"] = self.G if self.plane == "vertical" else 0.0
        return out

    # -- the plant --------------------------------------------------------------------------
    def _deriv(self, x, u, t, extra=0.0):
        p = self.params
        thm, q, vm, vq = x
        d, dd = thm - q, vm - vq
        tl = p["Ks"] * d + self.K3 * d ** 3 + p["Kd"] * dd
        g = self.G if self.plane == "vertical" else 0.0
        dist = self.periodic[0] * math.sin(2 * math.pi * self.periodic[1] * t) \
            if self.periodic else 0.0
        am = (u - p["Dm"] * vm - self.Fc * math.tanh(vm / 1e-3) - tl) / p["Im"]
        aq = (tl - p["Dl"] * vq - self.Fc_link * math.tanh(vq / 1e-3) - g * math.sin(q) + dist
              + extra) / p["I"]
        return (vm, vq, am, aq)

    def _measure(self, x, counts, noise, rng):
        if counts:
            res = 2 * np.pi / counts
            x = np.round(x / res) * res
        return x + rng.normal(0.0, noise) if noise else x

    def record(self) -> dict:
        if not self.hold and self.control != "open":
            raise ValueError("hold=False: only an open-loop torque is continuous")
        rng = np.random.default_rng(self.seed)
        dt = 1.0 / self.fs
        n = int(round(self.duration * self.fs))
        t = np.arange(n) * dt
        # excitation: a multisine with random phases, 0.2..8 Hz (torque or angle reference)
        freqs = np.array([0.2, 0.45, 0.9, 1.7, 3.1, 5.3, 8.0])
        ph = rng.uniform(0, 2 * np.pi, freqs.size)
        ref = np.sum(np.sin(2 * np.pi * freqs[None, :] * t[:, None] + ph) / (1 + freqs), axis=1)
        if self.excitation:
            if self.excitation[0] != "chirp" or not self.hold:
                raise ValueError("excitation: only ('chirp', f1), with the torque held")
            f0, f1 = 0.1, float(self.excitation[1])
            rate = np.log(f1 / f0) / self.duration
            ref = (np.sin(2 * np.pi * f0 * np.expm1(rate * t) / rate)
                   + 0.3 * np.sin(2 * np.pi * 0.23 * t))
            ref = ref / np.std(ref)
        h = dt / self.substeps
        skew_steps = int(round(self.skew / h))
        hist_q = [0.0] * (skew_steps + 1)   # fine-grid link angles for the skewed latch
        x = [0.0, 0.0, 0.0, 0.0]
        tau = np.zeros(n)
        thm_m, q_m = np.zeros(n), np.zeros(n)
        prev = None
        for k in range(n):
            thm_m[k] = self._measure(x[0] - self.zero - self.motor_zero, self.motor_counts,
                                     self.motor_noise, rng)
            q_m[k] = self._measure(hist_q[0] - self.zero, self.link_counts, self.link_noise,
                                   rng)
            if self.control == "open":
                u = 0.6 * ref[k]
            else:
                y = thm_m[k] if self.control == "motor" else q_m[k]
                r = 0.5 * ref[k]
                vel = 0.0 if prev is None else (y - prev) / dt
                prev = y
                kp, kd = self.gains or ((2.0, 0.08) if self.control == "motor" else (1.0, 0.1))
                u = kp * (r - y) - kd * vel
                if self.plane == "vertical":
                    u += self.G * np.sin(r + self.zero)   # gravity feed-forward
            tau[k] = u + self.tau_bias
            for j in range(self.substeps):
                tk = k * dt + j * h
                if self.hold:
                    u0 = um = u1 = u
                else:   # the torque itself is continuous; the record samples it at t_k
                    u0, um, u1 = (0.6 * float(np.sum(np.sin(2 * np.pi * freqs * tt + ph)
                                                     / (1 + freqs)))
                                  for tt in (tk, tk + 0.5 * h, tk + h))
                w = float(self.link_torque[k]) if len(self.link_torque) else 0.0
                k1 = self._deriv(x, u0, tk, w)
                k2 = self._deriv([a + 0.5 * h * b for a, b in zip(x, k1)], um, tk + 0.5 * h, w)
                k3 = self._deriv([a + 0.5 * h * b for a, b in zip(x, k2)], um, tk + 0.5 * h, w)
                k4 = self._deriv([a + h * b for a, b in zip(x, k3)], u1, tk + h, w)
                x = [a + h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
                     for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4)]
                hist_q.append(x[1])
                hist_q.pop(0)
        return {"t": t, "tau_m": tau, "theta_m": thm_m, "q": q_m, "truth": self.truth()}


def _grid(fs, duration):
    """(dt, samples, times) of a record at ``fs`` Hz lasting ``duration`` s."""
    dt = 1.0 / fs
    n = int(round(duration * fs))
    return dt, n, np.arange(n) * dt


def _multisine(rng, t, freqs, amp, roll):
    """sum_i amp sin(2 pi f_i t + phase_i) / (1 + roll f_i), phases uniform from ``rng``."""
    freqs = np.array(freqs)
    ph = rng.uniform(0, 2 * np.pi, freqs.size)
    return np.sum(amp * np.sin(2 * np.pi * freqs[None, :] * t[:, None] + ph)
                  / (1 + roll * freqs), axis=1)


def _rk4_held(f, x, uk, h, sub):
    """``sub`` classical RK4 steps of ``h`` of x' = f(x, uk), the input held."""
    for _ in range(sub):
        k1 = f(x, uk)
        k2 = f(x + 0.5 * h * k1, uk)
        k3 = f(x + 0.5 * h * k2, uk)
        k4 = f(x + h * k3, uk)
        x = x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def rigid_axis(fs=1000.0, duration=20.0, M=0.5, Fv=2.0, Fc=1.0, offset=0.0, counts=0,
               noise=0.0, seed=0, bias=0.0, G=0.0, zero=0.0) -> dict:
    """A rigid axis M q'' + Fv q' + Fc tanh(q' / 1 mrad/s) + offset + G sin(q + zero) = tau,
    open-loop multisine torque (plus a constant ``bias``) held over each sample, RK4 on a fine
    grid. ``G``: a rotary axis in a vertical plane (a pendulum), its encoder's zero ``zero``
    rad from the hanging position (it starts hanging, at q = -zero)."""
    rng = np.random.default_rng(seed)
    dt, n, t = _grid(fs, duration)
    u = _multisine(rng, t, (0.3, 0.7, 1.3, 3.1, 6.0), 3.0, 1.0) + bias

    def f(x, uk):
        return np.array([x[1], (uk - offset - G * np.sin(x[0] + zero) - Fv * x[1]
                                - Fc * np.tanh(x[1] / 1e-3)) / M])
    x = np.array([-zero, 0.0])
    q = np.zeros(n)
    sub = 8
    h = dt / sub
    for k in range(n):
        q[k] = x[0]
        x = _rk4_held(f, x, u[k], h, sub)
    if counts:
        res = 2 * np.pi / counts
        q = np.round(q / res) * res
    if noise:
        q = q + rng.normal(0.0, noise, n)
    return {"t": t, "tau": u, "q": q,
            "truth": {"M": M, "Fv": Fv, "Fc": Fc, "offset": offset, "G": G, "zero": zero}}


def pd_pendulum(fs=500.0, duration=20.0, M=0.5, Fv=2.0, Fc=1.0, G=1.5, zero=0.3,
                counts=16384, seed=0, kp=40.0, kd=3.0) -> dict:
    """A rotary axis in a vertical plane, M q'' + Fv q' + Fc tanh(q' / 1 mrad/s) +
    G sin(q + zero) = tau, under PD control on its measured (quantised) angle tracking a
    multisine reference (0.2-4.7 Hz), the velocity by backward difference; the torque held over
    each sample, RK4 on a fine grid; it starts hanging (q = -zero)."""
    rng = np.random.default_rng(seed)
    dt, n, t = _grid(fs, duration)
    ref = _multisine(rng, t, (0.2, 0.5, 1.1, 2.3, 4.7), 0.25, 0.5)

    def f(x, uk):
        return np.array([x[1], (uk - G * np.sin(x[0] + zero) - Fv * x[1]
                                - Fc * np.tanh(x[1] / 1e-3)) / M])
    x = np.array([-zero, 0.0])
    q, tau = np.zeros(n), np.zeros(n)
    res = 2 * np.pi / counts
    sub = 8
    h = dt / sub
    for k in range(n):
        q[k] = np.round(x[0] / res) * res
        v = 0.0 if k == 0 else (q[k] - q[k - 1]) / dt
        tau[k] = kp * (ref[k] - q[k]) - kd * v
        x = _rk4_held(f, x, tau[k], h, sub)
    return {"t": t, "tau": tau, "q": q,
            "truth": {"M": M, "Fv": Fv, "Fc": Fc, "G": G, "zero": zero}}


def _main(argv=None) -> int:
    """Write one record as CSV (plain numpy) for the README's example; print the truth."""
    import argparse
    import json
    ap = argparse.ArgumentParser(description="independent flexible-joint record (plain numpy)",
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("out", help="CSV file to write (columns t, tau_m1, theta_m1, q1)")
    ap.add_argument("--fs", type=float, default=500.0, help="sampling rate, Hz")
    ap.add_argument("--plane", choices=("horizontal", "vertical"), default="vertical",
                    help="plane of motion (vertical: gravity on the link)")
    ap.add_argument("--control", choices=("open", "motor", "link"), default="motor",
                    help="open-loop torque, or a PD loop on the measured motor or link angle")
    ap.add_argument("--link-counts", type=int, default=4096, help="link encoder counts/rev")
    ap.add_argument("--motor-counts", type=int, default=16384, help="motor encoder counts/rev")
    ap.add_argument("--Fc", type=float, default=0.0, help="motor dry friction, N m")
    ap.add_argument("--seed", type=int, default=0, help="seed of the excitation and the noise")
    a = ap.parse_args(argv)
    j = Joint(fs=a.fs, plane=a.plane, control=a.control, link_counts=a.link_counts,
              motor_counts=a.motor_counts, link_noise=2e-4 if a.link_counts else 0.0,
              Fc=a.Fc, seed=a.seed)
    r = j.record()
    np.savetxt(a.out, np.column_stack([r["t"], r["tau_m"], r["theta_m"], r["q"]]),
               delimiter=",", header="t,tau_m1,theta_m1,q1", comments="", fmt="%.10g")
    truth = dict(r["truth"])
    if a.Fc:
        truth["Fc"] = a.Fc
    print(json.dumps(truth))
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
