"""Why a linear model beats the physical one on EMPS under the protocol (issue [greybox] 19
item 8): experiments beside evaluate.lti_oe, all fitted by full simulation error on DATA_EMPS
and scored under the protocol (20 samples of qm given) on DATA_EMPS_PULSES.

(a) the order-2 transfer function with its integrator pinned at 1;
(b) the physical model M qdd = gtau vir - Fv qd - Fc sign(qd) + c (semi-implicit Euler at the
    record's step, state from the window's first two samples);
(c) (b) plus a first-order linear filter of vir added to qm (the grey-box's simulation residual
    modelled as a linear response to vir);
(d) (b) plus a position force k q (what the linear model's pole above 1 amounts to).
Run: python benchmarks/emps_lti_why.py
"""
import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from cdam_core.evaluate.lti_oe import Lti, score
from cdam_core.record.realdata.emps import load_emps

d, p = load_emps("DATA_EMPS"), load_emps("DATA_EMPS_PULSES")
DT = float(np.mean(np.diff(d["t"])))
GT = d["gtau"]


def Pinned_p(m):
    return np.roots(np.r_[1.0, m.theta[:2]]).real.min()


class Pinned(Lti):
    def __init__(self, th):
        a = np.convolve([1.0, -1.0], [1.0, -th[0]])
        super().__init__(np.r_[a[1:], th[1:4]], 2, False)


def fit_pinned(u, y):
    from cdam_core.evaluate.lti_oe import fit
    t = fit(2, False, [(u, y)])
    p0 = np.roots(np.r_[1, t[:2]]).real.min()

    def res(th):
        m = Pinned(th)
        return m.predict(u[:, None], y[:, None])[:, 0] - y
    return Pinned(least_squares(res, np.r_[p0, t[2:5]], x_scale="jac").x)


def phys(th, u, y0, y1):
    M, Fv, Fc, c = th[:4]
    kq = th[4] if len(th) == 5 else 0.0
    n = len(u)
    q = np.empty(n)
    q[0], q[1] = y0, y1
    v = (y1 - y0) / DT
    for k in range(1, n - 1):
        a = (GT * u[k] - Fv * v - Fc * np.sign(v) + c + kq * q[k]) / M
        v += DT * a
        q[k + 1] = q[k] + DT * v
    return q


class Phys:
    t0 = 20

    def __init__(self, th, filt):
        self.th, self.filt = th, filt

    def predict(self, U, Y, mode="free_run"):
        u, y = U[:, 0], Y[:, 0]
        extra = np.zeros_like(u)
        if self.filt is True:
            b, a = self.th[4:6], np.r_[1.0, self.th[6]]
            extra = lfilter(b, a, u)
        # the window's first two samples (minus the filter's part) start the integrator
        q = phys(self.th, u, y[0] - extra[0], y[1] - extra[1])
        return (q + extra)[:, None]


def fit_phys(u, y, filt):
    th0 = np.r_[95.0, 200.0, 20.0, 0.0]
    if filt is True:
        th0 = np.r_[fit_phys(u, y, False).th, 0.0, 0.0, -0.9]
    elif filt == "kq":
        th0 = np.r_[fit_phys(u, y, False).th, 10.0]

    def res(th):
        r = Phys(th, filt).predict(u[:, None], y[:, None])[:, 0] - y
        return r if np.all(np.isfinite(r)) else np.full_like(y, 1.0)
    return Phys(least_squares(res, th0, x_scale="jac", max_nfev=60 * len(th0)).x, filt)


if __name__ == "__main__":
    u, y = d["vir"], d["qm"]
    m = fit_pinned(u, y)
    print(f"(a) integrator pinned: poles 1, {Pinned_p(m):.5f}; "
          f"DATA_EMPS {score(m, u, y):.2f} mm, PULSES {score(m, p['vir'], p['qm']):.2f} mm")
    for lab, filt, what in (("b", False, ""), ("c", True, " + linear filter of vir"),
                            ("d", "kq", " + k q")):
        if lab != "d" and len(__import__("sys").argv) > 1:
            continue
        g = fit_phys(u, y, filt)
        print(f"({lab}) physical{what}: "
              f"params {np.round(g.th, 4)}; DATA_EMPS {score(g, u, y):.2f} mm, "
              f"PULSES {score(g, p['vir'], p['qm']):.2f} mm", flush=True)
