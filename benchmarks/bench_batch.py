"""batch_scaling: `cdam batch` throughput with 1 and 2 Dask workers on one small spec.

The spec: 4 simulated records (experiment ii, 2 s at 1 kHz, 6 inputs, 8 outputs) x IBOA and BP
x 3 seeds = 24 identify tasks (static 6-20-8 network, g = 20, Tmax = 50, 50 LM epochs, one
core thread a task). Run serially in this process (the reference), then on a LocalCluster
of 1 and 2 workers, both as threads in one process and as single-threaded processes; ratio =
tasks per second with 2 workers over 1 (processes). Every run's table is checked equal to the
serial one (seconds aside); each run's mean task seconds shows how much the workers slowed
each other (on a shared 2-core machine the load average decides the ratio).

On paper, how a spec spreads over N machines of C cores (``spread``): task count, mean
per-task seconds, a worker's peak memory (one task run in a fresh process: its resident set
after the imports, and the peak once the task ran), what is shipped to a worker (the task as
Dask pickles it, cloudpickle: paths and options, never data) and back (the row and the
model), the records' size on disk (what each worker reads), and the wall time if the tasks
spread evenly, ceil(tasks / (N C)) x mean task seconds (no scheduling overhead counted: about
1 ms a task on Dask). The same for the paper's 10-seed spec
(docs/examples/batch/paper_seeds.json: 90 tasks, nothing read: each worker simulates the
flights), from one task of each section.
"""
from __future__ import annotations

import json
import math
import os
import cloudpickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_RSS = """
import json, resource, sys
import cloudpickle
from cdam_core.fleet.spec import load_spec
from cdam_core.fleet.tasks import run_task
import cdam_core.evaluate.scores, cdam_core.identify.pipelines, cdam_core.paper.runner
spec = load_spec(sys.argv[1], base=sys.argv[2])
task = spec.tasks()[int(sys.argv[3])]
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = __import__("time").perf_counter()
res = run_task(task)
s = __import__("time").perf_counter() - t
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"rss_after_imports_mb": before / 1024, "rss_peak_mb": after / 1024,
                  "seconds": s, "status": res["row"]["status"],
                  "from_worker_bytes": len(cloudpickle.dumps(res))}))
"""


def _worker_memory(spec_path, base, index) -> dict:
    """One task in a fresh process (the modules a worker imports first): its peak RSS."""
    r = subprocess.run([sys.executable, "-c", _RSS, str(spec_path), str(base), str(index)],
                       capture_output=True, text=True, env=os.environ.copy(), timeout=900)
    if r.returncode:
        raise RuntimeError(r.stderr[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def spread(tasks: int, task_seconds: float, machines=(1, 2, 4, 8), cores: int = 2) -> dict:
    """Wall seconds if ``tasks`` of ``task_seconds`` spread evenly over N machines of
    ``cores`` single-threaded workers."""
    return {f"{n}x{cores}": math.ceil(tasks / (n * cores)) * task_seconds for n in machines}


def paper_spread() -> dict:
    """The 10-seed paper spec on paper: one task per section (iboa, seed 0) run here, each in a
    fresh process (its memory; the hybrid's includes its structure search, once a worker)."""
    from cdam_core.fleet.spec import load_spec
    path = ROOT / "docs" / "examples" / "batch" / "paper_seeds.json"
    spec = load_spec(path)
    tasks = spec.tasks()
    out = {"tasks": len(tasks), "to_worker_bytes": len(cloudpickle.dumps(tasks[0])),
           "records_bytes": 0, "sections": {}}
    for sec in spec.sections:
        i = next(t.index for t in tasks if t.section == sec)
        out["sections"][sec] = _worker_memory(path, ".", i)
    per = [out["sections"][t.section]["seconds"] for t in tasks]
    out["mean_task_seconds"] = sum(per) / len(per)
    out["cpu_seconds"] = sum(per)
    out["spread_seconds"] = spread(len(tasks), out["mean_task_seconds"])
    return out


def _records(folder: Path):
    import cdam_core
    from cdam_core.record.dataset import write_dataset
    for k in range(4):
        ds = cdam_core.simulate_flight(experiment="ii", seed=k + 1, duration=2.0)
        write_dataset(folder / f"rec{k}.csv", ds)


def _warm():
    import importlib
    for name in ("cdam_core.evaluate.scores", "cdam_core.identify.pipelines",
                 "cdam_core.record.stack"):
        importlib.import_module(name)


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
        res["to_worker_bytes"] = len(cloudpickle.dumps(tasks[0]))
        back = run_task(tasks[0])
        res["from_worker_bytes"] = len(cloudpickle.dumps(back))
        res["records_bytes"] = sum(p.stat().st_size for p in (d / "recs").iterdir())
        res["worker_memory"] = _worker_memory(d / "spec.json", d, 0)
        res["spread_seconds"] = spread(len(tasks), res["per_task_seconds"])
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
    res["paper_spec"] = paper_spread()
    return res


BENCHMARKS = {"batch_scaling": batch_scaling}
