"""`cdam evaluate`: a saved model of any kind on one or more records, at every horizon."""
from __future__ import annotations

import sys
from pathlib import Path

from cdam_core.cli.common import (CliError, add_validation_option, check_io, validation_rule,
                                  write_json)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "evaluate", help="score a saved model (any kind) on records, one step to free run",
        description="Load a model file (bp_network, arx, hybrid, greybox), read each RECORD "
                    "(dataset CSV or Parquet with the model's input and output columns, or "
                    "mapped to them with --map; records, and the segments of a record, are "
                    "separate: no prediction crosses a seam), and score the k-step "
                    "prediction at every horizon 1..H beside the naive predictor y(t-h), and "
                    "the free run. With --groups (default: the nano-drone benchmark's groups "
                    "when the outputs are its 13 states) also the benchmark's MAE per group "
                    "(mean Euclidean norm, attitude as the quaternion geodesic angle; its sum "
                    "over h = 1..50) and RMSE per group.")
    p.add_argument("model", help="model file (cdam identify --save, cdam residual --save)")
    p.add_argument("records", nargs="+", help="dataset files (.csv or .parquet)")
    p.add_argument("--map", default=None,
                   help="model names to record columns: name=column[*factor],... or a JSON "
                        "file of the same pairs (e.g. w1=m1_erpm*0.0174533)")
    p.add_argument("--nan", default="error", choices=["error", "split"],
                   help="a missing value is an error, or its row is left out and the record "
                        "cut there (default: error)")
    p.add_argument("--loader", default="dataset", choices=["dataset", "nanodrone"],
                   help="nanodrone: the nano-drone benchmark's Parquet flights (motor speeds "
                        "in rad/s, 13 states, takeoff/landing/gaps/diverging estimate left "
                        "out; see record.realdata.nanodrone)")
    p.add_argument("--groups", default=None,
                   help="output groups scored together, e.g. 'position=x,y,z;"
                        "attitude=quat:qx,qy,qz,qw' ('none' to skip)")
    p.add_argument("--predictions", default=None,
                   help="write every k-step prediction to this Parquet file (long format: "
                        "record, start row, start time, horizon, predicted outputs)")
    p.add_argument("--baselines", nargs="+", default=None, metavar="TRAIN",
                   help="also fit the ARX baseline on these training records (orders and delay "
                        "chosen on the validation records --validation picks among them, then "
                        "refitted on all) and score it beside the model and the naive "
                        "predictor, on the same rows")
    add_validation_option(p, "--baselines records validate the ARX orders")
    p.add_argument("--horizon", type=int, default=1,
                   help="largest horizon H in samples (every h in 1..H up to 50, about 30 "
                        "log-spaced above)")
    p.add_argument("--no-free-run", action="store_true", help="skip the free run")
    p.add_argument("--json", default=None, help="write the scores as JSON")
    p.add_argument("--report", default=None, help="folder for index.md and the error plot")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def _check_physical_units(mf, st, paths) -> None:
    """A grey-box model (physical parameters) checks the declared units of the columns that
    feed its signals (``GreyBoxModel.check_units``): no normalised command, no other unit."""
    if getattr(mf.model, "kind", None) != "greybox":
        return
    gm = mf.model.declared_model
    signals = list(gm.inputs) + list(gm.positions)
    columns = list(mf.inputs[:len(gm.inputs)]) + list(mf.outputs)
    for ds, path in zip(st.datasets, paths):
        units = ds.units
        gm.check_units({s: (c, units.get(c)) for s, c in zip(signals, columns)}, str(path))


def run(args) -> int:
    import numpy as np

    from cdam_core.evaluate.groups import NANODRONE_GROUPS, parse_groups
    from cdam_core.evaluate.horizons import default_horizons, score_horizons
    from cdam_core.models.file import read_model_file
    from cdam_core.record.columns import parse_column_map
    from cdam_core.record.stack import stack_records

    check_io(inputs=[("MODEL", args.model)] + [("RECORD", r) for r in args.records] +
             [("--baselines", r) for r in args.baselines or []],
             files=[("--json", args.json), ("--predictions", args.predictions)],
             folders=[("--report", args.report)])
    horizons = default_horizons(args.horizon) if args.horizon >= 1 else None
    if horizons is None:
        raise CliError(f"--horizon: must be >= 1, got {args.horizon}")
    if args.predictions and not str(args.predictions).lower().endswith(".parquet"):
        raise CliError(f"--predictions: expected a .parquet file name, got {args.predictions!r}")
    mapping = parse_column_map(args.map, "--map")
    mf = read_model_file(args.model)
    if args.groups is None:
        groups = [g for g in NANODRONE_GROUPS] if all(
            c in mf.outputs for g in NANODRONE_GROUPS for c in g.columns) else []
    elif args.groups.strip().lower() == "none":
        groups = []
    else:
        groups = parse_groups(args.groups, mf.outputs)
    if args.baselines is not None and len(args.baselines) < 2:
        raise CliError("--baselines: needs at least two training records (one validates the "
                       "ARX orders)")
    if args.validation != "auto" and not args.baselines:
        raise CliError("--validation: needs --baselines")
    rule = validation_rule(args)
    if args.baselines:
        from cdam_core.evaluate.baselines import validation_records
        try:
            valid_idx = validation_records(args.baselines, rule)
        except ValueError as exc:
            raise CliError(f"--validation {rule}: {str(exc).split(': ', 1)[-1]}") from None
    read = dict(inputs=mf.inputs, outputs=mf.outputs, mapping=mapping, nan=args.nan,
                loader=args.loader)
    st = stack_records(args.records, **read)
    _check_physical_units(mf, st, args.records)
    U, Y = _smoothed(st, mf.smoothing_passes)      # as the model's training data
    dts = [float(np.median(np.diff(ds.t))) for ds in st.datasets]
    model_dt = getattr(mf.model, "dt", None)
    for path, dt in zip(args.records, dts):
        if model_dt is not None and abs(dt / model_dt - 1) > 0.01:
            raise CliError(f"{path}: sampled every {dt:g} s, the model every {model_dt:g} s")
    lengths = st.lengths
    if max(lengths) <= horizons[-1] + max(mf.model.t0, 1):
        raise CliError(f"--horizon: {args.horizon} samples is longer than every record")
    horizons = [h for h in horizons if h + max(mf.model.t0, 1) < max(lengths)]

    def progress(i, n):
        if not args.quiet and sys.stderr.isatty():
            print(f"\rcdam evaluate: {i}/{n} samples", end="" if i < n else "\n", file=sys.stderr)

    collected, baseline, first = [], None, 1
    if args.baselines:
        baseline = _arx_baseline(args.baselines, valid_idx, rule, read, mf.smoothing_passes, groups,
                                 horizons)
        first = max(mf.model.t0, baseline[0].t0)
    scores = score_horizons(mf.model, U, Y, mf.outputs, horizons, segments=lengths,
                            free_run=not args.no_free_run, progress=progress, groups=groups,
                            on_prediction=(lambda h, idx, P: collected.append((h, idx, P)))
                            if args.predictions else None, first=first)
    if baseline:
        scores.add(score_horizons(baseline[0], U, Y, mf.outputs, horizons, segments=lengths,
                                  free_run=not args.no_free_run, groups=groups, first=first),
                   "model", "arx")
    js = {"model": {"path": str(args.model), "kind": mf.kind, "sha256": mf.sha256,
                    "inputs": mf.inputs, "outputs": mf.outputs},
          "records": [{"path": str(p), "samples": len(ds), "segments": len(ds.segments),
                       "excluded": ds.meta.get("excluded", [])}
                      for p, ds in zip(args.records, st.datasets)],
          "dt": dts[0], **scores.to_json()}
    if baseline:
        js["baselines"] = {"arx": baseline[1]}
    if args.predictions:
        from cdam_core.evaluate.predictions import write_predictions
        write_predictions(args.predictions, st, collected, mapping)
    if args.json:
        write_json(args.json, js)
    from cdam_core.evaluate.published import GROUPS as PUBLISHED_GROUPS
    published = [g.name for g in groups] == list(PUBLISHED_GROUPS)   # the benchmark's groups
    head = (f"{mf.kind} model {args.model} on {len(st.names)} record(s) in {len(lengths)} "
            f"segment(s), {sum(lengths)} samples")
    if baseline:
        head += (f"; ARX baseline: orders (na, nb, nk) {tuple(baseline[1]['narx'])} chosen on "
                 f"{', '.join(Path(p).name for p in baseline[1]['validation'])} "
                 f"({rule}), refitted on the {len(args.baselines)} --baselines records")
    if args.report:
        from cdam_core.report.horizons import write_horizon_report
        write_horizon_report(scores, args.report, f"{Path(args.model).name} ({mf.kind})",
                             dt=dts[0], published=published, intro=head)
    from cdam_core.report.horizons import horizon_table
    print(head)
    print(horizon_table(scores))
    if groups:
        from cdam_core.report.horizons import group_table
        print(group_table(scores))
    if published:
        from cdam_core.report.horizons import published_table
        print(published_table())
    for name, fr in scores.free_run.items():
        if "status" in fr:
            print(f"free run ({name}): {fr['status']}: {fr['reason']}")
        else:
            print(f"free run ({name}): " + ", ".join(
                f"{o} rmse {v['rmse']:.4g}" for o, v in fr.items()))
    return 0


def _smoothed(st, passes):
    """Inputs and outputs of a stack smoothed segment by segment."""
    from cdam_core.preprocess import smooth_pair
    U, Y = st.U.copy(), st.Y.copy()
    for a, b in st.pieces():
        U[a:b], Y[a:b] = smooth_pair(st.U[a:b], st.Y[a:b], passes)
    return U, Y


def _arx_baseline(paths, valid_idx, rule, read, passes, groups, horizons):
    """(ARX model, JSON) of the baseline: orders chosen with the records ``valid_idx`` of
    ``paths`` as validation (evaluate.baselines.select_arx), preprocessed as the model's
    training data."""
    from dataclasses import replace

    from cdam_core.evaluate.baselines import select_arx
    from cdam_core.record.stack import stack_records
    fits = [p for i, p in enumerate(paths) if i not in valid_idx]
    valids = [paths[i] for i in valid_idx]
    fit, valid = (stack_records(x, **read) for x in (fits, valids))
    fit, valid = (replace(st, U=u, Y=y) for st, (u, y) in
                  ((fit, _smoothed(fit, passes)), (valid, _smoothed(valid, passes))))
    sel = [h for h in (1, 10, 25, 50) if h <= horizons[-1]]
    model, orders, val = select_arx(fit, valid, horizons=sel, groups=groups)
    return model, {"kind": "arx", "narx": list(orders), "train": [str(p) for p in fits],
                   "validation": [str(p) for p in valids], "validation_rule": rule,
                   "selection_horizons": sel,
                   "validation_scores": {",".join(map(str, k)): v for k, v in val.items()}}
