"""Run a batch's tasks on ``dask.distributed`` (or serially, in this process) and write the
table and the models as the results arrive.

Tasks are submitted as plain futures, one per task (no shared intermediate: each task reads
its own record on its worker), keyed by the task's name, a bounded window of them at a time;
the client receives only the result rows and the fitted models. Rows are written in task
order whatever the order they finish in, so the table does not depend on the number of
workers.

Threads or processes (``WORKERS``): identify spends its time in the C++ core's optimiser and
Levenberg-Marquardt loops, which release the GIL (``gil_scoped_release`` in
cpp/bindings/optim.cpp and network.cpp), so threads in one process run its tasks side by side;
evaluate's and crossfold's k-step rollouts are numpy calls on small matrices in Python loops
that hold the GIL, so they get one single-threaded process per core; so do residual (scipy
least squares and the blocked cross-validation, Python-heavy) and paper (its tasks evaluate
every seed one-step, k-step and free run on two records, and the hybrid section searches its
structure with numpy; one process also keeps its own simulated flights for its next tasks).
Either way the answer is the serial one: the seeds come from the task, the core's threaded
sums are fixed-chunk (docs/DESIGN.md, "Same bits whatever the thread count"), and numpy's
BLAS runs on one thread in every task (``tasks.one_blas_thread``).

Output folder: ``results.parquet`` and ``results.json`` (the spec, the task count, the
aggregate of ``summary`` and one row per task: record, algorithm, seed, fold, section, model
file, status, error, seconds, every metric) and
``models/TASK.json`` (``cdam_core.models.file.save_model``, written by the worker and shipped
back as text). Cancelled or interrupted, the rows that completed are written and the others
are listed with status "cancelled".
"""
from __future__ import annotations

import os
import sys
import uuid
from pathlib import Path

from cdam_core.base.jsonio import atomic_target, write_json_atomic, write_text_atomic
from cdam_core.fleet.spec import BatchSpec
from cdam_core.fleet.summary import summarise_rows
from cdam_core.fleet.tasks import one_blas_thread, run_task

__all__ = ["run_batch", "local_cluster", "write_table", "results_document", "WORKERS"]

WORKERS = {"identify": "threads", "evaluate": "processes", "crossfold": "processes",
           "residual": "processes", "paper": "processes"}
FIRST = ("task", "command", "record", "algorithm", "seed_index", "seed", "fold", "section",
         "model", "status", "error", "seconds")


def local_cluster(command: str, n_workers: int | None = None):
    """An in-process ``LocalCluster`` sized to the machine: one single-threaded worker process
    per core, or (identify) one process with a thread per core (``WORKERS``)."""
    from dask.distributed import LocalCluster
    n = n_workers or os.cpu_count() or 1
    if WORKERS[command] == "threads":
        return LocalCluster(n_workers=1, threads_per_worker=n, processes=False,
                            dashboard_address=":0")
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_ in its workers (and in this process's
    # environment): every task undoes its cost (tasks.worker_malloc)
    return LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                        dashboard_address=":0")


def _cancelled_row(task) -> dict:
    return {"task": task.key, "command": task.command, "record": task.record,
            "algorithm": task.algorithm, "seed_index": task.seed_index, "seed": task.seed,
            "fold": None if task.fold is None else str(task.fold), "section": task.section,
            "status": "cancelled",
            "error": "cancelled before it completed"}


def run_batch(spec: BatchSpec, out, client=None, *, progress: bool = False, stop=None,
              on_row=None, window: int | None = None) -> list[dict]:
    """Run every task of ``spec``; write ``out`` (module doc) and return the rows in task order.

    ``client``: a ``dask.distributed.Client`` (None: serially in this process). ``stop``: a
    ``threading.Event``; once set, the tasks not yet finished are cancelled. ``on_row(row)``
    is called as each row arrives. An interrupt (Ctrl-C) cancels the rest too; the rows that
    completed are written before it propagates.

    Memory stays bounded whatever the task count: at most ``window`` tasks (default: twice the
    cluster's threads) are submitted at a time, the next one as each result arrives, and each
    result is released on the cluster once its row is written (the model goes to its file at
    once); the client keeps the rows only.
    """
    out = Path(out)
    (out / "models").mkdir(parents=True, exist_ok=True)
    tasks = spec.tasks()
    rows: dict[int, dict] = {}
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(tasks), desc="batch", unit="task", file=sys.stderr, leave=False)

    def take(task, result):
        row = _save(out, task, result)
        rows[task.index] = row
        if bar is not None:
            bar.update()
        if on_row is not None:
            on_row(row)

    live: dict = {}                   # Dask key -> (future, task) submitted, not yet taken
    blas = one_blas_thread()          # tasks run here too (--serial, threads)
    blas.__enter__()
    try:
        if client is None:
            for task in tasks:
                if stop is not None and stop.is_set():
                    break
                take(task, run_task(task))
        else:
            from dask.distributed import as_completed
            todo = iter(tasks)
            run_id = uuid.uuid4().hex[:8]     # keys unique to this run, even on a shared cluster
            done = as_completed()

            def top_up():
                """Submit tasks until ``window`` (or twice the threads of the workers there
                now: a worker that joins later gets work) are in flight."""
                size = window or max(2, 2 * sum(client.nthreads().values()))
                while len(live) < size:
                    task = next(todo, None)
                    if task is None:
                        return
                    fut = client.submit(run_task, task, key=f"cdam-batch-{run_id}-{task.key}",
                                        pure=False)
                    live[fut.key] = (fut, task)
                    done.add(fut)

            top_up()
            for fut in done:
                task = live.pop(fut.key)[1]
                if fut.status == "finished":
                    take(task, fut.result())
                elif fut.status == "error":       # the worker died (the task itself never raises)
                    exc = fut.exception()
                    take(task, {"row": {**_cancelled_row(task), "status": "error",
                                        "error": f"{type(exc).__name__}: {exc}"},
                                "model_file": None})
                fut.release()                     # its result leaves the worker's memory
                if stop is not None and stop.is_set():
                    break
                top_up()
            for fut, task in list(live.values()):   # finished meanwhile: kept, not cancelled
                if fut.status == "finished" and task.index not in rows:
                    take(task, fut.result())
    finally:
        if live:
            client.cancel([f for f, _ in live.values() if not f.done()])
        if bar is not None:
            bar.close()
        blas.__exit__(None, None, None)
        table = [rows[t.index] if t.index in rows else _cancelled_row(t) for t in tasks]
        write_table(out, spec, table)
    return table


def _save(out: Path, task, result) -> dict:
    row = dict(result["row"])
    row["model"] = None
    if result.get("model_file") is not None:
        name = f"models/{task.key}.json"
        write_text_atomic(out / name, result["model_file"])
        row["model"] = name
    return row


def write_table(out, spec: BatchSpec, rows: list[dict]) -> None:
    """``results.parquet`` (one row per task; columns FIRST, then the metrics sorted) and
    ``results.json``, each written atomically."""
    import pandas as pd
    out = Path(out)
    metrics = sorted({k for r in rows for k in r} - set(FIRST))
    df = pd.DataFrame([{k: r.get(k) for k in (*FIRST, *metrics)} for r in rows],
                      columns=[*FIRST, *metrics])
    # the same column types whatever the rows (all failed, none failed, a cancelled batch)
    for col in FIRST:
        df[col] = df[col].astype("Int64" if col in ("seed_index", "seed") else
                                 "float64" if col == "seconds" else "string")
    with atomic_target(out / "results.parquet") as tmp:
        df.to_parquet(tmp, engine="pyarrow", index=False)
    write_json_atomic(out / "results.json", results_document(spec, rows))


def results_document(spec: BatchSpec, rows: list[dict]) -> dict:
    """results.json: the spec, the task count, the status counts, the aggregate
    (``summary.summarise_rows``) and every row."""
    summary = summarise_rows(rows)
    return {"spec": spec.source, "command": spec.command, "tasks": len(rows),
            "status": summary["status"], "summary": {"groups": summary["groups"],
                                                     "failed": summary["failed"]},
            "rows": rows}
