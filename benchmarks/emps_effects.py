"""EMPS ([greybox] 19 item 8): effects prototyped in numpy on top of the loop's structures,
IDIM-LS on the loop's filtered columns (held timing, parallel filter), simulated by
semi-implicit Euler under the benchmark's protocol (20 samples of qm given): the mean over four
held-out blocks of DATA_EMPS (fitted on the other three) and DATA_EMPS_PULSES (fitted on all of
DATA_EMPS), in mm. "off": the published structure (Coulomb + offset); "asym": the loop's final
structure (Coulomb + asymmetric friction); "strib": Stribeck, sign(v) exp(-(v / vs)^2);
"poly": a cubic force in the position; "cog": a force periodic in the position (period lam);
with ``hold``: a stick-slip hold in the simulation (the velocity held at zero while the applied
force is inside the Coulomb level).
Run: python benchmarks/emps_effects.py (about ten minutes of CPU: a numpy loop per run)."""
import numpy as np
from cdam_core.residual.analyse import analyse
from cdam_core.record.realdata.emps import EMPS_UNITS, load_emps
from cdam_core.models.greybox.estimation import design
from cdam_core.models.greybox.registry import get_model
from cdam_core.models.greybox.effects import CoulombFriction
d0 = load_emps("DATA_EMPS")
sel = analyse("rigid_axis", d0["t"], {"tau": d0["force"], "q": d0["qm"]}, free_run=False,
              units=EMPS_UNITS)
sig = sel.declared.signals; trim = sel.settings["trim"]; dt = float(sig["dt"])
d, p = load_emps("DATA_EMPS"), load_emps("DATA_EMPS_PULSES")
N = len(d["qm"])
m0 = get_model("rigid_axis", {"G": 0.0, "Gc": 0.0})
s, eqs = design(m0, sig, (CoulombFriction("tau"),))
y, cols = eqs["tau"]
filt = m0.equation_filter("tau", s)
lp = lambda c: filt.lowpass(np.asarray(c, float)[:, None], dt)[:, 0]
q, v = np.asarray(s["q"]), np.asarray(s["q_d"])
qc = 0.5 * (d["qm"].max() + d["qm"].min()); qs = 0.5 * (d["qm"].max() - d["qm"].min())


def feats(q, v, which, par):
    """raw (unfiltered) feature columns of a structure, as functions of state."""
    out = {"M": None, "Fv": v, "Fc": np.sign(v)}
    if "off" in which: out["off"] = -np.ones_like(v)
    if "asym" in which:
        out["dFv"] = v * (v > 0); out["dFc"] = (v > 0).astype(float)
    if "strib" in which:
        out["Fs"] = np.sign(v) * np.exp(-(np.abs(v) / par["vs"]) ** 2)
    if "poly" in which:
        z = (q - qc) / qs
        out.update({"k1": z, "k2": z ** 2, "k3": z ** 3})
    if "cog" in which:
        out.update({"cs": np.sin(2 * np.pi * q / par["lam"]), "cc": np.cos(2 * np.pi * q / par["lam"])})
    return out

def fitls(which, par, mask):
    F = feats(q, v, which, par)
    X = [cols["M"]] + [lp(F[k]) for k in F if k != "M"]
    X = np.column_stack(X)
    r = np.zeros(N, bool); r[trim:N - trim] = True; r &= mask
    th = np.linalg.lstsq(X[r], np.asarray(y)[r], rcond=None)[0]
    return dict(zip(F, th))

def sim(th, which, par, u, Y, n0=20, hold=False):
    n = len(u); x = Y[n0 - 1]; vv = (Y[n0 - 1] - Y[n0 - 2]) / dt
    out = np.empty(n); out[:n0] = Y[:n0]
    M = th["M"]; names = [k for k in th if k != "M"]
    for k in range(n0 - 1, n - 1):
        F = feats(np.array([x]), np.array([vv]), which, par)
        f = u[k] - sum(th[nm] * F[nm][0] for nm in names)
        vn = vv + dt * f / M
        if hold and vv != 0 and np.sign(vn) != np.sign(vv):
            vn = 0.0
        if hold and vv == 0:
            # at rest: move only if the applied force exceeds the dry friction
            Fc = th["Fc"] + (th.get("dFc", 0.0) if False else 0.0)
            app = u[k] + th.get("off", 0.0) * 1.0
            if abs(app) <= Fc: vn = 0.0
            else: vn = dt * (app - np.sign(app) * Fc) / M
        vv = vn; x = x + dt * vv; out[k + 1] = x
    return 1000 * np.sqrt(np.mean((out[n0:] - Y[n0:]) ** 2))

def score(which, par, hold=False):
    edges = np.linspace(0, N, 5).astype(int); held = []
    for k in range(4):
        a, b = edges[k], edges[k + 1]
        mask = np.ones(N, bool); mask[max(0, a - trim):min(N, b + trim)] = False
        th = fitls(which, par, mask)
        held.append(sim(th, which, par, d["force"][a:b], d["qm"][a:b], hold=hold))
    th = fitls(which, par, np.ones(N, bool))
    pu = sim(th, which, par, p["force"], p["qm"], hold=hold)
    print(f"{'+'.join(which) or 'coul':22s} {par} hold={hold}: held {np.mean(held):6.2f} ({' '.join(f'{h:.2f}' for h in held)}) PULSES {pu:6.2f}  " + ", ".join(f"{k}={v:.3g}" for k, v in th.items()), flush=True)

CONFIGS = [(("off",), {}), (("asym",), {})] + [
    (w + (e,), par) for w in (("off",), ("asym",))
    for e, par in [("strib", {"vs": 0.005}), ("strib", {"vs": 0.01}), ("strib", {"vs": 0.02}),
                   ("strib", {"vs": 0.05}), ("poly", {}), ("cog", {"lam": 0.005}),
                   ("cog", {"lam": 0.01}), ("cog", {"lam": 0.02}), ("cog", {"lam": 0.05})]]
if __name__ == "__main__":
    for which, par in CONFIGS:
        score(which, par)
    for which, par in CONFIGS[:2]:
        score(which, par, hold=True)
