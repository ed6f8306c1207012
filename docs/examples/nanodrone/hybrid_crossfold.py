"""The physics + network flight model (kind quad_hybrid, trained by LM on the k-step error) on
the nano-drone benchmark's cross-trajectory protocol, beside the baselines.

    python docs/examples/nanodrone/hybrid_crossfold.py OUT_DIR [--types square,random1,...]

Per fold (``cdam_core.evaluate.crossfold.hybrid_fold``): the structure is chosen on the
validation flights of the training types (``HYBRID_GRID``), the chosen one retrained on all
training flights and scored on the test type at every horizon 1..50 beside naive, ARX(1), the
chosen ARX and the physics model (rates integrated and held). Prints the RMSE per group at
h = 1, 10, 25, 50 per fold and the mean over the folds, and where the hybrid is below naive,
the chosen ARX and the held-rates physics at every horizon; writes OUT_DIR/results.json.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from cdam_core.base.jsonio import write_json_atomic  # noqa: E402
from cdam_core.evaluate.crossfold import TYPES, hybrid_fold, mean_over_folds  # noqa: E402
from cdam_core.record.realdata.nanodrone import nanodrone_files  # noqa: E402
from cdam_core.report.horizons import group_table  # noqa: E402


def wins(scores, against=("naive", "arx", "physics_hold")) -> list[str]:
    """Per group: the horizons (of 1..50) where the hybrid's RMSE is below each of ``against``."""
    g = scores.group_rmse
    lines = []
    for j, group in enumerate(gr.name for gr in scores.groups):
        for other in against:
            below = g["hybrid"][:, j] < g[other][:, j]
            hs = [h for h, b in zip(scores.horizons, below) if b]
            lines.append(f"  {group:9s} below {other:12s} at {len(hs):2d}/50 horizons"
                         + (f" ({hs[0]}..{hs[-1]})" if hs else ""))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", help="output folder (created)")
    ap.add_argument("--types", default=",".join(TYPES))
    args = ap.parse_args(argv)
    files = nanodrone_files(None)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    loaded, folds, meta = {}, [], []
    for test_type in [t.strip() for t in args.types.split(",") if t.strip()]:
        t0 = time.perf_counter()
        r = hybrid_fold(files, test_type, loaded=loaded)
        f = r["fold"]
        folds.append(f)
        meta.append({k: v for k, v in r.items() if k != "fold"} | {"test_type": test_type})
        print(f"## Test type {test_type}: chosen {r['chosen']} (validation "
              f"{ {k: round(v, 4) for k, v in r['validation'].items()} }; final fit "
              f"{r['fit_seconds']:.1f} s; fold {time.perf_counter() - t0:.0f} s)")
        print(group_table(f.scores, at=[1, 10, 25, 50]))
        print("\n".join(wins(f.scores)) + "\n", flush=True)
    mean = mean_over_folds(folds)
    print(f"## Mean over the {len(folds)} folds")
    print(group_table(mean, at=[1, 10, 25, 50]))
    print("\n".join(wins(mean)))
    names = [g.name for g in mean.groups]
    write_json_atomic(out / "results.json", {
        "folds": [{**m, "group_rmse": {k: v.tolist() for k, v in f.scores.group_rmse.items()},
                   "group_mae": {k: v.tolist() for k, v in f.scores.group_mae.items()}}
                  for m, f in zip(meta, folds)],
        "mean": {"groups": names, "horizons": mean.horizons,
                 "group_rmse": {k: np.asarray(v).tolist() for k, v in mean.group_rmse.items()},
                 "group_mae": {k: np.asarray(v).tolist() for k, v in mean.group_mae.items()}}})
    print(f"results: {out / 'results.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
