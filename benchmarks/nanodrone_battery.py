"""Does thrust fall with the battery voltage, given the logged rotor speeds? (issue [flights]
item 4, the residual loop's actuation effects: the issue names it beside the rotors' reaction
torque and a motor lag, both measured in evaluate.crossfold and benchmarks/nanodrone_lag.py).
A measurement: `python benchmarks/nanodrone_battery.py [--json F]`, about 2 min on one core.

The effect: every rotor's force and torque coefficient scaled by (1 + c (V - V0)), V the
logged ``Vbat``, V0 the training flights' mean voltage (a centring, not a tuned value). It is
the quadratic map on rotor speeds w_i sqrt(1 + c (V - V0)), so ``QuadPhysics`` fitted and
scored on those speeds is the model with the effect. c (1/V) is estimated with its standard
deviation from the translational equation (``QuadPhysics._trans_system`` with the column
(V - V0) kT/m sum w_i^2 n beside kT/m's, ordinary least squares) on the fit flights of each
fold of the four-way cross-trajectory protocol (evaluate.crossfold's split: the last run of
each training type validates). The decision is the residual step's rule
(evaluate.crossfold.physics_effects_fold): the mean over h = 1, 10, 25, 50 and the four groups
of MAE over the naive predictor's MAE on the validation flights, with and without the effect,
both models fitted on the fit flights; the effect is supported in a fold if that score is
lower with it. Then c is re-estimated on all training flights and both models are scored on
the test type at every horizon (reported, never used to decide). Rates integrated
("dynamic") and held ("hold", the benchmark paper's physics model).

Measured (session 20, 17 flights, 2.5 min at load 2): V0 3.57-3.59 V, the training voltages
2.78-4.07 V. c on all training flights (1/V): square +0.0112 +- 0.0025, random1 -0.0015 +-
0.0048, random2 +0.0107 +- 0.0031, multisine +0.0216 +- 0.0031 (on the fit flights alone
+0.014, +0.027, +0.018, +0.021: random1's sign turns with one flight more). Validation score
without / with, rates integrated: every fold higher with it (random1 0.9654 / 0.9668); rates
held: square 0.5197 / 0.5201, random1 0.5688 / 0.5701, random2 0.5731 / 0.5740, multisine
0.5598 / 0.5595 (the one case lower, by 0.06 %). Mean over the folds on the test type, RMSE at
h = 50 without / with, rates held: position 0.1803 / 0.1804 m, velocity 1.0758 / 1.0756 m/s,
attitude 0.5709 / 0.5709 rad, rates 1.9283 / 1.9283 rad/s (integrated: 0.2405 / 0.2406,
1.5031 / 1.5031, 0.8595 / 0.8597, 3.1094 / 3.1102). Not supported: at the logged rotor speeds
the thrust does not depend on the battery (the voltage acts through the speed, which is
measured), and the small in-sample c is not stable across folds.
"""
import argparse
import time

import numpy as np
from group_rows import fold_means, print_groups, write_json

from cdam_core.evaluate.crossfold import TYPES, _split
from cdam_core.evaluate.groups import NANODRONE_GROUPS
from cdam_core.evaluate.horizons import score_horizons
from cdam_core.models.flight.physics import QuadPhysics, _ols
from cdam_core.record.realdata.nanodrone import nanodrone_files

SHOW = (1, 10, 25, 50)


def voltage(stack) -> np.ndarray:
    """``Vbat`` on every row of a stack (its records' rows as loaded)."""
    cols = [ds.column("Vbat") for ds in stack.datasets]
    return np.array([cols[r][i] for r, i in zip(stack.record, stack.row)], dtype=float)


def battery_coefficient(stack, V, V0, dt):
    """(c, sigma of c, kT/m) from the translational equation with the voltage column."""
    m = QuadPhysics(dt=dt, rates="hold", delay=None)
    m.fit(stack.U, stack.Y, segments=stack.lengths)
    d = m.delays_[0]
    dv, _, vm, n, _, t = m._equations(stack.Y, stack.pieces(), d + m._span())
    A, b = m._trans_system(stack.U, dv, vm, n, t, d)
    extra = (A[:, 0].reshape(-1, 3) * (V[t - d] - V0)[:, None]).ravel()
    th, sd, _ = _ols(np.column_stack([A, extra]), b)
    c = th[-1] / th[0]
    return float(c), float(abs(c) * np.hypot(sd[-1] / th[-1], sd[0] / th[0])), float(th[0])


def scaled(U, V, V0, c):
    """Rotor speeds with the voltage factor folded in (module doc); ValueError where the
    factor is not positive (a c outside the model's range on these voltages)."""
    k = 1.0 + c * (V - V0)
    if np.any(k <= 0):
        raise ValueError(f"c = {c:.3g} 1/V makes a thrust coefficient negative on this record")
    return U * np.sqrt(k)[:, None]


def score(m, U, st, groups, hs, first):
    return score_horizons(m, U, st.Y, st.outputs, hs, segments=st.lengths, free_run=False,
                          groups=groups, first=first)


def validation_score(sc) -> float:
    """The residual step's rule: mean over SHOW and groups of MAE / naive MAE."""
    rows = [h - 1 for h in SHOW]
    return float(np.mean(sc.group_mae["model"][rows] / sc.group_mae["naive"][rows]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None, help="write every figure here")
    args = ap.parse_args()
    files, loaded, out = nanodrone_files(), {}, {}
    groups, hs = list(NANODRONE_GROUPS), list(range(1, 51))
    names = [g.name for g in groups]
    for test_type in TYPES:
        t0 = time.time()
        _, _, (st_fit, st_val, st_train, st_test) = _split(files, test_type, loaded)
        dt = float(np.median(np.diff(st_train.t)))
        V = {k: voltage(s) for k, s in (("fit", st_fit), ("val", st_val), ("train", st_train),
                                         ("test", st_test))}
        V0 = float(np.mean(V["train"]))
        c_fit, sd_fit, _ = battery_coefficient(st_fit, V["fit"], V0, dt)
        c_tr, sd_tr, kt = battery_coefficient(st_train, V["train"], V0, dt)
        fold = {"V0": V0, "V_range_train": [float(V["train"].min()), float(V["train"].max())],
                "c_fit": c_fit, "c_fit_sigma": sd_fit, "c_train": c_tr, "c_train_sigma": sd_tr,
                "kT_over_m": kt}
        print(f"{test_type}: V0 {V0:.3f} V (training {V['train'].min():.2f}-"
              f"{V['train'].max():.2f}); c on the fit flights {c_fit:+.4f} +- {sd_fit:.4f} 1/V, "
              f"on all training {c_tr:+.4f} +- {sd_tr:.4f}", flush=True)
        for rates in ("dynamic", "hold"):
            mk = lambda: QuadPhysics(dt=dt, rates=rates)   # noqa: E731
            m0 = mk().fit(st_fit.U, st_fit.Y, segments=st_fit.lengths)
            m1 = mk().fit(scaled(st_fit.U, V["fit"], V0, c_fit), st_fit.Y,
                          segments=st_fit.lengths)
            first = max(m0.t0, m1.t0)
            v0 = validation_score(score(m0, st_val.U, st_val, groups, hs, first))
            v1 = validation_score(score(m1, scaled(st_val.U, V["val"], V0, c_fit), st_val,
                                        groups, hs, first))
            M0 = mk().fit(st_train.U, st_train.Y, segments=st_train.lengths)
            M1 = mk().fit(scaled(st_train.U, V["train"], V0, c_tr), st_train.Y,
                          segments=st_train.lengths)
            first = max(M0.t0, M1.t0)
            r0 = score(M0, st_test.U, st_test, groups, hs, first).group_rmse["model"]
            r1 = score(M1, scaled(st_test.U, V["test"], V0, c_tr), st_test, groups, hs,
                       first).group_rmse["model"]
            fold[rates] = {"validation_without": v0, "validation_with": v1,
                           "supported": bool(v1 < v0), "rmse_without": r0.tolist(),
                           "rmse_with": r1.tolist()}
            print(f"   {rates}: validation score without / with {v0:.4f} / {v1:.4f} -> "
                  + ("supported" if v1 < v0 else "not supported"))
            print_groups(names, r0, r1, SHOW, "without/with (test)", "      ")
        print(f"   ({time.time() - t0:.0f} s)", flush=True)
        out[test_type] = fold
    for rates in ("dynamic", "hold"):
        r0, r1 = fold_means(out, TYPES, rates, "rmse_without", "rmse_with")
        n = sum(out[k][rates]["supported"] for k in TYPES)
        print(f"mean over folds, {rates} (supported on validation in {n} of 4 folds):")
        print_groups(names, r0, r1, SHOW, "without/with")
    write_json(args.json, names, out)


if __name__ == "__main__":
    main()
