"""One batch task, run where Dask puts it: the worker reads its own record(s) and hands back
only a result row (and the fitted model, small), never the data.

A task that fails (a corrupt record, a bad column, a diverging fit) returns a row with
``status`` "error" and the error's one-line message; it never raises, so the other tasks
complete. Metric columns are the nested results flattened with dots, e.g.
``test.free_run.q1.r`` (identify), ``k_step.X.rmse`` (evaluate),
``group_rmse.arx.attitude.h50`` (crossfold).
"""
from __future__ import annotations

import time

from cdam_core.fleet.spec import Task

__all__ = ["run_task", "flatten"]

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


def run_task(task: Task) -> dict:
    """{"row": {task fields, status, error, seconds, metrics...}, "model": Model | None,
    "model_meta": save_model's keywords | None}."""
    row = {"task": task.key, "command": task.command, "record": task.record,
           "algorithm": task.algorithm, "seed_index": task.seed_index, "seed": task.seed,
           "fold": None if task.fold is None else str(task.fold)}
    t0 = time.perf_counter()
    model = meta = None
    try:
        metrics, model, meta = RUNNERS[task.command](task)
        row.update(status="ok", error=None)
        row.update(flatten(metrics))
    except Exception as exc:     # noqa: BLE001 - reported in the table; the others go on
        msg = " ".join(str(exc).split()) or type(exc).__name__
        row.update(status="error", error=f"{type(exc).__name__}: {msg}")
    row["seconds"] = time.perf_counter() - t0
    return {"row": row, "model": model, "model_meta": meta}


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


RUNNERS = {"identify": _identify, "evaluate": _evaluate, "crossfold": _crossfold}
