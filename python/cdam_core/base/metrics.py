"""Per-output error metrics of an identified model.

- Pearson r (``numpy.corrcoef``; NaN when either series is constant),
- RMSE in the output's units,
- NRMSE = RMSE / std(measured) (MATLAB goodnessOfFit 'NRMSE'; 0 is perfect, 1 is no better
  than predicting the mean) and fit % = 100 (1 - NRMSE),
- the adaptation value (the paper's "fitness") = 1 / (1 + MSE), MSE in normalised units.
"""
from __future__ import annotations

import numpy as np

__all__ = ["output_metrics", "adaptation_value", "mean_pearson", "pearson_r", "rmse", "nrmse"]


def _pair(measured, predicted):
    y = np.asarray(measured, dtype=np.float64)
    p = np.asarray(predicted, dtype=np.float64)
    if y.ndim == 1:
        y = y[:, None]
    if p.ndim == 1:
        p = p[:, None]
    if y.ndim != 2 or y.size == 0:
        raise ValueError(f"measured: expected a non-empty (N, m) array, got shape {y.shape}")
    if p.shape != y.shape:
        raise ValueError(f"predicted: shape {p.shape} differs from measured {y.shape}")
    for a, name in ((y, "measured"), (p, "predicted")):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: contains NaN or Inf")
    return y, p


def pearson_r(measured, predicted) -> np.ndarray:
    """Pearson correlation per column (NaN for a constant column)."""
    y, p = _pair(measured, predicted)
    out = np.full(y.shape[1], np.nan)
    for k in range(y.shape[1]):
        if np.ptp(y[:, k]) > 0 and np.ptp(p[:, k]) > 0:
            out[k] = np.corrcoef(y[:, k], p[:, k])[0, 1]
    return out


def rmse(measured, predicted) -> np.ndarray:
    """Root-mean-square error per column."""
    y, p = _pair(measured, predicted)
    return np.sqrt(np.mean((y - p) ** 2, axis=0))


def nrmse(measured, predicted) -> np.ndarray:
    """RMSE / std(measured) per column (NaN for a constant measured column)."""
    y, p = _pair(measured, predicted)
    sd = np.std(y, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sd > 0, rmse(y, p) / np.where(sd > 0, sd, 1.0), np.nan)


def output_metrics(measured, predicted, names=None) -> dict:
    """{name: {"r", "rmse", "nrmse", "fit_percent"}} for each output column."""
    y, p = _pair(measured, predicted)
    names = list(names) if names is not None else [f"y{k}" for k in range(y.shape[1])]
    if len(names) != y.shape[1]:
        raise ValueError(f"names: {len(names)} names for {y.shape[1]} outputs")
    r, e, ne = pearson_r(y, p), rmse(y, p), nrmse(y, p)
    return {n: {"r": float(r[k]), "rmse": float(e[k]), "nrmse": float(ne[k]),
                "fit_percent": float(100.0 * (1.0 - ne[k]))} for k, n in enumerate(names)}


def adaptation_value(mse):
    """The reported "fitness": 1 / (1 + MSE), MSE >= 0 in normalised units (1 is perfect)."""
    m = np.asarray(mse, dtype=np.float64)
    if np.any(~np.isfinite(m)) or np.any(m < 0):
        raise ValueError("mse: must be finite and >= 0")
    out = 1.0 / (1.0 + m)
    return float(out) if out.ndim == 0 else out


def mean_pearson(measured, predicted) -> float:
    """Mean Pearson r over outputs, a constant column counting as 0 (a selection score: a
    prediction that is constant carries no information)."""
    r = pearson_r(measured, predicted)
    return float(np.mean(np.where(np.isfinite(r), r, 0.0)))
