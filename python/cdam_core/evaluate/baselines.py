"""Baselines every comparison carries: persistence (naive), the references ``cdam identify``
prints beside a model, and a least-squares MIMO ARX with chosen orders.

``persistence`` (``cdam paper``): predict y(t) by the last measured y(t - k). A model-free
reference for the dynamic sections: one-step (k = 1) and k-step (k = the horizon
in samples) predictions are only informative where they beat persistence, since at a high
sampling rate consecutive samples of a smooth signal are almost perfectly correlated. Scored
like the models: per segment, the first k rows dropped (no earlier sample), segments pooled.

The ARX baseline (:func:`select_arx`): ``ArxModel`` (raw inputs, least squares) with orders
and delay chosen on training records only: each candidate (na, nb, nk) is fitted on the
training stack and scored on a validation stack (records held out of training) by the k-step
error at a few horizons, relative to the naive predictor on the same rows (so every output or
group weighs alike); the best is refitted on training and validation together. nk >= 1 by
default: the state at t is predicted from inputs up to t - 1, as the nano-drone benchmark's
protocol gives its models.
"""
from __future__ import annotations

import numpy as np

from cdam_core.base.metrics import output_metrics
from cdam_core.evaluate.horizons import score_horizons
from cdam_core.evaluate.kstep import horizon_steps
from cdam_core.evaluate.scores import evaluate
from cdam_core.models.arx import ArxModel
from cdam_core.models.protocol import segment_bounds
from cdam_core.preprocess import smooth_pair

__all__ = ["persistence", "naive_and_arx", "select_arx", "relative_error", "ARX_GRID",
           "validation_records", "VALIDATION_RULES"]

ARX_GRID = tuple((na, nb, nk) for na in (1, 2, 3) for nb in (1, 2, 3) for nk in (1, 2))


#: how training records are split into fit and validation records (``validation_records``)
VALIDATION_RULES = ("per-type", "last")


def validation_records(names, rule: str = "per-type") -> list[int]:
    """Indices of the training records that validate (the others are fitted), chosen by rule,
    never by hand: ``"per-type"``: the last record (by file name) of each type, the type being
    the file name's prefix before the first '_' (``square_20251017_run3`` -> ``square``: the
    nano-drone flights' naming; the cross-trajectory protocol's split,
    ``evaluate.crossfold``); ``"last"``: the last record given. ValueError when no record is
    left to fit."""
    from pathlib import Path

    from cdam_core.record.realdata.nanodrone import trajectory_type

    names = [str(n) for n in names]
    if rule not in VALIDATION_RULES:
        raise ValueError(f"rule: unknown {rule!r}; use {' or '.join(VALIDATION_RULES)}")
    if len(names) < 2:
        raise ValueError(f"records: {len(names)} given; at least two are needed (one fitted, "
                         f"one validating)")
    if rule == "last":
        return [len(names) - 1]
    last = {}
    for i in sorted(range(len(names)), key=lambda i: Path(names[i]).name):
        last[trajectory_type(names[i])] = i
    valid = sorted(last.values())
    if len(valid) == len(names):
        raise ValueError(f"records: every record is the only one of its type "
                         f"({', '.join(sorted(last))}), so none is left to fit; give more "
                         f"records per type, or use the rule 'last'")
    return valid


def persistence(segments, names, rate: float, horizons=()) -> tuple[dict, dict]:
    """Persistence r etc. on a segmented record: ({mode: {output: metrics}},
    {mode: (measured, predicted)}) with modes "one_step" and "k_step_<h>s" per horizon h (s)."""
    if not segments:
        raise ValueError("segments: no segment given")
    steps = {"one_step": 1}
    for h in horizons:
        steps[f"k_step_{float(h):g}s"] = horizon_steps(h, rate)
    metrics, arrays = {}, {}
    for mode, k in steps.items():
        short = [s.name for s in segments if len(s.Y) <= k]
        if short:
            raise ValueError(f"segments: {', '.join(short)} have no more than {k} samples")
        Ym = np.vstack([s.Y[k:] for s in segments])
        Pm = np.vstack([s.Y[:-k] for s in segments])
        metrics[mode] = output_metrics(Ym, Pm, names)
        arrays[mode] = (Ym, Pm)
    return metrics, arrays


def _smoothed(U, Y, bounds, passes):
    """(U, Y) smoothed ``passes`` times, each segment on its own."""
    parts = [smooth_pair(U[a:b], Y[a:b], passes) for a, b in bounds]
    return np.vstack([u for u, _ in parts]), np.vstack([y for _, y in parts])


def naive_and_arx(U, Y, records: dict, names, *, narx=None, smoothing_passes: int = 0,
                  features: str = "raw", segments=None, record_segments=None) -> dict:
    """The references ``cdam identify`` prints beside a model's scores on each record, with the
    model's preprocessing (records smoothed ``smoothing_passes`` times):

    - ``naive``: one step, the last measured output y(t-1); free run, the training mean (no
      measured output is seen after the start, so its r is undefined: None);
    - ``arx``: a least-squares ``ArxModel`` fitted on the training record (U, Y) with the
      model's NARX orders (a static map: y(t) = B u(t) + c, orders (0, 1, 0)) and ``features``,
      scored by :func:`~cdam_core.evaluate.scores.evaluate` like the model.

    ``segments`` (training) and ``record_segments`` ({record: segments}) cut the records
    (lengths or row ranges, as for ``Model.predict``): each segment is smoothed on its own, no
    ARX regressor and no prediction (naive or ARX) crosses a seam, and each segment's first rows
    (no earlier sample) are left out of the scores.

    Returns {"arx_orders": [na, nb, nk], record: {"naive": {mode: metrics}, "arx": {mode:
    metrics}}} with modes "one_step" and "free_run" (``arx`` is {"error": why} when its free
    run diverges).
    """
    orders = tuple(narx) if narx is not None else (0, 1, 0)
    bounds = segment_bounds(segments, len(U))
    Us, Ys = _smoothed(U, Y, bounds, smoothing_passes)
    arx = ArxModel(orders, features=features).fit(Us, Ys, segments=bounds)
    mean = Ys.mean(axis=0)
    out = {"arx_orders": list(orders)}
    for name, (Ur, Yr) in records.items():
        seg = (record_segments or {}).get(name)
        rb = segment_bounds(seg, len(Yr))
        _, Yp = _smoothed(Ur, Yr, rb, smoothing_passes)
        if len(Yp) < 3:
            raise ValueError(f"records: {name} has fewer than 3 samples")
        later = np.zeros(len(Yp), bool)              # rows with an earlier row of their segment
        for a, b in rb:
            later[a + 1:b] = True
        if not later.any():
            raise ValueError(f"records: {name}: no segment has 2 samples")
        prev = np.flatnonzero(later) - 1
        naive = {"one_step": output_metrics(Yp[later], Yp[prev], names),
                 "free_run": output_metrics(Yp, np.broadcast_to(mean, Yp.shape), names)}
        for m in naive["free_run"].values():
            m["r"] = None                                  # a constant: no correlation
        try:
            scores = evaluate(arx, Ur, Yr, names, smoothing_passes=smoothing_passes,
                              segments=seg)
        except ValueError as exc:                  # a diverged free run: said, not scored
            scores = {"error": str(exc)}
        out[name] = {"naive": naive, "arx": scores}
    return out


def relative_error(model, stack, horizons, groups) -> float:
    """Mean over horizons (and groups, else outputs) of the model's MAE over the naive MAE."""
    sc = score_horizons(model, stack.U, stack.Y, stack.outputs, horizons,
                        segments=stack.lengths, free_run=False, groups=groups)
    mae = sc.group_mae if groups else sc.mae
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = mae["model"] / mae["naive"]
    return float(np.mean(np.where(np.isfinite(ratio), ratio, 1.0)))


def select_arx(train, valid, grid=ARX_GRID, horizons=(1, 10, 25, 50), groups=()):
    """The ARX baseline (module doc): (model refitted on ``train`` + ``valid``, chosen
    (na, nb, nk), {candidate: validation score}). ``train``/``valid``: ``record.stack.Stack``s
    of the same inputs and outputs."""
    if train.inputs != valid.inputs or train.outputs != valid.outputs:
        raise ValueError("valid: different inputs or outputs than train")
    grid = [tuple(int(v) for v in g) for g in grid]
    if not grid:
        raise ValueError("grid: no candidate order")
    scores = {}
    for orders in grid:
        try:
            m = ArxModel(orders).fit(train.U, train.Y, segments=train.lengths)
            scores[orders] = relative_error(m, valid, horizons, groups)
        except ValueError:          # a diverging candidate is no candidate
            scores[orders] = float("inf")
    best = min(grid, key=lambda g: (scores[g], g))
    if not np.isfinite(scores[best]):
        raise ValueError("grid: every candidate diverged on the validation records")
    U = np.vstack([train.U, valid.U])
    Y = np.vstack([train.Y, valid.Y])
    model = ArxModel(best).fit(U, Y, segments=list(train.lengths) + list(valid.lengths))
    return model, best, scores
