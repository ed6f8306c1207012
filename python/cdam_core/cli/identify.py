"""`cdam identify`: IBOA-BP, BOA-BP, CABC-BP and plain BP on a dataset CSV, with report and JSON."""
from __future__ import annotations

from pathlib import Path

from cdam_core.cli.common import (CliError, add_validation_option, check_io, note, parse_narx,
                                  show_progress, validation_rule, write_json)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "identify", help="identify a BP/NARX model with IBOA, BOA, CABC or plain BP",
        description="Train on TRAIN.csv (dataset format), evaluate on a test record (--test, or "
                    "the last part of TRAIN with --split) and an optional validation record; "
                    "compare algorithms over several seeds with a rank-sum test. Several "
                    "TRAIN records (or one cut into segments) are kept apart: each is smoothed "
                    "on its own, and the network (static or NARX; no regressor crosses a seam) "
                    "trains across them; a hybrid model needs one contiguous record.")
    p.add_argument("train", nargs="+", help="training record(s) (dataset CSV or Parquet)")
    p.add_argument("--map", default=None,
                   help="model names to record columns: name=column[*factor],... or a JSON file")
    p.add_argument("--nan", default="error", choices=["error", "split"],
                   help="a missing value is an error, or its row is left out and the record "
                        "cut there (default: error)")
    p.add_argument("--loader", default="dataset", choices=["dataset", "nanodrone"],
                   help="nanodrone: the nano-drone benchmark's Parquet flights")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--test", help="test record (dataset CSV)")
    g.add_argument("--split", type=float, default=None,
                   help="fraction of TRAIN used for training; the rest is the test record")
    p.add_argument("--validate", help="validation record (dataset CSV)")
    p.add_argument("--algo", default="iboa", choices=["iboa", "boa", "cabc", "bp", "all"],
                   help="algorithm; all: the four, compared by a rank-sum test (use --seeds 4 "
                        "or more)")
    p.add_argument("--seeds", type=int, default=1,
                   help="seeds per algorithm (seeds 0..N-1)")
    p.add_argument("--hidden", type=int, default=None,
                   help="hidden units (default: 20; quad_hybrid: the model's default; "
                        "arx_kstep: chosen on validation among evaluate.crossfold.ANCHORED_GRID's "
                        "structures)")
    p.add_argument("--narx", default=None, help="NARX orders na,nb,nk (default: static map)")
    p.add_argument("--model", default="bp",
                   choices=["bp", "hybrid", "quad_physics", "quad_hybrid", "arx_kstep"],
                   help="bp: the paper's network (static or NARX); hybrid: linear ARX with the "
                        "algorithm's network on its residual (needs --narx); quad_physics: "
                        "the quadrotor rigid body on its 4 rotor speeds (rad/s) and 13 states, "
                        "least squares on the training records (no smoothing, no algorithm; "
                        "models/flight/physics.py); quad_hybrid: quad_physics with a "
                        "recurrent network on its rate residual trained by LM on the k-step "
                        "error (models/flight/hybrid.py; --hidden, --horizon, --lags, --epochs, "
                        "--weighting, --rates as its prior); arx_kstep: a least-squares ARX "
                        "(orders chosen on validation records) with a recurrent network on "
                        "the residual of its k-step rollout, kept only where it beats the ARX "
                        "on the validation records (models/arx_kstep.py, evaluate/crossfold.py "
                        "AnchoredFitter; --validation, --hidden, --lags, --horizon, --epochs, "
                        "--stride; no smoothing, no algorithm)")
    p.add_argument("--horizon", type=int, default=None,
                   help="quad_hybrid, arx_kstep: steps of each training window (default: "
                        "quad_hybrid: the model's; arx_kstep: chosen on validation among "
                        "ANCHORED_GRID's structures)")
    p.add_argument("--lags", type=int, default=None,
                   help="quad_hybrid: rotor-speed lags the network sees; arx_kstep: "
                        "input-feature lags (default: quad_hybrid: the model's; arx_kstep: chosen "
                        "on validation among ANCHORED_GRID's structures)")
    p.add_argument("--stride", type=int, default=None,
                   help="arx_kstep: samples between training-window starts (default: 100, "
                        "evaluate.crossfold.ANCHORED_FIXED's)")
    add_validation_option(p, "TRAIN records validate arx_kstep's choices (the ARX orders, "
                             "the network's structure and epoch count, whether it is kept; "
                             "then it is refitted on all TRAIN)")
    p.add_argument("--blend-design", default=None, choices=["auto", "flights", "types"],
                   help="arx_kstep: where the blend's weights are chosen: flights: on the "
                        "validation records (session 8's design); types: type out (each "
                        "trajectory type of TRAIN, the file name's prefix up to the first "
                        "'_', held out in turn from the components' training, the direct "
                        "multi-step predictor kept where it lowers the type-out score, each "
                        "step's and group's weights the ARX's alone unless the held-out types "
                        "prefer the blend there on the mean; evaluate.crossfold.AnchoredFitter, "
                        "the "
                        "design of docs/examples/nanodrone/anchored/; needs two types in "
                        "TRAIN); auto: types when TRAIN holds two or more types, else flights "
                        "(default: auto)")
    p.add_argument("--weighting", default=None, choices=["flat", "naive"],
                   help="quad_hybrid: the steps' errors alike, or each over the naive "
                        "predictor's error at that step (default: the model's)")
    p.add_argument("--rates", default="dynamic", choices=["dynamic", "hold"],
                   help="quad_physics: integrate the rotational dynamics, or hold the body "
                        "rates (the nano-drone benchmark paper's physics model); quad_hybrid: "
                        "the prior of the network's rate residual")
    p.add_argument("--features", default="raw", choices=["raw", "physics"],
                   help="hybrid inputs: raw, or physics (4 motor commands in X-mixer order: "
                        "commands, thrust ~ sum of squares, roll/pitch/yaw torque combinations)")
    p.add_argument("--ensemble", type=int, default=None,
                   help="hybrid: train K residual networks (seeds s .. s+K-1 for seed s) and "
                        "use their mean (default: 1)")
    p.add_argument("--residual-weights", default=None,
                   help="hybrid: candidate weights in [0, 1] of the network's term, chosen on "
                        "validation with 0 (the ARX alone) always among them (default: 0,1)")
    p.add_argument("--validation-blocks", type=int, default=None,
                   help="hybrid: choose the weight on B contiguous blocks of the training "
                        "part, each held out in turn (default: 0, the last 20 %%)")
    p.add_argument("--residual-training", default=None, choices=["one_step", "free_run"],
                   help="hybrid: each network fitted on the ARX's one-step residual, or that "
                        "fit refined by LM on the hybrid's free-run error (default: one_step)")
    p.add_argument("--inputs", default=None, help="comma-separated input columns")
    p.add_argument("--outputs", default=None, help="comma-separated output columns")
    p.add_argument("--smoothing", type=int, default=5, help="five-point smoothing passes")
    p.add_argument("--iterations", type=int, default=50, help="Tmax of the optimisers")
    p.add_argument("--population", type=int, default=20, help="g (butterflies) and CABC Np")
    p.add_argument("--epochs", type=int, default=None,
                   help="LM epochs at most (default: 50; quad_hybrid: the model's; arx_kstep: "
                        "20, ANCHORED_FIXED's: the validation records' best epoch is kept)")
    p.add_argument("--goal", type=float, default=0.003, help="LM goal (training MSE)")
    p.add_argument("--report", default=None, help="folder for report.md and PNG figures")
    p.add_argument("--json", default=None, help="write the results as JSON")
    p.add_argument("--save", default=None,
                   help="save the model (best seed of the first algorithm) for cdam_core.load_model")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def _hybrid_options(args) -> dict:
    """IdentifyConfig fields of --ensemble, --residual-weights, --validation-blocks (only with
    --model hybrid)."""
    given = {"ensemble": args.ensemble, "residual_weights": args.residual_weights,
             "validation_blocks": args.validation_blocks,
             "residual_training": args.residual_training}
    given = {k: v for k, v in given.items() if v is not None}
    if given and args.model != "hybrid":
        raise CliError(f"--{next(iter(given)).replace('_', '-')}: needs --model hybrid")
    if "residual_weights" in given:
        try:
            given["residual_weights"] = tuple(float(v) for v in given["residual_weights"]
                                              .split(","))
        except ValueError:
            raise CliError(f"--residual-weights: expected numbers in [0, 1] separated by "
                           f"commas, got {args.residual_weights!r}") from None
    return given


def run(args) -> int:
    from cdam_core.record.columns import parse_column_map
    from cdam_core.record.stack import stack_records
    from cdam_core.evaluate import compare
    from cdam_core.identify import IdentifyConfig

    check_io(inputs=[("TRAIN", t) for t in args.train] +
             [("--test", args.test), ("--validate", args.validate)],
             files=[("--json", args.json), ("--save", args.save)],
             folders=[("--report", args.report)])
    if args.seeds < 1:
        raise CliError("--seeds: must be >= 1")
    if args.split is not None and not 0 < args.split < 1:
        raise CliError(f"--split: must be in (0, 1), got {args.split}")
    hyb = _hybrid_options(args)
    mapping = parse_column_map(args.map, "--map")
    read = dict(mapping=mapping, nan=args.nan, loader=args.loader)
    train = stack_records(args.train, inputs=args.inputs, outputs=args.outputs, **read)
    if args.model == "arx_kstep":
        return _anchored(args, train, read)
    for name in ("stride", "blend_design"):
        if getattr(args, name) is not None:
            raise CliError(f"--{name.replace('_', '-')}: needs --model arx_kstep")
    if args.validation != "auto":
        raise CliError("--validation: needs --model arx_kstep (other kinds: --validate FILE)")
    if args.model in ("quad_physics", "quad_hybrid"):
        return _physics(args, train, read)
    for name in ("horizon", "lags", "weighting"):
        if getattr(args, name) is not None:
            raise CliError(f"--{name}: needs --model quad_hybrid or arx_kstep"
                           if name != "weighting" else f"--{name}: needs --model quad_hybrid")
    args.hidden = 20 if args.hidden is None else args.hidden
    args.epochs = 50 if args.epochs is None else args.epochs
    if len(train.lengths) > 1 and not args.test:
        raise CliError(f"--split: needs one contiguous TRAIN record, got {len(train.lengths)} "
                       f"segments (several records, or gaps declared in a sidecar); give "
                       f"--test instead")
    U, Y, t = train.U, train.Y, train.t
    records, times, segs = {}, {}, {}
    if args.test:
        te = stack_records([args.test], inputs=train.inputs, outputs=train.outputs, **read)
        records["test"] = (te.U, te.Y)
        times["test"], segs["test"] = te.t, te.lengths
    else:
        frac = 0.5 if args.split is None else args.split
        n = int(round(len(t) * frac))
        if n < 10 or len(t) - n < 10:
            raise CliError(f"--split: {frac} leaves fewer than 10 samples on one side")
        records["test"] = (U[n:], Y[n:])
        times["test"] = t[n:]
        U, Y, t = U[:n], Y[:n], t[:n]
    if args.validate:
        va = stack_records([args.validate], inputs=train.inputs, outputs=train.outputs, **read)
        records["validation"] = (va.U, va.Y)
        segs["validation"] = va.lengths
        times["validation"] = va.t
    if args.model == "hybrid" and args.narx is None:
        raise CliError("--model hybrid: needs --narx na,nb,nk")
    if args.features != "raw" and args.model != "hybrid":
        raise CliError("--features physics: needs --model hybrid")
    if args.features == "physics" and len(train.inputs) != 4:
        raise CliError(f"--features physics: needs 4 motor-command inputs, got {len(train.inputs)}")
    try:
        cfg = IdentifyConfig(hidden=args.hidden, narx=parse_narx(args.narx),
                             smoothing_passes=args.smoothing, iterations=args.iterations,
                             population=args.population, lm_epochs=args.epochs,
                             lm_goal=args.goal, model=args.model, features=args.features, **hyb)
    except ValueError as exc:
        msg = str(exc)
        for field, opt in (("ensemble", "--ensemble"), ("weights", "--residual-weights"),
                           ("validation_blocks", "--validation-blocks")):
            if msg.startswith(field + ":"):
                raise CliError(opt + msg[len(field):]) from None
        raise
    algos = ["iboa", "boa", "cabc", "bp"] if args.algo == "all" else [args.algo]
    comparison = compare(algos, U, Y, records=records, seeds=range(args.seeds), config=cfg,
                         names=train.outputs, progress=show_progress(args),
                         segments=train.lengths if args.test else None,
                         record_segments={k: v for k, v in segs.items() if len(v) > 1})
    result, models = comparison.result, comparison.models
    result["inputs"] = train.inputs
    result["train_file"] = str(args.train[0]) if len(args.train) == 1 else \
        [str(x) for x in args.train]
    from cdam_core.evaluate.baselines import naive_and_arx
    from cdam_core.report.identify import headline
    result["baselines"] = naive_and_arx(U, Y, records, train.outputs, narx=cfg.narx,
                                        smoothing_passes=cfg.smoothing_passes,
                                        features=cfg.features,
                                        segments=train.lengths if args.test else None,
                                        record_segments=segs)
    print("\n".join(headline(result)))
    for other, entry in result.get("rank_sum", {}).items():
        for score, v in entry.items():
            print(f"IBOA vs {other} on {score}: p = {v['p_value']:.3g} "
                  f"({'IBOA better' if v['iboa_better'] else 'not significant'})")
    if args.json:
        write_json(args.json, result)
    if args.report:
        from cdam_core.report.identify import write_report
        md = write_report(comparison, args.report, records=records, times=times,
                          title=f"Identification of {', '.join(Path(x).name for x in args.train)}")
        note(args, f"report: {md}")
    if args.save:
        from cdam_core.models.file import save_model
        save_model(args.save, models[algos[0]], inputs=train.inputs, outputs=train.outputs,
                   smoothing_passes=args.smoothing)
        note(args, f"model: {args.save}")
    return 0


def _physics(args, train, read) -> int:
    """``--model quad_physics`` / ``quad_hybrid``: fit on every training record (segments kept
    apart), print the parameters with their standard deviations, score a --test record at
    h = 1, 10, 50 beside the naive predictor, save."""
    from cdam_core.models.flight.hybrid import QuadHybrid
    from cdam_core.models.flight.physics import STATES, QuadPhysics

    kind = args.model
    if len(train.inputs) != 4 or list(train.outputs) != list(STATES):
        raise CliError(f"--model {kind}: needs the 4 rotor speeds as inputs and the 13 "
                       f"states {' '.join(STATES)} as outputs, in this order (got inputs "
                       f"{', '.join(train.inputs)}; outputs {', '.join(train.outputs)})")
    if args.split is not None:
        raise CliError(f"--model {kind}: give --test records instead of --split")
    dts = _one_rate(train)
    try:
        if kind == "quad_physics":
            model = QuadPhysics(dt=dts[0], rates=args.rates)
        else:
            kw = {k: getattr(args, k) for k in ("hidden", "horizon", "lags", "epochs",
                                                 "weighting") if getattr(args, k) is not None}
            model = QuadHybrid(dt=dts[0], prior=args.rates, **kw)
    except ValueError as exc:
        raise CliError(f"--{str(exc).split(':')[0]}: {str(exc).split(': ', 1)[-1]}") from None
    try:
        model.fit(train.U, train.Y, segments=train.lengths)
    except ValueError as exc:
        raise CliError(f"TRAIN: {exc}") from None
    params = model.parameters()
    print(f"{kind} ({args.rates} rates) on {len(train.names)} record(s), "
          f"{len(train.lengths)} segment(s), {len(train.Y)} samples, dt {dts[0]:g} s")
    for name, (v, s) in params.items():
        rel = f" ({100 * abs(s / v):.2g} %)" if s is not None and v else ""
        print(f"  {name:18s} {v:.6g}" + (f" +- {s:.3g}{rel}" if s is not None else ""))
    result = {"kind": kind, "rates": args.rates, "dt": dts[0],
              "train_file": [str(x) for x in args.train],
              "parameters": {k: {"value": v, "std": s} for k, (v, s) in params.items()}}
    if kind == "quad_hybrid":
        result["structure"] = {k: getattr(model, k) for k in
                               ("hidden", "horizon", "lags", "prior", "weighting", "epochs")}
        result["training"] = model.history_
        print(f"  k-step LM: {len(model.history_['mse']) - 1} epochs, weighted k-step mse "
              f"{model.history_['mse'][0]:.4g} -> {model.history_['mse'][-1]:.4g} "
              f"({model.history_['stop']})")
    return _finish(args, model, train, read, result, {"train": [str(x) for x in args.train]})


def _finish(args, model, train, read, result, meta) -> int:
    """The flight kinds' common end: score --test, write --json, save (with ``meta``)."""
    if args.test:
        result["test"] = _score_test(args, model, train, read)
    if args.json:
        write_json(args.json, result)
    if args.save:
        from cdam_core.models.file import save_model
        save_model(args.save, model, inputs=train.inputs, outputs=train.outputs, meta=meta)
        note(args, f"model: {args.save}")
    return 0


def _one_rate(train) -> list[float]:
    """The records' sampling intervals (s); CliError unless they share one rate."""
    import numpy as np
    dts = [float(np.median(np.diff(ds.t))) for ds in train.datasets if len(ds.t) > 1]
    if not dts or max(dts) / min(dts) - 1 > 0.01:
        raise CliError("TRAIN: the records are not sampled at one rate")
    return dts


def _flight_groups(outputs) -> list:
    """The nano-drone benchmark's output groups when every one of their columns is an output,
    else none (each output scored alone)."""
    from cdam_core.evaluate.groups import NANODRONE_GROUPS
    groups = list(NANODRONE_GROUPS)
    return groups if all(c in outputs for g in groups for c in g.columns) else []


def _group_name(groups, label) -> str:
    """A group label of ``AnchoredFitter._labels`` by name (the ungrouped outputs' by number)."""
    label = int(label)
    return groups[label].name if label < len(groups) else f"output group {label}"


def _score_test(args, model, train, read) -> dict:
    """Scores of ``model`` on the --test record at h = 1, 10, 50 (those it is long enough
    for) beside the naive predictor; the group table printed."""
    from cdam_core.evaluate.horizons import score_horizons
    from cdam_core.record.stack import stack_records
    from cdam_core.report.horizons import group_table, horizon_table

    te = stack_records([args.test], inputs=train.inputs, outputs=train.outputs, **read)
    hs = [h for h in (1, 10, 50) if h + model.t0 < max(te.lengths)]
    if not hs:
        raise CliError(f"--test: {args.test} is too short to score")
    groups = _flight_groups(te.outputs)
    sc = score_horizons(model, te.U, te.Y, te.outputs, hs, segments=te.lengths,
                        free_run=False, groups=groups)
    print(group_table(sc, at=hs) if groups else horizon_table(sc, at=hs))
    return {"file": str(args.test), **sc.to_json()}


#: the command-line options passed to the anchored model (AnchoredFitter's ``fixed``; an option
#: given overrides the structure grid's value too): one entry per ArxKStep argument offered
ANCHORED_OPTIONS = ("hidden", "lags", "horizon", "epochs", "stride")


def _anchored(args, train, read) -> int:
    """``--model arx_kstep``: the validation records chosen from TRAIN by ``--validation``;
    ``evaluate.crossfold.AnchoredFitter`` chooses the ARX orders, the network's structure and
    epoch count, and whether the network is kept, on them, then refits on all TRAIN; prints
    the choices and their validation scores, scores a --test record, saves (kind arx_kstep, or
    arx when the network is not kept)."""
    import time

    from cdam_core.evaluate.baselines import validation_records
    from cdam_core.evaluate.crossfold import ANCHORED_FIXED, ANCHORED_GRID, AnchoredFitter
    from cdam_core.models.arx_kstep import ArxKStep
    from cdam_core.record.stack import stack_records

    why = {"split": "give --test records instead",
           "narx": "arx_kstep chooses the ARX orders on the validation records",
           "weighting": "arx_kstep weighs each step's error over the ARX's there",
           "validate": "arx_kstep takes its validation records from TRAIN (--validation)"}
    for name, reason in why.items():
        if getattr(args, name) is not None:
            raise CliError(f"--{name}: not used by --model arx_kstep: {reason}")
    if args.features != "raw":
        raise CliError("--features physics: needs --model hybrid")
    dt = _one_rate(train)[0]
    rule = validation_rule(args)
    try:
        valid_idx = validation_records(train.names, rule)
    except ValueError as exc:
        raise CliError(f"--validation {rule}: {str(exc).split(': ', 1)[-1]}") from None
    groups = _flight_groups(train.outputs)
    given = {k: getattr(args, k) for k in ANCHORED_OPTIONS if getattr(args, k) is not None}
    # physics features of the network's inputs: four rotor speeds of a flight; others raw
    fixed = {**ANCHORED_FIXED, **({} if groups and len(train.inputs) == 4 else
                                  {"net_features": "raw"}), **given}
    grid = {}
    for name, kw in ANCHORED_GRID.items():
        over = [k for k in kw if k in given]     # the grid's values the options replace
        kw = {k: v for k, v in kw.items() if k not in given}
        if kw not in grid.values():
            grid[name + "".join(f" {k} {given[k]}" for k in over)] = kw
    for kw in grid.values():                      # the options' values checked before training
        try:
            ArxKStep(**{**fixed, **kw})
        except ValueError as exc:
            raise CliError(f"--{str(exc).split(':')[0]}: {str(exc).split(': ', 1)[-1]}") \
                from None
    sets = dict(inputs=train.inputs, outputs=train.outputs)
    fit = stack_records([ds for i, ds in enumerate(train.datasets) if i not in valid_idx], **sets)
    valid = stack_records([train.datasets[i] for i in valid_idx], **sets)
    for kw in grid.values():
        K = int({**fixed, **kw}.get("horizon", 1))
        if max(fit.lengths) <= K + 1:
            raise CliError(f"--horizon: windows of {K} steps do not fit in any segment of the "
                           f"fitted records (the longest has {max(fit.lengths)} samples)")
    design = args.blend_design or "auto"
    fitter = AnchoredFitter(grid=grid, fixed=fixed, groups=groups, blend_design=design,
                            direct=design != "flights", **({} if groups else {"blind": ()}))
    t = time.perf_counter()
    try:
        model = fitter(train, fit, valid)
    except ValueError as exc:
        raise CliError(f"TRAIN: {exc}") from None
    seconds = time.perf_counter() - t
    c = fitter.choices[-1]
    names = [str(x) for x in args.train]
    vnames = [names[i] for i in valid_idx]
    print(f"arx_kstep on {len(names)} record(s), {len(train.lengths)} segment(s), "
          f"{len(train.Y)} samples, dt {dt:g} s; validation ({rule}): "
          + ", ".join(Path(v).name for v in vnames))
    print(f"  ARX orders (na, nb, nk) chosen on validation: {tuple(c['arx_orders'])}"
          + (f", features {c['anchor_features']}" if "anchor_features" in c else ""))
    print("  validation score (MAE over naive MAE, mean over h = "
          + ", ".join(map(str, fitter.select_horizons))
          + (" and the groups" if groups else " and the outputs") + "): "
          + ", ".join(f"{k} {v:.4g}" if v != float("inf") else f"{k} failed (diverged, or "
                      f"too few windows)" for k, v in c["validation"].items()))
    if c["chosen"] == "arx":
        print("  chosen: the ARX alone (the network did not lower the validation score); "
              "saved as kind arx")
    else:
        print(f"  chosen: {c['chosen']} (network kept), {c['epochs']} LM epochs (the "
              f"validation flights' best), structure "
              + ", ".join(f"{k} {v}" for k, v in c["structure"].items()))
    if c.get("type_out"):
        t = c["type_out"]
        print(f"  direct predictor orders {tuple(c['direct']['orders'])} (validation); "
              f"type-out score with it {t['scores']['with_direct']:.4g}, without "
              f"{t['scores']['without_direct']:.4g}: "
              + ("kept" if t["keep_direct"] else "left out"))
        first = (c["direct"] or {}).get("first") or {}
        if first.get("chosen"):
            print("  its step 1 chosen type out per group (least mean one-step RMSE over the "
                  "raw ARX's): " + ", ".join(
                      f"{_group_name(groups, g)} {v}" for g, v in first["chosen"].items())
                  + (f"; mixed row by row with the raw ARX's by their one-step errors over "
                     f"the {first['mix'][2]} rows before" if first.get("mix") else ""))
    if c.get("blend_weights") is not None:
        where = "type out over " + ", ".join(c["type_out"]["types"]) if c.get("type_out") \
            else "on validation"
        print(f"  blended per step and group (blend design {c['blend_design']}"
              + (f", asked {c['blend_design_asked']}" if c.get("blend_design_asked") !=
                 c["blend_design"] else "") + f"; weights chosen {where}) of: "
              + ", ".join(c.get("blend_components", [])))
        gate = (c.get("type_out") or {}).get("gate")
        if gate:
            closed = sum(len(v) for v in gate["closed"])
            print(f"  the ARX's weights alone (the held-out types did not prefer the blend) "
                  f"at {closed} of {sum(len(v) for v in gate['kept'])} steps x groups")
    print(f"  wall time {seconds:.0f} s (selection {c['select_seconds']:.0f} s, final fit on "
          f"all TRAIN {c['fit_seconds']:.0f} s)")
    choice = {k: c[k] for k in ("arx_orders", "validation", "chosen", "epochs", "structure",
                                "anchor_features", "blend_components", "blend_design",
                                "blend_design_asked",
                                "direct") if k in c}
    if c.get("type_out"):
        choice["type_out"] = {k: v for k, v in c["type_out"].items()
                              if k != "other_rule_weights"}
    choice["validation"] = {k: v if v != float("inf") else None       # None: diverged
                            for k, v in choice["validation"].items()}
    result = {"kind": type(model).kind, "dt": dt, "train_file": names,
              "validation_rule": rule, "validation_files": vnames,
              "grid": grid, "fixed": fixed, "choice": choice, "seconds": seconds,
              "select_seconds": c["select_seconds"], "fit_seconds": c["fit_seconds"],
              "training": c["history"], "validation_history": c["validation_history"]}
    return _finish(args, model, train, read, result, {
        "train": names, "validation_rule": rule, "validation": vnames, "choice": choice})
