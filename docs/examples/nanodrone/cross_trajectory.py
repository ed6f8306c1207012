"""The nano-drone benchmark's multi-step protocol across trajectory types, with the baselines.

    python docs/examples/nanodrone/cross_trajectory.py OUT_DIR [--types square,random1,...]
        [--paper-networks] [--ardrone] [--no-flights] [--quick]

Train on three trajectory types of the 17 flights in ../shared/data/nanodrone (or
$CDAM_SHARED_DATA/nanodrone), test on the fourth, all four ways
(``cdam_core.evaluate.crossfold``): the naive predictor (hold the state), a full-state ARX(1)
and a MIMO ARX with orders and delay chosen on the training flights only, scored with the
benchmark's metrics per group (RMSE and MAE, attitude as the quaternion geodesic angle) at
every horizon 1..50. Prints per group the RMSE and MAE at h = 1, 10, 25, 50 per fold and their
mean over the folds, beside the published table; writes OUT_DIR/results.json, OUT_DIR/index.md
and the error-against-horizon figures (mean over the folds) in OUT_DIR/mean/.

``--paper-networks`` adds the paper's pipelines (IBOA-, BOA- and CABC-seeded BP networks
trained by LM, static and NARX, the paper's fixed choices: ``cdam_core.evaluate.papernets``)
to every fold, and ``iboa_narx_chosen``: the IBOA NARX network with its smoothing and LM goal
chosen on the fold's validation flights (``papernets.ChosenNetworkFitter``); ``--ardrone``
adds the AR.Drone flight (first 75 % / last 25 %, free run, mean r) with the same networks,
the naive predictor, the ARX chosen on the training part and the selected hybrid
(preprocessing, structure and network chosen by blocked validation on the training part,
network kept only if it helps there); the page then opens with one table of every predictor
on both records. ``--no-flights`` skips the nano-drone folds; ``--quick`` runs tiny settings (2
optimiser iterations and LM epochs, a one-point hybrid grid) to check the output, not to read.
The committed report docs/examples/papernets/ is
``python docs/examples/nanodrone/cross_trajectory.py docs/examples/papernets --paper-networks
--ardrone`` (about 20 minutes here, on a busy 2-core machine); docs/examples/ardrone/ is the
AR.Drone part alone, ``... docs/examples/ardrone --no-flights --ardrone`` (194 s CPU).
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
from cdam_core.evaluate.papernets import (ChosenNetworkFitter,  # noqa: E402
                                          paper_network_fitters)
from cdam_core.record.realdata.nanodrone import exclusion_report, nanodrone_files  # noqa: E402
from cdam_core.report.horizons import (group_table, published_table,  # noqa: E402
                                       write_horizon_report)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", help="output folder (created)")
    ap.add_argument("--types", default=",".join(TYPES),
                    help="test trajectory types, comma-separated (default: all four)")
    ap.add_argument("--data", default=None, help="folder of the flights (default: shared data)")
    ap.add_argument("--paper-networks", action="store_true",
                    help="also the paper's IBOA/BOA/CABC-BP networks, static and NARX")
    ap.add_argument("--ardrone", action="store_true",
                    help="also the AR.Drone flight (75 %% / 25 %%, free run, mean r)")
    ap.add_argument("--no-flights", action="store_true", help="skip the nano-drone folds")
    ap.add_argument("--quick", action="store_true",
                    help="tiny training settings (checks the output; numbers not meaningful)")
    args = ap.parse_args(argv)
    if args.no_flights and not args.ardrone:
        print("cross_trajectory.py: error: --no-flights: nothing left to run (add --ardrone)",
              file=sys.stderr)
        return 2
    quick = dict(iterations=2, lm_epochs=2, hidden=4) if args.quick else {}
    models, chosen = None, None
    if args.paper_networks:
        models = paper_network_fitters(**quick)
        # the same pipeline with smoothing and LM goal chosen on the validation flights
        chosen = ChosenNetworkFitter("iboa", "narx", **quick)
        models["iboa_narx_chosen"] = chosen
    out = Path(args.out)
    if args.no_flights:
        out.mkdir(parents=True, exist_ok=True)
        return _ardrone_section(out, [], None, ["# The paper's pipelines on the AR.Drone flight",
                                                ""], {}, quick)
    try:
        files = nanodrone_files(args.data)
    except FileNotFoundError as exc:
        # a plain clone: the flights are not in the repository (no licence file to ship them)
        print(f"cross_trajectory.py: error: the nano-drone flights are not in the repository "
              f"(no licence file), they live in a shared folder: {exc}; set CDAM_SHARED_DATA "
              f"to the folder holding nanodrone/ (or give --data)", file=sys.stderr)
        return 3
    out.mkdir(parents=True, exist_ok=True)
    flags = "".join(f" --{k}" for k in ("paper-networks", "ardrone")
                    if getattr(args, k.replace("-", "_")))
    nets = (" The paper's networks (IBOA-, BOA- and CABC-seeded BP trained by LM, static and "
            "NARX (2, 2, 1), its fixed choices: hidden 20, 5 smoothing passes, LM goal 0.003; "
            "at most 10,000 evenly spaced training rows) and iboa_narx_chosen (the IBOA NARX "
            "network with smoothing and LM goal chosen on the validation flights) train on all "
            "training flights." if args.paper_networks else "")
    loaded, folds, md = {}, [], ["# Nano-drone flights: train on three trajectory types, test "
                                 "on the fourth", "",
                                 "Produced by `python docs/examples/nanodrone/cross_trajectory.py"
                                 f" OUT_DIR{flags}`." + nets + " Predictors: naive (hold "
                                 "the state), ARX(1) (full state, na = nb = nk = 1, least "
                                 "squares on all training flights), arx (orders and delay "
                                 "chosen on the training "
                                 "flights: the last run of each training type validates). "
                                 "Scored k-step from the measured state with the measured "
                                 "motor speeds, every horizon 1..50 (10 ms steps), on every "
                                 "flight of the test type; samples left out by the loader are "
                                 "listed at the end.", ""]
    for test_type in [t.strip() for t in args.types.split(",") if t.strip()]:
        t0 = time.perf_counter()
        f = cross_trajectory_fold(files, test_type, loaded=loaded, models=models)
        folds.append(f)
        head = (f"## Test type {test_type} ({len(f.test_files)} flights; chosen ARX orders "
                f"na, nb, nk = {', '.join(map(str, f.orders))}; "
                f"{time.perf_counter() - t0:.0f} s)")
        if chosen is not None:
            c = chosen.choices[-1]
            head += ("\n\niboa_narx_chosen: " + ", ".join(f"{k} {v}" for k, v in
                                                         c["chosen"].items()) +
                     " (validation MAE / naive MAE: " + "; ".join(
                         ", ".join(f"{k} {v}" for k, v in x.items() if k != "relative_mae") +
                         f": {x['relative_mae']:.3f}" for x in c["validation"]) + ")")
        table = group_table(f.scores)
        print(head + "\n" + table + "\n", flush=True)
        md += [head, "", table, ""]
    mean = mean_over_folds(folds)
    table = group_table(mean)
    print(f"## Mean over the {len(folds)} folds\n{table}\n")
    write_horizon_report(mean, out / "mean", "Mean over the folds", dt=0.01,
                         logy=args.paper_networks)
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
    def groups_only(js):   # per output at every horizon is in to_json(); kept out here
        return {k: v for k, v in js.items() if k not in ("rmse", "mae")}
    js = {"folds": [groups_only(f.to_json()) for f in folds], "mean": groups_only(mean.to_json())}
    if chosen is not None:
        for f, c in zip(js["folds"], chosen.choices):
            f["iboa_narx_chosen"] = c
    if args.ardrone or args.paper_networks:
        return _ardrone_section(out, folds, mean, md, js, quick, args.ardrone)
    write_text_atomic(out / "index.md", "\n".join(md))
    write_json_atomic(out / "results.json", js)
    print(f"report: {out / 'index.md'}", file=sys.stderr)
    return 0


def _ardrone_section(out, folds, mean, md, js, quick, ardrone=True) -> int:
    """The AR.Drone rows (with ``ardrone``), the one table of every predictor on both records
    at the top of the page, the AR.Drone table and free-run figure; writes index.md,
    index.html and results.json."""
    from cdam_core.evaluate.papernets import ardrone_comparison
    from cdam_core.record.realdata.ardrone2 import load_ardrone2
    from cdam_core.report.page import write_page
    from cdam_core.report.papernets import (ardrone_table, selection_md, standing_table,
                                            write_ardrone_figure)
    rows = []
    if ardrone:
        t0 = time.perf_counter()
        hybrid = dict(decimations=(4,), passes=(0,), orders=(2,), delays=(0,),
                      features=("physics",), hidden=(3,), seeds=(0,), iterations=2,
                      lm_epochs=2, refine_epochs=1) if quick else None
        rows = ardrone_comparison(load_ardrone2(), paper_overrides=quick, hybrid=hybrid)
        print(f"## AR.Drone ({time.perf_counter() - t0:.0f} s)\n{ardrone_table(rows)}\n",
              flush=True)
        js["ardrone"] = [r.to_json() for r in rows]
    top = ["## Where the paper's method stands", "",
           "Every predictor on both records. Nano-drone: RMSE per group, mean over the four "
           "folds (train on three trajectory types, test on the fourth), at h = 1 and h = 50 "
           "(10 ms and 0.5 s ahead, k-step from the measured state). AR.Drone: free run on "
           "the last 25 % after training on the first 75 %, mean Pearson r over the six "
           "outputs and mean NRMSE (RMSE / std of the test part). '-': the model does not run "
           "on that record (quad_physics needs the 13 states and rotor speeds; arx1 and the "
           "physics variants are the nano-drone protocol's; the selected hybrid is the "
           "AR.Drone's).", "", standing_table(mean, rows), ""]
    md = md[:4] + top + md[4:]
    if rows:
        outputs = list(next(r for r in rows if r.metrics).metrics)
        traced = [r for r in rows if r.trace is not None]
        best_paper = max((r for r in traced if r.name not in ("arx", "hybrid_selected")),
                         key=lambda r: r.mean_r, default=None)
        pick = ["arx", "hybrid_selected"] + ([best_paper.name] if best_paper else [])
        write_ardrone_figure(out / "ardrone_free_run.png", rows, outputs, pick)
        md += ["## AR.Drone 2.0 flight: first 75 % trains, last 25 % runs free", "",
               ardrone_table(rows), "",
               "![AR.Drone free run](ardrone_free_run.png)", "",
               "*Figure: the AR.Drone test part in free run (angles in rad, positions in m, "
               "against the time from the start of the test part in s): measured, the chosen "
               "ARX, the selected hybrid and the best of the paper's networks.*", "",
               "### What the selected hybrid chose", "",
               *selection_md(next(r for r in rows if r.name == "hybrid_selected").details), ""]
    write_json_atomic(out / "results.json", js)
    write_page(out / "index.md", md, md[0].lstrip("# "))
    print(standing_table(mean, rows))
    print(f"report: {out / 'index.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
