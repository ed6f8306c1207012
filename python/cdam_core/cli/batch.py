"""`cdam batch SPEC`: one command over records x seeds x algorithms x folds on dask.distributed."""
from __future__ import annotations

import os
import time
from pathlib import Path

from cdam_core import _core
from cdam_core.cli.common import (CliError, CliIOError, add_outputs, check_io, note,
                                  show_progress, write_json)

SPEC_HELP = """spec (JSON):
  {"command": "identify" | "evaluate" | "crossfold" | "residual" | "paper",
   "records": ["flights/*.csv"],          globs, relative to the current folder
                                          ("shared:nanodrone/*.parquet": shared data)
   "algorithms": ["iboa", "bp"],          identify (default ["iboa"]), paper (default
                                          ["iboa", "boa", "cabc"])
   "seeds": 10,                           identify, paper: seed indices 0..N-1
   "seed_rule": "index" | "derived",      seed = index (as cdam identify --seeds), or a
                                          uint32 from (record, algorithm, index, fold)
   "folds": 1,                            identify: 1 = --split; K > 1 = forward chaining;
                                          crossfold: test types (default all four)
   "model": "model.json",                 evaluate: the model scored on every record
   "sections": ["static", "narx", "hybrid"],  paper (no "records": each worker simulates
                                          the flights of options.flight_seed, as cdam paper)
   "options": {"hidden": 20, "narx": [2, 2, 1], "epochs": 50, ...}}
residual: options.model (rigid_axis, flexible_joint, quadrotor, aerial_manipulator), map,
fixed, inputs, outputs, cutoff, alpha, free_run, estimator (auto, idim-ls, idim-iv, oe,
sim; output_error: true is estimator oe), stick_slip (auto, on, off) (cdam residual's).
See cdam_core.fleet.spec for every option.

example, cdam paper --seeds 10 as one batch (90 tasks; same figures):
  cdam batch docs/examples/batch/paper_seeds.json --out out/batch-paper --report out/batch-paper"""


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "batch", help="run identify/evaluate/crossfold/residual/paper over many records, seeds, "
                      "algorithms and folds on Dask",
        description="Expand SPEC into tasks (records x algorithms x seeds x folds), run them on "
                    "dask.distributed: an in-process LocalCluster sized to this machine, or "
                    "the cluster at --scheduler. Each worker reads its own records; the "
                    "results are gathered into OUT/results.parquet and OUT/results.json (one "
                    "row per task with every metric; a task that fails is listed with its "
                    "error, the others complete) and the models into OUT/models/, with the "
                    "aggregate (mean, std, min, max of every metric over the seeds and folds "
                    "of each record, algorithm and section) in results.json and --report. "
                    "Same answer whatever the number of workers, and as --serial. Progress: a "
                    "bar on stderr when it is a terminal, and the dashboard's address.",
        epilog=SPEC_HELP)
    p.add_argument("spec", help="the batch spec (JSON)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (results.parquet, results.json, models/)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of a running dask scheduler (e.g. tcp://127.0.0.1:8786); "
                        "default: a LocalCluster in this process")
    g.add_argument("--serial", action="store_true",
                   help="no Dask: run the tasks one after the other in this process")
    p.add_argument("--workers", type=int, default=None,
                   help="LocalCluster workers (default: one per core)")
    add_outputs(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from cdam_core.fleet.spec import load_spec
    if args.workers is not None and args.workers < 1:
        raise CliError(f"--workers: must be >= 1, got {args.workers}")
    spec = load_spec(args.spec)        # a bad spec: exit 2 before any folder is created
    check_io(inputs=[("SPEC", args.spec)], files=[("--json", args.json)],
             folders=[("--out", args.out)])
    if args.report is not None:
        check_io(inputs=[("SPEC", args.spec)], files=[("--json", args.json)],
                 folders=[("--report", args.report)])
    tasks = spec.tasks()
    from cdam_core.fleet.graph import local_cluster, run_batch
    t0 = time.perf_counter()
    if args.serial:
        where = "serial, this process"
        note(args, f"{len(tasks)} task(s), {where}")
        rows = run_batch(spec, args.out, progress=show_progress(args))
    else:
        import logging

        from dask.distributed import Client
        logging.getLogger("distributed").setLevel(logging.ERROR)   # our notes, not its log
        # Under load Dask's teardown can time out closing an internal future, and asyncio logs
        # "Future exception was never retrieved ... TimeoutError" when that future is collected
        # (spurious errors on LocalCluster.close: dask/distributed#2273, #8775; seen once here in
        # CI at load 2): no result of ours (every row is written before the close), so not on the
        # user's stderr. Task errors are rows of the table, not log records.
        for name in ("asyncio", "tornado.application"):
            logging.getLogger(name).setLevel(logging.CRITICAL)
        cluster = None
        if args.scheduler:
            try:
                client = Client(args.scheduler, timeout="10s")
            except (OSError, TimeoutError) as exc:
                raise CliIOError(f"--scheduler: cannot reach {args.scheduler} "
                                 f"({' '.join(str(exc).split())})") from None
        else:
            cluster = local_cluster(spec.command, args.workers)
            client = Client(cluster)
        try:
            if args.scheduler and not client.scheduler_info()["workers"]:
                note(args, f"no worker at {args.scheduler} yet: waiting up to 60 s for one "
                           f"(the tasks wait for workers anyway)")
                try:
                    client.wait_for_workers(1, timeout=60)
                except TimeoutError:
                    pass
            workers = client.scheduler_info()["workers"].values()
            where = (f"{len(workers)} worker(s), {sum(w.get('nthreads', 1) for w in workers)} "
                     f"thread(s), "
                     + (f"scheduler {args.scheduler}" if args.scheduler else "LocalCluster"))
            note(args, f"{len(tasks)} task(s) on {where}; dashboard: {client.dashboard_link}")
            rows = run_batch(spec, args.out, client, progress=show_progress(args))
        except KeyboardInterrupt:
            # the rows that completed are written; worker threads still inside a native loop
            # see no signal: ask them to stop before the cluster and the interpreter shut down
            _core.cancel_native_loops()
            raise
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    seconds = time.perf_counter() - t0
    failed = [r for r in rows if r["status"] != "ok"]
    print(f"{len(rows) - len(failed)} of {len(rows)} task(s) done in {seconds:.1f} s; table: "
          f"{args.out}/results.parquet")
    for r in failed:
        print(f"  {r['task']}: {r['status']}: {r['error']}")
    if args.json or args.report:
        from cdam_core.fleet.graph import results_document
        doc = {**results_document(spec, rows), "seconds": seconds, "workers": where}
        if args.json:
            write_json(args.json, doc)
            note(args, f"results: {args.json}")
        if args.report:
            from cdam_core.fleet.summary import write_report
            md, _ = write_report(args.report, {"status": doc["status"], **doc["summary"]},
                                 title=f"cdam batch: {Path(args.spec).name}",
                                 command=spec.command, source=spec.source, seconds=seconds,
                                 workers=where,
                                 table=os.path.relpath(args.out, args.report))
            note(args, f"report: {md}")
    return 1 if failed else 0

