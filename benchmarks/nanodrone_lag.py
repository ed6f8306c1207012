"""Does a first-order actuation lag chosen from the training flights give the physics flight
model a multi-step gain on a held-out trajectory type? (issue [flights] item 4, the residual
loop's actuation effects). A measurement: `python benchmarks/nanodrone_lag.py [--json F]`.

On the 17 nano-drone flights, the four-way cross-trajectory protocol (train on three types,
test on the fourth; evaluate.crossfold's split): ``QuadPhysics`` with the rates integrated
("dynamic") and held ("hold", the benchmark paper's physics model), each fitted on all
training flights with lag 0 and with ``lag=None`` (the lag chosen on held-out time blocks of
the training flights among 0..50 ms, models.flight.physics), scored k-step on every test
flight at h = 1..50 on the same rows. Printed per fold: the chosen lag and delays, and per
group RMSE at h = 1, 10, 25, 50 without / with the lag, and at how many of the 50 horizons
the lag is lower; then the mean over the folds. About 3 min on one core.

Measured (session 8): chosen lags, rates integrated / held: square 10 / 0 ms, random1 0 / 10,
random2 10 / 20, multisine 0 / 20; the held-out score gaps between the candidates 0.00-0.03 in
a log sum of six RMS errors. Mean over the folds, group RMSE at h = 1, 10, 25, 50 without /
with the lag:
  integrated: position 0.0082/0.0082 0.0198/0.0198 0.0469/0.0465 0.2408/0.2408 (lower 50/50)
              velocity 0.0271/0.0271 0.0707/0.0690 0.2468/0.2461 1.5046/1.5059 (32/50)
              attitude 0.0060/0.0060 0.0514/0.0516 0.2603/0.2615 0.8602/0.8642 (2/50)
              rates    0.1705/0.1703 0.9602/0.9646 1.9325/1.9430 3.1128/3.1297 (1/50)
  held:       position 0.0082/0.0082 0.0197/0.0197 0.0424/0.0424 0.1805/0.1804 (39/50)
              velocity 0.0271/0.0271 0.0696/0.0698 0.2054/0.2054 1.0766/1.0757 (26/50)
              attitude 0.0060/0.0060 0.0448/0.0448 0.2083/0.2083 0.5712/0.5712 (14/50)
              rates    0.1742/0.1742 0.8743/0.8743 1.5308/1.5308 1.9314/1.9314 (12/50)
No multi-step gain worth the name: under 1 % at h = 50 on every group, worse on attitude and
rates with the rates integrated. The lag is not supported on these flights.

``--fixed``: stated lags 0, 20, 50, 100, 200 ms scored on the test type (a look at the test
data, never a choice; about 5 min). Mean over the folds, RMSE ratio to lag 0 at h = 50
(position, velocity, attitude, rates): integrated 20 ms 0.975 0.973 0.973 0.970, 50 ms 0.905
0.884 0.881 0.866, 100 ms 0.858 0.815 0.816 0.791, 200 ms 0.819 0.749 0.750 0.715 (velocity at
h = 10: 0.95, 0.98, 1.16, 1.41); held 20 ms 0.989 0.990 1 1, 50 ms 0.977 0.973, 100 ms 0.977
0.955 (velocity at h = 10 1.17), 200 ms 0.997 0.947 (h = 10 1.43). The long lags help the
integrated rates at h = 50 on random1, random2, multisine (on square they raise the attitude
and rate errors) by slowing the open-loop torque response toward holding the rates, not as a
motor's lag: 100-200 ms is 3-10 times a micro brushless motor's time constant, velocity at h = 10 gets worse, and with them the
integrated model's attitude error at h = 50 (mean 0.655 rad at 200 ms) stays above holding the
rates (0.580) -- the finding of the residual step in evaluate.crossfold.
"""
import argparse
import time

import numpy as np
from group_rows import fold_means, print_groups, write_json

from cdam_core.evaluate.crossfold import TYPES, _split
from cdam_core.evaluate.groups import NANODRONE_GROUPS
from cdam_core.evaluate.horizons import score_horizons
from cdam_core.models.flight.physics import QuadPhysics
from cdam_core.record.realdata.nanodrone import nanodrone_files

SHOW = (1, 10, 25, 50)


FIXED = (0.0, 0.02, 0.05, 0.1, 0.2)


def fixed():
    """Stated lags on the test type (module doc): RMSE per fold, then the mean ratio to lag 0."""
    files, loaded, res = nanodrone_files(), {}, {}
    groups, hs = list(NANODRONE_GROUPS), list(SHOW)
    for test_type in TYPES:
        _, _, (_, _, st_train, st_test) = _split(files, test_type, loaded)
        dt = float(np.median(np.diff(st_train.t)))
        for rates in ("dynamic", "hold"):
            ms = {T: QuadPhysics(dt=dt, rates=rates, lag=T).fit(st_train.U, st_train.Y,
                                                              segments=st_train.lengths)
                  for T in FIXED}
            first = max(m.t0 for m in ms.values())
            for T, m in ms.items():
                sc = score_horizons(m, st_test.U, st_test.Y, st_test.outputs, hs,
                                    segments=st_test.lengths, free_run=False, groups=groups,
                                    first=first)
                res[(test_type, rates, T)] = sc.group_rmse["model"]
                print(test_type, rates, f"{1000 * T:.0f} ms", m.delays_,
                      np.round(sc.group_rmse["model"], 4).tolist(), flush=True)
    for rates in ("dynamic", "hold"):
        base = np.mean([res[(k, rates, 0.0)] for k in TYPES], axis=0)
        for T in FIXED[1:]:
            r = np.mean([res[(k, rates, T)] for k in TYPES], axis=0)
            print(f"mean {rates} {1000 * T:.0f} ms: RMSE / lag 0 at h = {SHOW} (rows; groups "
                  f"as columns)", np.round(r / base, 3).tolist())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", default=None)
    ap.add_argument("--fixed", action="store_true", help="score stated lags on the test type")
    args = ap.parse_args()
    if args.fixed:
        return fixed()
    files, loaded, out = nanodrone_files(), {}, {}
    groups, hs = list(NANODRONE_GROUPS), list(range(1, 51))
    names = [g.name for g in groups]
    for test_type in TYPES:
        t = time.time()
        _, _, (_, _, st_train, st_test) = _split(files, test_type, loaded)
        dt = float(np.median(np.diff(st_train.t)))
        models = {}
        for rates in ("dynamic", "hold"):
            for lag in (0.0, None):
                models[(rates, lag)] = QuadPhysics(dt=dt, rates=rates, lag=lag).fit(
                    st_train.U, st_train.Y, segments=st_train.lengths)
        first = max(m.t0 for m in models.values())
        sc = {k: score_horizons(m, st_test.U, st_test.Y, st_test.outputs, hs,
                                segments=st_test.lengths, free_run=False, groups=groups,
                                first=first) for k, m in models.items()}
        fold = {}
        for rates in ("dynamic", "hold"):
            m = models[(rates, None)]
            r0 = sc[(rates, 0.0)].group_rmse["model"]
            r1 = sc[(rates, None)].group_rmse["model"]
            a0 = sc[(rates, 0.0)].group_mae["model"]
            a1 = sc[(rates, None)].group_mae["model"]
            fold[rates] = {"lag": m.lag_, "lag_fit": {str(k): v for k, v in m.lag_fit_.items()},
                           "delays": list(m.delays_), "delays_lag0": list(models[(rates, 0.0)].delays_),
                           "rmse_lag0": r0.tolist(), "rmse_lag": r1.tolist(),
                           "mae_lag0": a0.tolist(), "mae_lag": a1.tolist(),
                           "naive_rmse": sc[(rates, 0.0)].group_rmse["naive"].tolist()}
            print(f"{test_type} {rates}: lag {1000 * m.lag_:.0f} ms (delays {m.delays_}, "
                  f"lag 0: {models[(rates, 0.0)].delays_}); held-out scores "
                  + " ".join(f"{1000 * k:.0f}:{v:.2f}" for k, v in m.lag_fit_.items()))
            print_groups(names, r0, r1, SHOW, "lag0/lag")
        print(f"   ({time.time() - t:.0f} s)", flush=True)
        out[test_type] = fold
    for rates in ("dynamic", "hold"):
        r0, r1 = fold_means(out, TYPES, rates, "rmse_lag0", "rmse_lag")
        print(f"mean over folds, {rates}:")
        print_groups(names, r0, r1, SHOW, "lag0/lag")
    write_json(args.json, names, out)


if __name__ == "__main__":
    main()
