"""batch_scaling: `cdam batch` throughput with 1 and 2 Dask workers on one small spec.

The spec: 4 simulated records (experiment ii, 2 s at 1 kHz, 6 inputs, 8 outputs) x IBOA and BP
x 3 seeds = 24 identify tasks (static 6-20-8 network, g = 20, Tmax = 50, 50 LM epochs, one
core thread a task). Run serially in this process (the reference), then on a LocalCluster
of 1 and 2 workers, both as threads in one process and as single-threaded processes; ratio =
tasks per second with 2 workers over 1 (processes). Every run's table is checked equal to the
serial one (seconds aside); each run's mean task seconds shows how much the workers slowed
each other (on a shared 2-core machine the load average decides the ratio). The on-paper figures for N machines: task count, mean per-task
seconds, what is shipped to a worker (the pickled task: paths and options, never data) and
back (the pickled row and model), and the records' size on disk (what each worker reads).
"""
from __future__ import annotations

import json
import os
import pickle
import tempfile
import time
from pathlib import Path


def _records(folder: Path):
    import cdam_core
    from cdam_core.record.dataset import write_dataset
    for k in range(4):
        ds = cdam_core.simulate_flight(experiment="ii", seed=k + 1, duration=2.0)
        write_dataset(folder / f"rec{k}.csv", ds)


def _warm():
    import cdam_core.evaluate.scores  # noqa: F401
    import cdam_core.identify.pipelines  # noqa: F401
    import cdam_core.record.stack  # noqa: F401


def _table(out):
    import pandas as pd
    return pd.read_parquet(Path(out) / "results.parquet").drop(columns="seconds")


def batch_scaling() -> dict:
    from dask.distributed import Client, LocalCluster

    from cdam_core.fleet.graph import run_batch
    from cdam_core.fleet.spec import load_spec
    from cdam_core.fleet.tasks import run_task
    res = {"load_1min": round(os.getloadavg()[0], 2)}
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        (d / "recs").mkdir()
        _records(d / "recs")
        (d / "spec.json").write_text(json.dumps({
            "command": "identify", "records": ["recs/*.csv"], "algorithms": ["iboa", "bp"],
            "seeds": 3, "options": {"hidden": 20, "iterations": 50, "population": 20,
                                    "epochs": 50, "goal": 0.0, "threads": 1}}))
        spec = load_spec(d / "spec.json", base=d)
        tasks = spec.tasks()
        res["tasks"] = len(tasks)
        t = time.perf_counter()
        rows = run_batch(spec, d / "serial")
        res["serial_seconds"] = time.perf_counter() - t
        ref = _table(d / "serial")
        res["per_task_seconds"] = sum(r["seconds"] for r in rows) / len(rows)
        res["to_worker_bytes"] = len(pickle.dumps(tasks[0]))
        back = run_task(tasks[0])
        res["from_worker_bytes"] = len(pickle.dumps(back))
        res["records_bytes"] = sum(p.stat().st_size for p in (d / "recs").iterdir())
        equal = True
        for kind, processes in (("threads", False), ("processes", True)):
            for n in (1, 2):
                kw = (dict(n_workers=n, threads_per_worker=1) if processes
                      else dict(n_workers=1, threads_per_worker=n))
                with LocalCluster(processes=processes, dashboard_address=":0", **kw) as cl, \
                        Client(cl) as c:
                    c.run(_warm)            # the imports, once per worker process
                    t = time.perf_counter()
                    got = run_batch(spec, d / f"{kind}{n}", c)
                    s = time.perf_counter() - t
                res[f"{kind}_{n}_task_seconds"] = sum(r["seconds"] for r in got) / len(got)
                res[f"{kind}_{n}_seconds"] = s
                res[f"{kind}_{n}_tasks_per_s"] = len(tasks) / s
                equal = equal and _table(d / f"{kind}{n}").equals(ref)
        res["equal_to_serial"] = equal
    res["seconds"] = res["processes_2_seconds"]
    res["ratio"] = res["processes_2_tasks_per_s"] / res["processes_1_tasks_per_s"]
    res["threads_ratio"] = res["threads_2_tasks_per_s"] / res["threads_1_tasks_per_s"]
    return res


BENCHMARKS = {"batch_scaling": batch_scaling}
