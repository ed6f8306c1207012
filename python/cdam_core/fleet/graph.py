"""Run a batch's tasks on ``dask.distributed`` (or serially, in this process) and write the
table and the models as the results arrive.

Tasks are submitted as plain futures, one per task (no shared intermediate: each task reads
its own record on its worker), keyed by the task's name; the client receives only the result
rows and the fitted models. Rows are written in task order whatever the order they finish in,
so the table does not depend on the number of workers.

Threads or processes (``WORKERS``): identify spends its time in the C++ core's optimiser and
Levenberg-Marquardt loops, which release the GIL (``gil_scoped_release`` in
cpp/bindings/optim.cpp and network.cpp), so threads in one process run its tasks side by side;
evaluate's and crossfold's k-step rollouts are numpy calls on small matrices in Python loops
that hold the GIL, so they get one single-threaded process per core. Either way the answer is
the serial one: the seeds come from the task, and the core's threaded sums are fixed-chunk
(docs/DESIGN.md, "Same bits whatever the thread count").

Output folder: ``results.parquet`` and ``results.json`` (the spec, the task count and one row
per task: record, algorithm, seed, fold, model file, status, error, seconds, every metric) and
``models/TASK.json`` (``cdam_core.models.file.save_model``). Cancelled or interrupted, the
rows that completed are written and the others are listed with status "cancelled".
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from cdam_core.base.jsonio import atomic_target, write_json_atomic
from cdam_core.fleet.spec import BatchSpec
from cdam_core.fleet.tasks import run_task

__all__ = ["run_batch", "local_cluster", "write_table", "WORKERS"]

WORKERS = {"identify": "threads", "evaluate": "processes", "crossfold": "processes"}
FIRST = ("task", "command", "record", "algorithm", "seed_index", "seed", "fold", "model",
         "status", "error", "seconds")


def local_cluster(command: str, n_workers: int | None = None):
    """An in-process ``LocalCluster`` sized to the machine: one single-threaded worker process
    per core, or (identify) one process with a thread per core (``WORKERS``)."""
    from dask.distributed import LocalCluster
    n = n_workers or os.cpu_count() or 1
    if WORKERS[command] == "threads":
        return LocalCluster(n_workers=1, threads_per_worker=n, processes=False,
                            dashboard_address=":0")
    return LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                        dashboard_address=":0")


def _cancelled_row(task) -> dict:
    return {"task": task.key, "command": task.command, "record": task.record,
            "algorithm": task.algorithm, "seed_index": task.seed_index, "seed": task.seed,
            "fold": None if task.fold is None else str(task.fold), "status": "cancelled",
            "error": "cancelled before it completed"}


def run_batch(spec: BatchSpec, out, client=None, *, progress: bool = False, stop=None,
              on_row=None) -> list[dict]:
    """Run every task of ``spec``; write ``out`` (module doc) and return the rows in task order.

    ``client``: a ``dask.distributed.Client`` (None: serially in this process). ``stop``: a
    ``threading.Event``; once set, the tasks not yet finished are cancelled. ``on_row(row)``
    is called as each row arrives. An interrupt (Ctrl-C) cancels the rest too; the rows that
    completed are written before it propagates.
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

    futures = []
    try:
        if client is None:
            for task in tasks:
                if stop is not None and stop.is_set():
                    break
                take(task, run_task(task))
        else:
            from dask.distributed import as_completed
            futures = client.map(run_task, tasks, key=[f"cdam-batch-{t.key}" for t in tasks],
                                 pure=False)
            by_key = {f.key: t for f, t in zip(futures, tasks)}
            for fut in as_completed(futures):
                task = by_key[fut.key]
                if fut.status == "finished":
                    take(task, fut.result())
                elif fut.status == "error":       # the worker died (the task itself never raises)
                    exc = fut.exception()
                    take(task, {"row": {**_cancelled_row(task), "status": "error",
                                        "error": f"{type(exc).__name__}: {exc}"},
                                "model": None, "model_meta": None})
                if stop is not None and stop.is_set():
                    break
            for fut, task in zip(futures, tasks):   # finished meanwhile: kept, not cancelled
                if fut.status == "finished" and task.index not in rows:
                    take(task, fut.result())
    finally:
        if futures:
            client.cancel([f for f in futures if not f.done()])
        if bar is not None:
            bar.close()
        table = [rows[t.index] if t.index in rows else _cancelled_row(t) for t in tasks]
        write_table(out, spec, table)
    return table


def _save(out: Path, task, result) -> dict:
    row = dict(result["row"])
    row["model"] = None
    if result.get("model") is not None:
        from cdam_core.models.file import save_model
        name = f"models/{task.key}.json"
        save_model(out / name, result["model"], **result["model_meta"])
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
    counts = {s: sum(r.get("status") == s for r in rows) for s in ("ok", "error", "cancelled")}
    write_json_atomic(out / "results.json", {"spec": spec.source, "command": spec.command,
                                             "tasks": len(rows), "status": counts,
                                             "rows": rows})
