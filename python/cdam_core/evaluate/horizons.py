"""Multi-step scores of a saved model of any kind beside the naive (persistence) predictor.

For each horizon h the model predicts every sample from the measured outputs h samples earlier
(``predict(mode="k_step", k=h)``; h = 1 is one-step) over records laid end to end as segments,
so no prediction crosses a seam. The model and the naive predictor y(t) = y(t - h) are scored
on the same rows: in each segment, those from ``max(t0, 1) + h - 1`` on. The free run starts
from each segment's first ``t0`` rows (the naive free run holds the last of them).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cdam_core.base.metrics import output_metrics
from cdam_core.evaluate.groups import Group, group_errors
from cdam_core.models.protocol import Model, segment_bounds

__all__ = ["HorizonScores", "score_horizons", "default_horizons"]


def default_horizons(max_h: int) -> list[int]:
    """Every horizon 1..max_h up to 50 (the nano-drone benchmark's protocol); above that about
    30 log-spaced horizons including 1 and max_h."""
    max_h = int(max_h)
    if max_h < 1:
        raise ValueError(f"horizon: must be >= 1, got {max_h}")
    if max_h <= 50:
        return list(range(1, max_h + 1))
    return sorted({int(round(x)) for x in np.geomspace(1, max_h, 30)} | {1, max_h})


@dataclass
class HorizonScores:
    """RMSE per output at each horizon, one-step and free-run metrics, per predictor."""

    outputs: list[str]
    horizons: list[int]
    rmse: dict[str, np.ndarray] = field(default_factory=dict)   # predictor -> (H, m)
    mae: dict[str, np.ndarray] = field(default_factory=dict)    # predictor -> (H, m)
    free_run: dict[str, dict] = field(default_factory=dict)     # predictor -> output metrics
    rows: list[int] = field(default_factory=list)               # scored rows per horizon
    groups: list[Group] = field(default_factory=list)
    group_rmse: dict[str, np.ndarray] = field(default_factory=dict)  # predictor -> (H, G)
    group_mae: dict[str, np.ndarray] = field(default_factory=dict)   # predictor -> (H, G)

    def group_mae_sum(self, name: str, upto: int = 50):
        """Sum over h = 1..upto of each group's MAE (None unless every such h was scored)."""
        if not set(range(1, upto + 1)) <= set(self.horizons):
            return None
        rows = [self.horizons.index(h) for h in range(1, upto + 1)]
        return self.group_mae[name][rows].sum(axis=0)

    def add(self, other: "HorizonScores", name: str, as_name: str) -> None:
        """Take predictor ``name`` of ``other`` (same outputs, horizons, rows) as ``as_name``."""
        if other.horizons != self.horizons or other.outputs != self.outputs or \
                other.rows != self.rows:
            raise ValueError("other: scored on different outputs, horizons or rows")
        for mine, theirs in ((self.rmse, other.rmse), (self.mae, other.mae),
                             (self.group_rmse, other.group_rmse),
                             (self.group_mae, other.group_mae),
                             (self.free_run, other.free_run)):
            if name in theirs:
                mine[as_name] = theirs[name]

    def to_json(self) -> dict:
        def per(d, names):
            return {k: {o: v[:, j].tolist() for j, o in enumerate(names)} for k, v in d.items()}
        js = {"outputs": self.outputs, "horizons": self.horizons, "rows": self.rows,
              "rmse": per(self.rmse, self.outputs), "mae": per(self.mae, self.outputs),
              "free_run": self.free_run}
        if self.groups:
            names = [g.name for g in self.groups]
            sums = {k: self.group_mae_sum(k) for k in self.group_mae}
            js["groups"] = {g.name: g.to_json() for g in self.groups}
            js["group_rmse"] = per(self.group_rmse, names)
            js["group_mae"] = per(self.group_mae, names)
            js["group_mae_sum_1_50"] = {k: None if v is None else dict(zip(names, v.tolist()))
                                        for k, v in sums.items()}
        return js


def _one_blas_thread():
    """The rollout multiplies many small matrices: BLAS threads only contend for the cores
    (2-3x slower on a busy 2-core machine), so they are limited to one where threadpoolctl
    (a scikit-learn dependency) is installed."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:                 # pragma: no cover
        from contextlib import nullcontext
        return nullcontext()
    return threadpool_limits(1, user_api="blas")


def _scored(rollout, want):
    """The rollout's horizons in ``want``, computed with one BLAS thread."""
    with _one_blas_thread():
        for h, idx, P in rollout:
            if h in want:
                yield h, idx, P


def score_horizons(model: Model, U, Y, outputs, horizons, segments=None,
                   free_run: bool = True, progress=None, groups=(),
                   on_prediction=None, first: int = 1) -> HorizonScores:
    """Score ``model`` and the naive predictor at every horizon (see the module doc).
    ``first``: score from at least this row of each segment as well (the largest t0 of the
    models compared, so that they are all scored on the same rows)."""
    Y = np.asarray(Y, dtype=float)
    bounds = segment_bounds(segments, len(Y))
    start = max(model.t0, 1, int(first))
    out = HorizonScores(list(outputs), [int(h) for h in horizons], groups=list(groups))
    outputs = list(outputs)
    for g in out.groups:
        for c in g.columns:
            if c not in outputs:
                raise ValueError(f"groups: {g.name}: {c!r} is not an output")
    if not out.horizons:
        raise ValueError("horizons: empty")
    for i, h in enumerate(out.horizons):
        if h < 1:
            raise ValueError(f"horizons[{i}]: must be >= 1, got {h}")
    H, G, m = max(out.horizons), len(out.groups), Y.shape[1]
    want = set(out.horizons)
    # per horizon: rows, then sums of squared and absolute errors (model, naive) per output
    # and per group; the rollout gives every horizon in one pass, possibly in chunks
    acc = {h: [0, np.zeros((2, m)), np.zeros((2, m)), np.zeros((2, G)), np.zeros((2, G))]
           for h in want}
    done = 0
    for h, idx, P in _scored(model.rollout(U, Y, H, segments=segments, first=start), want):
        if not np.all(np.isfinite(P)):
            raise ValueError(f"model: the {h}-step prediction diverged (NaN or Inf)")
        a_ = acc[h]
        a_[0] += idx.size
        for j, Q in enumerate((P, Y[idx - h])):
            E = Q - Y[idx]
            a_[1][j] += np.sum(E ** 2, axis=0)
            a_[2][j] += np.sum(np.abs(E), axis=0)
            if G:
                Ge = group_errors(Y[idx], Q, outputs, out.groups)
                a_[3][j] += np.sum(Ge ** 2, axis=0)
                a_[4][j] += np.sum(Ge, axis=0)
        if on_prediction is not None:
            on_prediction(h, idx, P)
        if progress is not None and h == H:
            done = min(done + idx.size, len(Y))
            progress(done, len(Y))
    for h in out.horizons:
        if acc[h][0] == 0:
            raise ValueError(f"horizons: {h} samples is longer than every record")
    out.rows = [int(acc[h][0]) for h in out.horizons]
    stats = {}
    for k, key in ((1, "rmse"), (2, "mae"), (3, "group_rmse"), (4, "group_mae")):
        for j, name in enumerate(("model", "naive")):
            v = np.array([acc[h][k][j] / acc[h][0] for h in out.horizons])
            stats.setdefault(key, {})[name] = np.sqrt(v) if key.endswith("rmse") else v
    out.rmse, out.mae = stats["rmse"], stats["mae"]
    if out.groups:
        out.group_rmse, out.group_mae = stats["group_rmse"], stats["group_mae"]
    if free_run and model.dynamic:
        P = model.predict(U, Y, mode="free_run", segments=segments)
        keep = np.zeros(len(Y), bool)
        hold = np.empty_like(Y)
        for a, b in bounds:
            keep[a + start:b] = True
            hold[a:b] = Y[a + start - 1]
        if np.all(np.isfinite(P[keep])):
            out.free_run["model"] = output_metrics(Y[keep], P[keep], outputs)
        else:
            out.free_run["model"] = {"status": "unavailable", "reason": "the free run diverged"}
        out.free_run["naive"] = output_metrics(Y[keep], hold[keep], outputs)
    return out
