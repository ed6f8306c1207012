"""EMPS ([greybox] 19 item 8): each step of the residual loop and each estimator, scored on
DATA_EMPS's held-out blocks (BlockedCV, five folds: the windows and the free runs of the
blocks, in mm) and on DATA_EMPS_PULSES under the benchmark's protocol (mm).
Run: python benchmarks/emps_steps.py idim,oe,sim,iv (about a minute of CPU)."""
import sys, time, numpy as np
from cdam_core.residual.analyse import analyse
from cdam_core.record.realdata.emps import EMPS_UNITS, load_emps
from cdam_core.residual.benchmark import greybox_of
from cdam_core.evaluate.simulation import simulation_score
from cdam_core.models.greybox.estimation import fit
from cdam_core.models.greybox.registry import get_model
from cdam_core.models.greybox.effects import CoulombFriction, AsymmetricFriction
from cdam_core.residual.validation import BlockedCV
from cdam_core.residual.instrumental import iv_fit
d0 = load_emps("DATA_EMPS")
sel = analyse("rigid_axis", d0["t"], {"tau": d0["force"], "q": d0["qm"]}, free_run=False,
              units=EMPS_UNITS)
sig = sel.declared.signals; trim = sel.settings["trim"]
p = load_emps("DATA_EMPS_PULSES")
cv = BlockedCV(sel.declared.model, sig, trim, declared=sel.declared)
mm = lambda e: 1000 * np.sqrt(np.mean(e) * cv.norm[0])
C, A = CoulombFriction("tau"), AsymmetricFriction("tau")
S = {"declared (M, Fv, offset)": ((), get_model("rigid_axis", {"G": 0.0, "Gc": 0.0})),
     "+ Coulomb (published structure)": ((C,), get_model("rigid_axis", {"G": 0.0, "Gc": 0.0})),
     "+ Coulomb, offset 0": ((C,), get_model("rigid_axis", {"offset": 0.0, "G": 0.0, "Gc": 0.0})),
     "+ Coulomb + asymmetric, offset 0 (final)": ((C, A), get_model("rigid_axis", {"offset": 0.0, "G": 0.0, "Gc": 0.0}))}
for name, (eff, m) in S.items():
    for est in sys.argv[1].split(","):
        t0 = time.process_time()
        ew, _ = cv.scores(eff, m, est)
        eb, r = cv.scores(eff, m, est, True, True)
        f = fit(m, sig, eff, trim, bounded=True)
        g = greybox_of(f, cv.dt)
        U = cv.inputs(eff); every = np.ones(cv.Y.shape[0], bool)
        if est == "oe": cv.refine(g, f, U, every)
        elif est == "sim": cv.simulate_refine(g, f, U, every)
        elif est == "iv":
            f, _ = iv_fit(f, sig, U, cv.horizon, trim, integrator=cv.integrator); g = greybox_of(f, cv.dt)
        sp = simulation_score(g, p["force"][:, None], p["qm"][:, None], 20, 1000.0)
        print(f"{name:42s} {est:4s} held-out windows {mm(ew):6.3f} mm, block runs {mm(eb):6.2f} mm {r}; PULSES {sp.rmse[0]:6.2f} mm; "
              + ", ".join(f"{k.split('.')[-1]}={v:.2f}" for k, v in g.theta_.items()) + f"  cpu {time.process_time()-t0:.1f}", flush=True)
