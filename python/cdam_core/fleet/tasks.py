"""One batch task, run where Dask puts it: the worker reads its own record(s) and hands back
only a result row (and the fitted model, small), never the data.

A task that fails (a corrupt record, a bad column, a diverging fit) returns a row with
``status`` "error" and the error's one-line message; it never raises, so the other tasks
complete. Metric columns are the nested results flattened with dots, e.g.
``test.free_run.q1.r`` (identify, paper), ``k_step.X.rmse`` (evaluate),
``group_rmse.arx.attitude.h50`` (crossfold), ``error_final.tau.rmse`` (residual).
"""
from __future__ import annotations

import json
import os
import sys
import threading
import time

from cdam_core.fleet.spec import PAPER_OPTIONS, Task

__all__ = ["run_task", "flatten", "one_blas_thread", "worker_malloc"]

CROSSFOLD_HORIZONS = (1, 10, 25, 50)


def flatten(d: dict, prefix: str = "") -> dict:
    """{"a": {"b": 1}} -> {"a.b": 1}; lists and strings are kept as they are."""
    out = {}
    for k, v in d.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(flatten(v, name + "."))
        else:
            out[name] = v
    return out


_KEPT: list = []


def one_blas_thread():
    """A context in which numpy's BLAS runs on one thread in this process (threadpoolctl).

    Why: numpy's least squares (the hybrid's ARX part, the ARX baselines) give results that
    differ in the last bits with the number of BLAS threads, and Dask's worker processes run
    with one (the nanny sets OPENBLAS_NUM_THREADS=1), so every task runs with one, wherever it
    runs: --serial, threads in this process, a LocalCluster, a hand-started cluster. The cores
    are filled by the workers, not by BLAS. Serial commands compare bit for bit when run with
    OPENBLAS_NUM_THREADS=1 (README).
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:                 # pragma: no cover - a dependency
        from contextlib import nullcontext
        return nullcontext()
    return threadpool_limits(1, user_api="blas")


def _pin_blas() -> None:
    """One BLAS thread for good in a worker process that has more (a worker started without
    the nanny's environment); a no-op inside :func:`one_blas_thread` (--serial, threads)."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:                 # pragma: no cover
        return
    if any(i.get("num_threads", 1) != 1 for i in threadpool_info() if i["user_api"] == "blas"):
        _KEPT.append(one_blas_thread())


_MALLOC_DONE: list = []
MMAP_THRESHOLD = 32 * 1024 * 1024      # glibc's own ceiling for its dynamic mmap threshold


def worker_malloc() -> bool:
    """Where MALLOC_TRIM_THRESHOLD_ is set (Dask's nanny sets 65536 in every worker it
    starts, `dask worker` by hand included) and MALLOC_MMAP_THRESHOLD_ is not, set glibc's
    mmap threshold to 32 MiB and its trim threshold to 64 MiB in this process (mallopt), once:
    where glibc's own dynamic thresholds end up for large arrays; True if set.

    Why: setting the trim threshold freezes glibc's mmap threshold at 128 KiB (mallopt(3):
    any of them set disables the dynamic adjustment), so every numpy temporary over 128 KiB
    is a fresh mmap whose pages fault in again, and a 64 KiB trim hands the heap's top back
    after each. The crossfold's multisine fold spent 11.0 s of system time so, 1.7 s with
    glibc's defaults. The cost: up to 64 MiB of freed heap kept by a worker. A no-op off
    glibc."""
    if _MALLOC_DONE:
        return _MALLOC_DONE[0]
    done = False
    if ("MALLOC_TRIM_THRESHOLD_" in os.environ and "MALLOC_MMAP_THRESHOLD_" not in os.environ
            and sys.platform.startswith("linux")):
        try:
            import ctypes
            libc = ctypes.CDLL("libc.so.6")
            done = (bool(libc.mallopt(-3, MMAP_THRESHOLD))       # M_MMAP_THRESHOLD
                    and bool(libc.mallopt(-1, 2 * MMAP_THRESHOLD)))  # M_TRIM_THRESHOLD
        except (OSError, AttributeError):                    # pragma: no cover - not glibc
            done = False
    _MALLOC_DONE.append(done)
    return done


def run_task(task: Task) -> dict:
    """{"row": {task fields, status, error, seconds, metrics...}, "model_file": the text of
    the fitted model's file (``models.file.save_model``, written here: the worker ships back
    the file, never the model object) or None}. Runs with one BLAS thread (_pin_blas) and,
    in a Dask worker, glibc's thresholds reset (worker_malloc)."""
    _pin_blas()
    worker_malloc()
    row = {"task": task.key, "command": task.command, "record": task.record,
           "algorithm": task.algorithm, "seed_index": task.seed_index, "seed": task.seed,
           "fold": None if task.fold is None else str(task.fold), "section": task.section}
    t0 = time.perf_counter()
    text = None
    try:
        metrics, model, meta = RUNNERS[task.command](task)
        if model is not None:
            text = _model_text(model, meta)
        row.update(status="ok", error=None)
        row.update(flatten(metrics))
    except Exception as exc:     # noqa: BLE001 - reported in the table; the others go on
        msg = " ".join(str(exc).split()) or type(exc).__name__
        row.update(status="error", error=f"{type(exc).__name__}: {msg}")
    row["seconds"] = time.perf_counter() - t0
    return {"row": row, "model_file": text}


def _model_text(model, meta: dict) -> str:
    """The model file's text (save_model into a scratch folder, read back)."""
    import tempfile
    from pathlib import Path

    from cdam_core.models.file import save_model
    with tempfile.TemporaryDirectory(prefix="cdam-batch-") as d:
        path = Path(d) / "model.json"
        save_model(path, model, **meta)
        return path.read_text(encoding="utf-8")


def _read(task: Task, inputs, outputs):
    from cdam_core.record.columns import parse_column_map
    from cdam_core.record.stack import stack_records
    o = task.options
    return stack_records(list(task.records), inputs=inputs, outputs=outputs,
                         mapping=parse_column_map(o["map"], "spec.options.map"), nan=o["nan"],
                         loader=o["loader"])


def fold_rows(n: int, fold: int, folds: int, split: float) -> tuple[slice, slice]:
    """(training rows, test rows) of ``fold`` (spec module doc: split, or forward chaining)."""
    if folds == 1:
        cut = int(round(n * split))
        train, test = slice(0, cut), slice(cut, n)
    else:
        edge = [int(round(n * k / (folds + 1))) for k in range(folds + 2)]
        train, test = slice(0, edge[fold + 1]), slice(edge[fold + 1], edge[fold + 2])
    if train.stop - train.start < 10 or test.stop - test.start < 10:
        raise ValueError(f"fold {fold}: fewer than 10 training or test samples in {n}")
    return train, test


def _identify(task: Task):
    from cdam_core.evaluate.scores import evaluate
    from cdam_core.identify.pipelines import IdentifyConfig, identify, preprocess
    o = task.options
    st = _read(task, o["inputs"], o["outputs"])
    if len(st.lengths) > 1:
        raise ValueError(f"{task.record}: {len(st.lengths)} segments; a batch identify task "
                         f"trains on one contiguous record")
    train, test = fold_rows(len(st.t), int(task.fold), o["folds"], o["split"])
    cfg = IdentifyConfig(hidden=o["hidden"], narx=None if o["narx"] is None else tuple(o["narx"]),
                         smoothing_passes=o["smoothing"], iterations=o["iterations"],
                         population=o["population"], lm_epochs=o["epochs"], lm_goal=o["goal"],
                         model=o["model"], features=o["features"], threads=o["threads"])
    Us, Ys = preprocess(st.U[train], st.Y[train], cfg.smoothing_passes)
    run = identify(task.algorithm, Us, Ys, seed=task.seed, config=cfg, preprocessed=True)
    scores = evaluate(run.model, st.U[test], st.Y[test], st.outputs,
                      smoothing_passes=cfg.smoothing_passes, k=o["horizon"])
    metrics = {"fitness": run.fitness, "final_mse": run.final_mse,
               "optimiser_mse": run.optimiser_mse, "evaluations": run.evaluations,
               "train_rows": train.stop - train.start, "test_rows": test.stop - test.start,
               "test": scores}
    meta = {"inputs": st.inputs, "outputs": st.outputs,
            "smoothing_passes": cfg.smoothing_passes,
            "meta": {"batch_task": task.key, "algorithm": task.algorithm, "seed": task.seed,
                     "fold": task.fold, "record": task.record}}
    return metrics, run.model, meta


def _evaluate(task: Task):
    from cdam_core.evaluate.scores import evaluate
    from cdam_core.models.file import read_model_file
    mf = read_model_file(task.model_file)
    st = _read(task, mf.inputs, mf.outputs)
    scores = evaluate(mf.model, st.U, st.Y, mf.outputs, smoothing_passes=mf.smoothing_passes,
                      k=task.options["horizon"], segments=st.lengths)
    return {"rows": int(len(st.t)), "segments": len(st.lengths), **scores}, None, None


def _crossfold(task: Task):
    from cdam_core.evaluate.crossfold import cross_trajectory_fold
    h = task.options["horizon"] or 50
    fold = cross_trajectory_fold(list(task.records), task.fold, horizon=h)
    sc = fold.scores
    names = [g.name for g in sc.groups]
    metrics = {"arx_orders": ",".join(map(str, fold.orders)),
               "test_files": len(fold.test_files), "train_files": len(fold.train_files)}
    for key in ("group_rmse", "group_mae"):
        for pred, arr in getattr(sc, key).items():
            for h_ in CROSSFOLD_HORIZONS:
                if h_ in sc.horizons:
                    for j, g in enumerate(names):
                        metrics[f"{key}.{pred}.{g}.h{h_}"] = float(arr[sc.horizons.index(h_), j])
    return metrics, None, None


_PAPER_LOCK = threading.Lock()
_PAPER_CACHE: dict = {}


def _paper_setup(task: Task):
    """(PaperConfig, PaperData, identify config) of a paper task's section. The flights are
    simulated and the section set up (the hybrid's structure search) once per worker process
    and kept for its next tasks (both deterministic: every worker gets `cdam paper`'s)."""
    from cdam_core.paper.records import prepare_data, simulate_records
    from cdam_core.paper.runner import PaperConfig, section_setup
    cfg = PaperConfig(seeds=1, algos=(task.algorithm,),
                      **{PAPER_OPTIONS[k]: v for k, v in task.options.items()})
    key = json.dumps({k: v for k, v in cfg.to_dict().items() if k not in ("seeds", "algos")},
                     sort_keys=True)
    with _PAPER_LOCK:
        if key not in _PAPER_CACHE:
            if len(_PAPER_CACHE) >= 4:
                _PAPER_CACHE.clear()
            records = simulate_records(cfg.flight_seed, cfg.duration, cfg.effects or None)
            _PAPER_CACHE[key] = {"data": prepare_data(records, cfg.smoothing, cfg.rate)}
        entry = _PAPER_CACHE[key]
        if task.section not in entry:
            narx, model = {"static": (None, "bp"), "narx": (cfg.narx, "bp"),
                           "hybrid": (None, "hybrid")}[task.section]
            entry[task.section] = (section_setup(entry["data"], cfg, narx, model), model)
    (icfg, structure), model = entry[task.section]
    return cfg, entry["data"], icfg, model


def _paper(task: Task):
    from cdam_core.paper.runner import run_seed
    cfg, data, icfg, model = _paper_setup(task)
    run, fitted, _ = run_seed(data, cfg, icfg, task.algorithm, task.seed, label=task.section,
                              model=model)
    metrics = {k: v for k, v in run.items()
               if k not in ("seed", "curve_mse", "lm_mse", "metrics")}
    metrics.update(run["metrics"])           # test.one_step.q1.r, validation.free_run...
    meta = {"inputs": data.inputs, "outputs": data.outputs, "smoothing_passes": cfg.smoothing,
            "meta": {"batch_task": task.key, "algorithm": task.algorithm, "seed": task.seed,
                     "section": task.section, "flight_seed": cfg.flight_seed,
                     "rate_hz": data.rate,
                     "note": f"trained on the simulated flights smoothed at 1 kHz and "
                             f"decimated to {data.rate:g} Hz (cdam paper)"}}
    return metrics, fitted, meta


def _residual(task: Task):
    """`cdam residual`'s analysis on one record: the declared model's fit, the effects found,
    the errors before and after (report.residual.to_json's numbers) and the final model."""
    import numpy as np

    from cdam_core.models.greybox.effects import LIBRARY
    from cdam_core.models.greybox.registry import get_model
    from cdam_core.record.dataset import read_dataset
    from cdam_core.report.residual import to_json
    from cdam_core.residual import analyse
    from cdam_core.residual.benchmark import greybox_of
    o = task.options
    gm = get_model(o["model"])
    mapping = dict(gm.defaults)
    for k in (o["map"] or {}):
        if k not in gm.signals:
            raise ValueError(f"options.map: {o['model']} has no signal {k!r} "
                             f"(signals: {', '.join(gm.signals)})")
    mapping.update(o["map"] or {})
    inputs = list(o["inputs"] or [])
    ds = read_dataset(task.record, inputs=inputs or None, outputs=o["outputs"] or None)
    for name, col in mapping.items():
        if col not in ds.columns:
            raise ValueError(f"options.map: column {col!r} (for {name}) not in {task.record}; "
                             f"columns: {', '.join(ds.columns)}")
    signals = {name: ds.column(col) for name, col in mapping.items()}
    extra = {c: ds.column(c) for c in inputs if c not in set(mapping.values())}
    model_meta = (getattr(ds, "meta", None) or {}).get("model")
    model_meta = model_meta if isinstance(model_meta, dict) else {}
    declared = [e for e in (model_meta.get("effects") or []) if e in LIBRARY]
    sel = analyse(o["model"], ds.t, signals, extra=extra or None, cutoff_hz=o["cutoff"],
                  alpha=o["alpha"], free_run=o["free_run"], fixed=o["fixed"] or None,
                  declared=declared, keep_terms=list(model_meta.get("terms") or []),
                  estimator=o.get("estimator", "auto"),
                  stick_slip=o.get("stick_slip", "auto"),
                  units={name: u for name, col in mapping.items() if (u := ds.units.get(col))})
    js = to_json(sel)
    metrics = {"effects_found": len(js["findings"]),
               "effects": ",".join(f"{f['effect']}@{f['channel']}" for f in js["findings"]),
               "complete": bool(js["complete"]),
               "declared_error": js["declared_error"], "error_final": js["error_final"],
               "final_parameters": js["final_parameters"]}
    final = sel.final
    g = greybox_of(final, float(np.mean(np.diff(ds.t))))
    meta = {"inputs": [mapping[i] for i in final.model.inputs] + list(g.extra_columns),
            "outputs": [mapping[p] for p in final.model.positions],
            "meta": {"source": task.record, "command": "cdam batch (residual)",
                     "effects": [e.key for e in final.effects], "batch_task": task.key}}
    return metrics, g, meta


RUNNERS = {"identify": _identify, "evaluate": _evaluate, "crossfold": _crossfold,
           "residual": _residual, "paper": _paper}
