"""The nano-drone benchmark's multi-step protocol across trajectory types, with the baselines.

    python docs/examples/nanodrone/cross_trajectory.py OUT_DIR [--types square,random1,...]

Train on three trajectory types of the 17 flights in ../shared/data/nanodrone (or
$CDAM_SHARED_DATA/nanodrone), test on the fourth, all four ways
(``cdam_core.evaluate.crossfold``): the naive predictor (hold the state), a full-state ARX(1)
and a MIMO ARX with orders and delay chosen on the training flights only, scored with the
benchmark's metrics per group (RMSE and MAE, attitude as the quaternion geodesic angle) at
every horizon 1..50. Prints per group the RMSE and MAE at h = 1, 10, 25, 50 per fold and their
mean over the folds, beside the published table; writes OUT_DIR/results.json, OUT_DIR/index.md
and the error-against-horizon figures (mean over the folds) in OUT_DIR/mean/.
"""
import os

# the k-step rollouts multiply many small matrices: BLAS threads only contend for the cores
for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from cdam_core.base.jsonio import write_json_atomic, write_text_atomic  # noqa: E402
from cdam_core.evaluate.crossfold import (TYPES, cross_trajectory_fold,  # noqa: E402
                                          mean_over_folds)
from cdam_core.record.realdata.nanodrone import exclusion_report, nanodrone_files  # noqa: E402
from cdam_core.report.horizons import (group_table, published_table,  # noqa: E402
                                       write_horizon_report)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", help="output folder (created)")
    ap.add_argument("--types", default=",".join(TYPES),
                    help="test trajectory types, comma-separated (default: all four)")
    ap.add_argument("--data", default=None, help="folder of the flights (default: shared data)")
    args = ap.parse_args(argv)
    try:
        files = nanodrone_files(args.data)
    except FileNotFoundError as exc:
        # a plain clone: the flights are not in the repository (no licence file to ship them)
        print(f"cross_trajectory.py: error: the nano-drone flights are not in the repository "
              f"(no licence file), they live in a shared folder: {exc}; set CDAM_SHARED_DATA "
              f"to the folder holding nanodrone/ (or give --data)", file=sys.stderr)
        return 3
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    loaded, folds, md = {}, [], ["# Nano-drone flights: train on three trajectory types, test "
                                 "on the fourth", "",
                                 "Produced by `python docs/examples/nanodrone/cross_trajectory.py"
                                 " OUT_DIR`. Predictors: naive (hold the state), ARX(1) (full "
                                 "state, na = nb = nk = 1, least squares on all training "
                                 "flights), arx (orders and delay chosen on the training "
                                 "flights: the last run of each training type validates). "
                                 "Scored k-step from the measured state with the measured "
                                 "motor speeds, every horizon 1..50 (10 ms steps), on every "
                                 "flight of the test type; samples left out by the loader are "
                                 "listed at the end.", ""]
    for test_type in [t.strip() for t in args.types.split(",") if t.strip()]:
        t0 = time.perf_counter()
        f = cross_trajectory_fold(files, test_type, loaded=loaded)
        folds.append(f)
        head = (f"## Test type {test_type} ({len(f.test_files)} flights; chosen ARX orders "
                f"na, nb, nk = {', '.join(map(str, f.orders))}; "
                f"{time.perf_counter() - t0:.0f} s)")
        table = group_table(f.scores)
        print(head + "\n" + table + "\n", flush=True)
        md += [head, "", table, ""]
    mean = mean_over_folds(folds)
    table = group_table(mean)
    print(f"## Mean over the {len(folds)} folds\n{table}\n")
    write_horizon_report(mean, out / "mean", "Mean over the folds", dt=0.01)
    arx1 = ["| test type | position [m] | velocity [m/s] | attitude [rad] | rates [rad/s] |",
            "|---|---|---|---|---|"]
    for f in folds:
        r = f.scores.group_rmse["arx1"][f.scores.horizons.index(50)]
        arx1.append(f"| {f.test_type} | " + " | ".join(f"{v:.3f}" for v in r) + " |")
    print("ARX(1) full state, RMSE per group at h = 50, per fold:\n" + "\n".join(arx1) + "\n")
    print(published_table())
    md += [f"## Mean over the {len(folds)} folds", "", table, "",
           "![MAE per group against horizon](mean/group_mae_vs_horizon.png)", "",
           "*Figure: MAE per group against the horizon, mean over the folds, for the naive "
           "predictor, ARX(1) and the chosen ARX.*", "",
           "## ARX(1), RMSE per group at h = 50, per fold", "", *arx1, "",
           "## Published", "", published_table(), "",
           "## Samples left out by the loader", "", "```",
           exclusion_report(sorted(loaded)), "```", ""]
    write_text_atomic(out / "index.md", "\n".join(md))
    def groups_only(js):   # per output at every horizon is in to_json(); kept out here
        return {k: v for k, v in js.items() if k not in ("rmse", "mae")}
    write_json_atomic(out / "results.json", {"folds": [groups_only(f.to_json()) for f in folds],
                                             "mean": groups_only(mean.to_json())})
    print(f"report: {out / 'index.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
