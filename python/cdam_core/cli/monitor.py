"""`cdam monitor MODEL RECORD`: the residual monitor's alarms on a record (and its calibration
on a training record with --calibrate OUT)."""
from __future__ import annotations

from cdam_core.cli.common import (CliError, add_outputs, check_io, elapsed_ticker, note,
                                  write_json)

FLAG_NAMES = {1: "cusum_up", 2: "cusum_down", 4: "ewma"}


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "monitor", help="watch a model's one-step residual on a record: EWMA + CUSUM alarms",
        description="Run the residual monitor of a model file (any kind with a one-step "
                    "predictor: arx, hybrid, greybox, a NARX bp_network) on RECORD: per output, "
                    "the one-step residual normalised by the training record's residual mean "
                    "and std, its EWMA and a two-sided CUSUM, thresholds from the model file's "
                    "'monitor' section. Prints each alarm (time, output, statistic); the "
                    "firmware (fw/monitor.hpp) takes the same decisions. With --calibrate OUT, "
                    "RECORD is the training record: the residual statistics and thresholds "
                    "(set by simulating the residual's own autocorrelation for a false-alarm "
                    "probability per 60 s; cdam_core.evaluate.monitor) are computed on it and "
                    "written with the model to OUT.")
    p.add_argument("model", metavar="MODEL", help="model file (.json)")
    p.add_argument("record", metavar="RECORD", help="dataset file (.csv or .parquet)")
    p.add_argument("--map", default=None,
                   help="model names to record columns: name=column[*factor],... or a JSON file")
    p.add_argument("--calibrate", metavar="OUT", default=None,
                   help="compute the monitor section on RECORD (a training record) and write "
                        "the model with it to OUT")
    p.add_argument("--paths", type=int, default=1000,
                   help="simulated in-control paths per output for the thresholds (--calibrate)")
    p.add_argument("--seed", type=int, default=0, help="seed of the simulation (--calibrate)")
    add_outputs(p)
    p.set_defaults(func=run)


def run(args) -> int:
    import numpy as np

    from cdam_core.evaluate.monitor import calibrate, one_step_residuals, run_monitor
    from cdam_core.models.file import read_model_file, save_model
    from cdam_core.preprocess import smooth_pair
    from cdam_core.record.columns import parse_column_map
    from cdam_core.record.stack import stack_records

    check_io(inputs=[("MODEL", args.model), ("RECORD", args.record)],
             files=[("--json", args.json), ("--calibrate", args.calibrate)],
             folders=[("--report", args.report)])
    if args.report and args.calibrate:
        raise CliError("--report: a report of the alarms on a record; not with --calibrate")
    if args.paths < 100:
        raise CliError(f"--paths: at least 100, got {args.paths}")
    if args.seed < 0:
        raise CliError(f"--seed: must be >= 0, got {args.seed}")
    mf = read_model_file(args.model)
    st = stack_records([args.record], inputs=mf.inputs, outputs=mf.outputs,
                       mapping=parse_column_map(args.map, "--map"))
    U, Y = st.U.copy(), st.Y.copy()
    for a, b in st.pieces():
        U[a:b], Y[a:b] = smooth_pair(st.U[a:b], st.Y[a:b], mf.smoothing_passes)
    dt = float(np.median(np.diff(st.t)))
    if args.calibrate:
        note(args, f"calibrating the monitor on {args.record} ({len(st.t)} rows)")
        with elapsed_ticker(args, "simulating the residual's false-alarm thresholds"):
            sec = calibrate(mf.model, U, Y, dt, st.lengths, paths=args.paths, seed=args.seed)
        save_model(args.calibrate, mf.model, inputs=mf.inputs, outputs=mf.outputs,
                   smoothing_passes=mf.smoothing_passes, meta=mf.meta, monitor=sec)
        js = {"model": str(args.model), "record": str(args.record), "output": args.calibrate,
              "monitor": sec}
        if args.json:
            write_json(args.json, js)
        for c, name in enumerate(mf.outputs):
            print(f"{name}: residual mean {sec['mean'][c]:.4g} std {sec['std'][c]:.4g}, "
                  f"AR({sec['ar_order'][c]}), CUSUM h {sec['h'][c]:.4g} (k {sec['k']}), "
                  f"EWMA limit {sec['ewma_limit'][c]:.4g} (lambda {sec['lambda']:.4g})"
                  + ("" if sec["watched"][c] else "; not watched (a unit quaternion's "
                                                    "largest component)"))
        print(f"-> {args.calibrate}")
        return 0
    if mf.monitor is None:
        raise CliError(f"MODEL: {args.model} has no monitor section; calibrate it on its "
                       f"training record first (cdam monitor MODEL TRAIN --calibrate OUT)")
    if abs(dt / mf.monitor["dt"] - 1) > 0.01:
        raise CliError(f"RECORD: sampled every {dt:g} s, the monitor was set for "
                       f"{mf.monitor['dt']:g} s")
    R, valid = one_step_residuals(mf.model, U, Y, st.lengths)
    starts = [a for a, _ in st.pieces()]
    res = run_monitor(mf.monitor, R, valid, starts)
    alarms = [{"row": int(st.row[t]), "t": float(st.t[t]), "output": mf.outputs[c],
               "statistics": [n for bit, n in FLAG_NAMES.items() if f & bit]}
              for t, c, f in res.alarms]
    js = {"model": {"path": str(args.model), "kind": mf.kind, "sha256": mf.sha256},
          "record": str(args.record), "rows": int(len(st.t)), "monitored_rows": int(valid.sum()),
          "alarms": alarms,
          "alarm_count": {name: sum(a["output"] == name for a in alarms) for name in mf.outputs},
          "monitor": mf.monitor}
    if args.json:
        write_json(args.json, js)
    if args.report:
        from cdam_core.report.monitor import write_monitor_report
        md = write_monitor_report(args.report, st.t, list(mf.outputs), res, mf.monitor, alarms,
                                  title=f"Residual monitor: {mf.kind} model on {args.record}",
                                  source=f"model {args.model} (sha256 {mf.sha256[:12]}...), "
                                         f"record {args.record}",
                                  units={o: u for o, u in st.datasets[0].units.items() if u})
        note(args, f"report: {md}")
    print(f"{mf.kind} model {args.model} on {args.record}: {int(valid.sum())} rows monitored, "
          f"{len(alarms)} alarm(s)")
    for a in alarms[:50]:
        print(f"  t {a['t']:.4f} s  {a['output']}  {'+'.join(a['statistics'])}")
    if len(alarms) > 50:
        print(f"  ... {len(alarms) - 50} more (--json has them all)")
    return 0
