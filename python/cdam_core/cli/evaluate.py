"""`cdam evaluate`: a saved model of any kind on one or more records, at every horizon."""
from __future__ import annotations

import sys
from pathlib import Path

from cdam_core.cli.common import CliError, check_io, write_json


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "evaluate", help="score a saved model (any kind) on records, one step to free run",
        description="Load a model file (bp_network, arx, hybrid, greybox), read each RECORD "
                    "(dataset CSV with the model's input and output columns; records are "
                    "separate segments, no prediction crosses a seam), and score the k-step "
                    "prediction at every horizon 1..H beside the naive predictor y(t-h), and "
                    "the free run.")
    p.add_argument("model", help="model file (cdam identify --save, cdam residual --save)")
    p.add_argument("records", nargs="+", help="dataset CSV files")
    p.add_argument("--horizon", type=int, default=1,
                   help="largest horizon H in samples (every h in 1..H up to 50, about 30 "
                        "log-spaced above)")
    p.add_argument("--no-free-run", action="store_true", help="skip the free run")
    p.add_argument("--json", default=None, help="write the scores as JSON")
    p.add_argument("--report", default=None, help="folder for index.md and the error plot")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def run(args) -> int:
    import numpy as np

    from cdam_core.evaluate.horizons import default_horizons, score_horizons
    from cdam_core.models.file import read_model_file
    from cdam_core.preprocess import smooth_pair
    from cdam_core.record.dataset import read_dataset

    check_io(inputs=[("MODEL", args.model)] + [("RECORD", r) for r in args.records],
             files=[("--json", args.json)], folders=[("--report", args.report)])
    horizons = default_horizons(args.horizon) if args.horizon >= 1 else None
    if horizons is None:
        raise CliError(f"--horizon: must be >= 1, got {args.horizon}")
    mf = read_model_file(args.model)
    Us, Ys, lengths, dts = [], [], [], []
    for path in args.records:
        ds = read_dataset(path, inputs=mf.inputs, outputs=mf.outputs)
        U, Y = ds.select(mf.inputs), ds.select(mf.outputs)
        U, Y = smooth_pair(U, Y, mf.smoothing_passes)   # as the model's training data
        Us.append(U)
        Ys.append(Y)
        lengths.append(len(Y))
        dts.append(float(np.median(np.diff(ds.t))))
    model_dt = getattr(mf.model, "dt", None)
    for path, dt in zip(args.records, dts):
        if model_dt is not None and abs(dt / model_dt - 1) > 0.01:
            raise CliError(f"{path}: sampled every {dt:g} s, the model every {model_dt:g} s")
    if max(lengths) <= horizons[-1] + max(mf.model.t0, 1):
        raise CliError(f"--horizon: {args.horizon} samples is longer than every record")
    horizons = [h for h in horizons if h + max(mf.model.t0, 1) < max(lengths)]

    def progress(i, n):
        if not args.quiet and sys.stderr.isatty():
            print(f"\rcdam evaluate: horizon {i}/{n}", end="" if i < n else "\n", file=sys.stderr)

    scores = score_horizons(mf.model, np.vstack(Us), np.vstack(Ys), mf.outputs, horizons,
                            segments=lengths, free_run=not args.no_free_run, progress=progress)
    js = {"model": {"path": str(args.model), "kind": mf.kind, "sha256": mf.sha256,
                    "inputs": mf.inputs, "outputs": mf.outputs},
          "records": [{"path": str(p), "samples": n} for p, n in zip(args.records, lengths)],
          "dt": dts[0], **scores.to_json()}
    if args.json:
        write_json(args.json, js)
    if args.report:
        from cdam_core.report.horizons import write_horizon_report
        write_horizon_report(scores, args.report, f"{Path(args.model).name} ({mf.kind})",
                             dt=dts[0])
    from cdam_core.report.horizons import horizon_table
    print(f"{mf.kind} model {args.model} on {len(lengths)} record(s), {sum(lengths)} samples")
    print(horizon_table(scores))
    for name, fr in scores.free_run.items():
        if "status" in fr:
            print(f"free run ({name}): {fr['status']}: {fr['reason']}")
        else:
            print(f"free run ({name}): " + ", ".join(
                f"{o} rmse {v['rmse']:.4g}" for o, v in fr.items()))
    return 0
