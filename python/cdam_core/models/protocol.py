"""The one model protocol every identified model follows.

A model maps inputs U (N, i) to outputs Y (N, m). It is fitted with ``fit(U, Y)`` and predicts
with ``predict(U, Y, mode, k, segments)``:

- ``mode="one_step"``: y(t) from the measured outputs before t (a static model ignores Y);
- ``mode="k_step"``: y(t) from the measured outputs up to t - k, the model's own predictions
  between (k = 1 is one-step; k >= the record length is free run);
- ``mode="free_run"``: from the first ``t0`` measured rows only.

``predict(U)`` alone (scikit-learn's call): a static model maps U; a dynamic one runs free from
its start outputs (``_start_outputs``: the middle of the training output range for a network,
the training mean for ARX kinds), since no measured output is given. A model fitted on a 1-D Y
predicts 1-D arrays (scikit-learn's convention); ``score`` is R^2 of the one-step prediction.
The scikit-learn protocol (``get_params``, ``set_params``, tags) comes from
:class:`cdam_core.base.estimator.EstimatorParams`, without scikit-learn as a dependency.

``segments`` splits the rows into records laid end to end (a list of lengths, or of (start,
stop) row ranges that tile 0..N): no prediction crosses a seam; each segment starts again from
its own first ``t0`` measured rows, which are returned as measured (as are the first t0 + k - 1
rows of a k-step prediction). ``parameters()`` gives every parameter with its standard
deviation where the estimator defines one (None otherwise). ``to_dict()`` / ``from_dict()`` is
the model file's ``model`` section (plain numbers and strings; see :mod:`.file`).

Subclasses implement ``_fit``, ``_one_step`` (rows t >= t0 from rows t - t0 .. t of one
segment), ``_free_run`` and the dictionary pair; k-step prediction is derived here from the
one-step predictor (exact for any model whose one-step row t depends on rows t - t0 .. t only).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

from cdam_core.base.checks import as_2d, positive_int
from cdam_core.base.estimator import EstimatorParams

__all__ = ["Model", "MODES", "segment_bounds", "Parameter"]

MODES = ("one_step", "k_step", "free_run")

Parameter = tuple  # (value, std or None)


def segment_bounds(segments, n: int) -> list[tuple[int, int]]:
    """(start, stop) row ranges from ``segments`` (None, lengths or ranges) tiling 0..n."""
    if segments is None:
        return [(0, n)]
    try:
        items = list(segments)
    except TypeError:
        raise ValueError("segments: expected a list of lengths or of (start, stop) pairs") from None
    if not items:
        raise ValueError("segments: empty list")
    bounds = []
    if all(isinstance(s, (int, np.integer)) and not isinstance(s, bool) for s in items):
        start = 0
        for k, length in enumerate(items):
            if length < 1:
                raise ValueError(f"segments[{k}]: length must be >= 1, got {length}")
            bounds.append((start, start + int(length)))
            start += int(length)
    else:
        for k, s in enumerate(items):
            try:
                a, b = (int(v) for v in s)
            except (TypeError, ValueError):
                raise ValueError(f"segments[{k}]: expected (start, stop), got {s!r}") from None
            bounds.append((a, b))
    pos = 0
    for k, (a, b) in enumerate(bounds):
        if a != pos or b <= a:
            raise ValueError(f"segments[{k}]: ({a}, {b}) does not continue the tiling at row {pos}")
        pos = b
    if pos != n:
        raise ValueError(f"segments: cover {pos} rows, the data has {n}")
    return bounds


class Model(EstimatorParams, ABC):
    """Base of every model kind (see the module doc)."""

    kind: ClassVar[str] = ""

    @property
    def dynamic(self) -> bool:
        """False for a static map (predictions ignore Y)."""
        return True

    # -- fitted state every kind sets ------------------------------------------------------
    n_inputs_: int
    n_outputs_: int

    @property
    def t0(self) -> int:
        """Measured output rows a prediction starts from (0 for a static map)."""
        return 0

    def is_fitted(self) -> bool:
        return getattr(self, "n_outputs_", None) is not None

    def _n_features(self) -> int:
        return self.n_inputs_

    def _note_target(self, Y) -> None:
        """Remember whether Y was 1-D, so that predictions come back in its shape."""
        self._target_1d = np.asarray(Y).ndim == 1

    def _start_outputs(self) -> np.ndarray:
        """Outputs a free run starts from when no measured output is given."""
        start = getattr(self, "y_start_", None)
        if start is None:
            raise ValueError("Y: a dynamic model needs the measured outputs (at least the first "
                             "t0 rows of each segment)")
        return start

    def _check_fitted(self):
        if not self.is_fitted():
            raise ValueError(f"{type(self).__name__}: not fitted; call fit(U, Y) first")

    # -- the protocol ------------------------------------------------------------------------
    #: True for a kind whose ``_fit(U, Y, bounds)`` takes records laid end to end
    fits_segments: ClassVar[bool] = False

    def fit(self, U, Y, segments=None):
        """Fit on inputs U (N, i) and outputs Y (N, m); returns self. ``segments`` as for
        ``predict``: no regressor crosses a seam (kinds with ``fits_segments``; others take
        one record)."""
        U = as_2d(U, "U")
        if Y is None:
            raise ValueError("Y: the measured outputs are required (requires y to be passed, "
                             "but the target y is None)")
        Y1 = Y
        Y = as_2d(Y, "Y")
        if U.shape[0] != Y.shape[0]:
            raise ValueError(f"U, Y: mismatched sample counts ({U.shape[0]} and {Y.shape[0]})")
        bounds = segment_bounds(segments, U.shape[0])
        if len(bounds) == 1:
            self._fit(U, Y)
        elif not self.fits_segments:
            raise ValueError(f"segments: a {self.kind or type(self).__name__} model is fitted "
                             f"on one record; join the records or fit an arx model")
        else:
            self._fit(U, Y, bounds)
        self._note_target(Y1)
        return self

    def predict(self, U, Y=None, mode: str | None = None, k: int = 1,
                segments=None) -> np.ndarray:
        """Outputs (N, m) in physical units; see the module doc for ``mode``, ``k``, ``segments``
        (default: one step when Y is given, else free run from ``_start_outputs``)."""
        P = self._predict(U, Y, mode, k, segments)
        return P[:, 0] if getattr(self, "_target_1d", False) and P.shape[1] == 1 else P

    def _predict(self, U, Y, mode, k, segments) -> np.ndarray:
        self._check_fitted()
        if mode is None:
            mode = "one_step" if Y is not None else "free_run"
        if mode not in MODES:
            raise ValueError(f"mode: unknown {mode!r}; use one of {', '.join(MODES)}")
        U = as_2d(U, "U")
        if U.shape[1] != self.n_inputs_:
            raise ValueError(f"U: expected {self.n_inputs_} columns, got {U.shape[1]}")
        if not self.dynamic:
            return self._static(U)
        if Y is None:
            if mode != "free_run":
                raise ValueError(f"Y: mode {mode!r} needs the measured outputs")
            Y = np.tile(self._start_outputs(), (U.shape[0], 1))
        Y = as_2d(Y, "Y")
        if Y.shape[1] != self.n_outputs_:
            raise ValueError(f"Y: expected {self.n_outputs_} columns, got {Y.shape[1]}")
        if Y.shape[0] != U.shape[0]:
            raise ValueError(f"U, Y: mismatched sample counts ({U.shape[0]} and {Y.shape[0]})")
        if mode == "k_step":
            k = positive_int(k, "k")
        P = np.array(Y, dtype=np.float64, copy=True)
        for a, b in segment_bounds(segments, U.shape[0]):
            if b - a <= self.t0:
                continue                       # too short to predict: measured rows only
            u, y = U[a:b], Y[a:b]
            if mode == "one_step":
                P[a + self.t0:b] = self._one_step(u, y)
            elif mode == "free_run":
                P[a + self.t0:b] = self._free_run_segment(u, y)
            else:
                P[a:b] = self._k_step(u, y, k)
        return P

    def rollout(self, U, Y, horizon: int, segments=None, first: int = 1, chunk=None):
        """Every k-step prediction for k = 1..``horizon`` in one pass: yields (k, rows, P),
        P (len(rows), m) predicting the rows ``rows`` from the measured outputs up to
        rows - k (the origin) and the model's own predictions after, with the measured
        inputs; equal to ``predict(mode="k_step", k=k)`` on those rows. Origins start at
        row max(t0, 1, first) - 1 of each segment; a horizon may come in several chunks
        (bounded memory; ``chunk`` origins each, default from the sizes), and the k steps of all
        origins run together."""
        self._check_fitted()
        horizon = positive_int(horizon, "horizon")
        U, Y = as_2d(U, "U"), as_2d(Y, "Y")
        bounds = segment_bounds(segments, U.shape[0])
        start = max(self.t0, 1, int(first))
        if not self.dynamic or (type(self)._k_step is not Model._k_step
                                and type(self)._rollout_step is Model._rollout_step):
            for k in range(1, horizon + 1):   # static maps and kinds with their own k-step
                P = self.predict(U, Y, mode="k_step", k=k, segments=segments) \
                    if self.dynamic else self.predict(U)
                rows = np.concatenate([np.arange(a + start + k - 1, b) for a, b in bounds])
                if rows.size:
                    yield k, rows, P[rows]
            return
        t0, m = self.t0, Y.shape[1]
        width = t0 + horizon
        origins = np.concatenate([np.arange(a + start - 1, b - 1) for a, b in bounds])
        seg_end = np.concatenate([np.full(max(b - 1 - (a + start - 1), 0), b)
                                  for a, b in bounds])
        chunk = int(chunk) if chunk else max(256, (1 << 22) // (width * (m + U.shape[1])))
        offs = np.arange(width) - (t0 - 1)            # buffer column -> row offset from origin
        for c in range(0, origins.size, chunk):
            o, end = origins[c:c + chunk], seg_end[c:c + chunk]
            idx = np.minimum(o[:, None] + offs[None, :], U.shape[0] - 1)
            Ub, Zb = U[idx], Y[idx].copy()
            for k in range(1, horizon + 1):
                live = np.flatnonzero(o + k < end)
                if not live.size:
                    break
                P = self._rollout_step(k, o[live], Ub[live], Zb[live], U, Y)
                Zb[live, t0 - 1 + k] = P
                yield k, o[live] + k, P

    def _rollout_step(self, k, origins, Ub, Zb, U, Y):
        """Step k of ``rollout`` for the live ``origins``: their buffers Ub, Zb (inputs and
        outputs, measured then predicted, from t0 - 1 rows before each origin) and the whole
        segment stack U, Y; by default the one-step predictor on each window's last t0 + 1
        rows (a kind with its own k-step predictor overrides this and ``_k_step``)."""
        t0, W = self.t0, len(origins)
        u = np.ascontiguousarray(Ub[:, k - 1:k + t0].reshape(W * (t0 + 1), -1))
        z = np.ascontiguousarray(Zb[:, k - 1:k + t0].reshape(W * (t0 + 1), -1))
        return self._windows_one_step(u, z, W, t0)

    def score(self, U, Y, mode: str = "one_step", k: int = 1, segments=None) -> float:
        """Coefficient of determination R^2 averaged over outputs (as scikit-learn), skipping
        the measured rows of each segment."""
        Y = as_2d(Y, "Y")
        P = self._predict(U, Y, mode, k, segments)
        skip = self.t0 + (k - 1 if mode == "k_step" else 0)
        keep = np.zeros(len(Y), bool)
        for a, b in segment_bounds(segments, len(Y)):
            keep[a + skip:b] = True
        yt, pt = Y[keep], P[keep]
        ss_res = np.sum((yt - pt) ** 2, axis=0)
        ss_tot = np.sum((yt - yt.mean(axis=0)) ** 2, axis=0)
        r2 = np.where(ss_tot > 0, 1.0 - ss_res / np.where(ss_tot > 0, ss_tot, 1.0), 0.0)
        return float(np.mean(r2))

    def parameters(self) -> dict[str, Parameter]:
        """{name: (value, standard deviation or None)}."""
        return {}

    # -- to implement ------------------------------------------------------------------------
    @abstractmethod
    def _fit(self, U: np.ndarray, Y: np.ndarray) -> None: ...

    def _static(self, U: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _one_step(self, U: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Rows t0.. of one segment from measured rows (U, Y of the segment)."""
        raise NotImplementedError

    def _free_run_segment(self, U: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Free run of one segment: by default from its first t0 measured rows alone; a kind
        driven by measured exogenous channels (the grey-box model's arm coupling) overrides it."""
        return self._free_run(U, Y[:self.t0])

    def _free_run(self, U: np.ndarray, Y0: np.ndarray) -> np.ndarray:
        """Rows t0.. of one segment from its inputs and first t0 measured rows Y0."""
        raise NotImplementedError

    def _k_step(self, U: np.ndarray, Y: np.ndarray, k: int) -> np.ndarray:
        """All rows of one segment: every target t >= t0 + k - 1 gets its own window of t0 + k
        rows starting at t - k - t0 + 1; the k steps of all windows run together, one
        vectorised one-step call per step (the first t0 + k - 1 rows stay measured)."""
        t0 = self.t0
        n, m = Y.shape
        first = t0 + k - 1
        P = Y.copy()
        if n <= first:
            return P
        targets = np.arange(first, n)
        idx = (targets - first)[:, None] + np.arange(t0 + k)[None, :]
        Uw, Zw = U[idx], Y[idx].copy()
        W = len(targets)
        for j in range(k):
            u = np.ascontiguousarray(Uw[:, j:j + t0 + 1].reshape(W * (t0 + 1), -1))
            z = np.ascontiguousarray(Zw[:, j:j + t0 + 1].reshape(W * (t0 + 1), m))
            Zw[:, t0 + j] = self._windows_one_step(u, z, W, t0)
        P[targets] = Zw[:, -1]
        return P

    def _windows_one_step(self, u, z, W, t0):
        """One-step prediction of the last row of each of W stacked windows of t0 + 1 rows."""
        # windows laid end to end: the last row of window w is row w (t0 + 1) + t0 of the
        # stack and its one-step prediction uses exactly that window; _one_step returns the
        # rows from t0 on, so it sits at index w (t0 + 1)
        full = self._one_step(u, z)
        return full[np.arange(W) * (t0 + 1)]

    @abstractmethod
    def to_dict(self) -> dict: ...

    @classmethod
    @abstractmethod
    def from_dict(cls, d: dict) -> "Model": ...
