"""Why a linear model beats the physical one on EMPS under the protocol (issue [greybox] 19
item 8): experiments beside evaluate.lti_oe, all fitted by full simulation error on DATA_EMPS
and scored under the protocol (20 samples of qm given) on DATA_EMPS_PULSES.

(a) the order-2 transfer function with its integrator pinned at 1;
(b) the physical model M qdd = gtau vir - Fv qd - Fc sign(qd) + c (semi-implicit Euler at the
    record's step, state from the window's first two samples);
(c) (b) plus a first-order linear filter of vir added to qm (the grey-box's simulation residual
    modelled as a linear response to vir);
(d) (b) plus a position force k q (what the linear model's pole above 1 amounts to).
Fits by scipy's least_squares on central differences (session 18: forward differences
stopped early on these open-loop runs: (b) on all of DATA_EMPS cost 0.1087 against 0.0977,
PULSES 7.83 against 7.41 mm).
Run: python benchmarks/emps_lti_why.py (about a minute; with ``cv``: the held-out blocks,
about 3 min; with ``halves``: each half of DATA_EMPS as training set;
with ``forward``: the training window chosen by forward validation)
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
    return Pinned(least_squares(res, np.r_[p0, t[2:5]], x_scale="jac", jac="3-point").x)


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


def fit_phys(segments, filt):
    """Full simulation-error fit on segments [(u, y), ...]; for (c) and (d) from the fit of (b)
    with several starts of the added terms, the lowest training cost kept."""
    if filt is False:
        starts = [np.r_[95.0, 200.0, 20.0, 0.0]]
    else:
        base = fit_phys(segments, False).th
        starts = ([np.r_[base, 0.0, 0.0, -0.9], np.r_[base, 1e-3, -1e-3, -0.95]] if filt is True
                  else [np.r_[base, k] for k in (0.0, 10.0, 30.0)])

    def res(th):
        out = []
        for u, y in segments:
            r = Phys(th, filt).predict(u[:, None], y[:, None])[:, 0] - y
            out.append(r if np.all(np.isfinite(r)) else np.full_like(y, 1.0))
        return np.concatenate(out)
    best = None
    for th0 in starts:
        r = least_squares(res, th0, x_scale="jac", jac="3-point", max_nfev=60 * len(th0))
        if best is None or r.cost < best.cost:
            best = r
    return Phys(best.x, filt)


MODELS = (("b", False, ""), ("c", True, " + linear filter of vir"), ("d", "kq", " + k q"))


def held_out(n_blocks=4):
    """Each model fitted on three of four blocks of DATA_EMPS, scored on the fourth."""
    from cdam_core.evaluate.lti_oe import blocks
    u, y = d["vir"], d["qm"]
    for lab, filt, what in MODELS:
        vals = []
        for a, b in blocks(n_blocks, len(y)):
            train = [(u[s:e], y[s:e]) for s, e in ((0, a), (b, len(y))) if e - s > 100]
            vals.append(score(fit_phys(train, filt), u[a:b], y[a:b]))
        print(f"({lab}) physical{what}: held-out blocks " + " ".join(f"{v:6.2f}" for v in vals)
              + f"  mean {np.mean(vals):.2f} mm", flush=True)


def halves():
    """The order-2 transfer function and (b) fitted on each half of DATA_EMPS: the other half
    and DATA_EMPS_PULSES under the protocol."""
    from cdam_core.evaluate.lti_oe import fit
    u, y = d["vir"], d["qm"]
    h = len(y) // 2
    for (a, b), (c, e) in (((0, h), (h, len(y))), ((h, len(y)), (0, h))):
        tr = [(u[a:b], y[a:b])]
        for name, m in (("LTI order 2", Lti(fit(2, False, tr), 2, False)),
                        ("physical (b)", fit_phys(tr, False))):
            print(f"{name} fitted on DATA_EMPS[{a}:{b}]: other half {score(m, u[c:e], y[c:e]):.2f}"
                  f" mm, PULSES {score(m, p['vir'], p['qm']):.2f} mm", flush=True)


def forward():
    """Friction drifts over DATA_EMPS: forward validation (fit on the 1, 2 or all blocks before
    a block of four, score that block) picks the training window; then each window at the end
    of DATA_EMPS scored on PULSES."""
    from cdam_core.evaluate.lti_oe import blocks
    u, y = d["vir"], d["qm"]
    bl = blocks(4, len(y))
    for back in (1, 2, 3):
        vals = []
        for k in (2, 3):
            s, e = bl[k]
            a = bl[max(0, k - back)][0]
            vals.append(score(fit_phys([(u[a:s], y[a:s])], False), u[s:e], y[s:e]))
        print(f"forward validation, the last {back} block(s) before: "
              + " ".join(f"{v:.2f}" for v in vals) + f" mean {np.mean(vals):.2f} mm", flush=True)
    for back in (1, 2, 3, 4):
        a = bl[4 - back][0]
        g = fit_phys([(u[a:], y[a:])], False)
        print(f"fitted on DATA_EMPS[{a}:]: PULSES {score(g, p['vir'], p['qm']):.2f} mm, "
              f"params {np.round(g.th, 2)}", flush=True)


if __name__ == "__main__":
    import sys
    if sys.argv[1:] == ["forward"]:
        forward()
        sys.exit()
    if sys.argv[1:] == ["cv"]:
        held_out()
        sys.exit()
    if sys.argv[1:] == ["halves"]:
        halves()
        sys.exit()
    u, y = d["vir"], d["qm"]
    m = fit_pinned(u, y)
    print(f"(a) integrator pinned: poles 1, {Pinned_p(m):.5f}; "
          f"DATA_EMPS {score(m, u, y):.2f} mm, PULSES {score(m, p['vir'], p['qm']):.2f} mm")
    for lab, filt, what in MODELS:
        g = fit_phys([(u, y)], filt)
        print(f"({lab}) physical{what}: "
              f"params {np.round(g.th, 4)}; DATA_EMPS {score(g, u, y):.2f} mm, "
              f"PULSES {score(g, p['vir'], p['qm']):.2f} mm", flush=True)
