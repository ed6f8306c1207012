"""NARX regressors and free-run simulation, numpy reference.

With orders na (outputs), nb (inputs) and delay nk, t0 = max(na, nk + nb - 1) and the
regressor for time t (t = t0 .. N-1) is

    [Y[t-1, :], ..., Y[t-na, :], U[t-nk, :], U[t-nk-1, :], ..., U[t-nk-nb+1, :]]

(channels fastest), length na*m + nb*i. One-step prediction is ``mlp_forward`` on these rows;
free-run simulation feeds the network's own outputs back in place of the measured Y.
"""
from __future__ import annotations

import numpy as np

from cdam_core.reference._checks import activation as check_activation
from cdam_core.reference._checks import common_dtype, float_array, integer, same_rows
from cdam_core.reference.mlp import _forward


def _orders(na, nb, nk):
    na = integer(na, "na", minimum=0)
    nb = integer(nb, "nb", minimum=0)
    nk = integer(nk, "nk", minimum=0)
    if na + nb < 1:
        raise ValueError("na: na + nb must be at least 1, got na=0, nb=0")
    return na, nb, nk, max(na, nk + nb - 1)


def narx_start(na: int, nb: int, nk: int) -> int:
    """First time index with a full regressor: t0 = max(na, nk + nb - 1)."""
    return _orders(na, nb, nk)[3]


def _row(U, Y, t, na, nb, nk):
    parts = [Y[t - a] for a in range(1, na + 1)]
    parts += [U[t - nk - b] for b in range(nb)]
    return np.concatenate(parts) if parts else np.empty(0, dtype=U.dtype)


def narx_regressors(U, Y, na: int, nb: int, nk: int) -> np.ndarray:
    """Lagged regressor matrix (N - t0, na*m + nb*i) from inputs U (N, i) and outputs Y (N, m)."""
    na, nb, nk, t0 = _orders(na, nb, nk)
    u = float_array(U, "U", 2)
    y = float_array(Y, "Y", 2)
    same_rows(u, y, "U", "Y")
    n = u.shape[0]
    if n <= t0:
        raise ValueError(f"U: needs more than t0 = {t0} samples, got {n}")
    dtype = common_dtype(u, y)
    u, y = u.astype(dtype, copy=False), y.astype(dtype, copy=False)
    blocks = [y[t0 - a:n - a] for a in range(1, na + 1)]
    blocks += [u[t0 - nk - b:n - nk - b] for b in range(nb)]
    return np.concatenate(blocks, axis=1)


def narx_simulate(theta, U, Y0, hidden: int, activation: str, na: int, nb: int,
                  nk: int) -> np.ndarray:
    """Free-run simulation Y (N, m): Y[:t0] = Y0, then Y[t] = network(regressor from simulated Y).

    U is (N, i); Y0 is (t0, m) with t0 = max(na, nk + nb - 1) (it may have zero rows).
    """
    check_activation(activation)
    na, nb, nk, t0 = _orders(na, nb, nk)
    h = integer(hidden, "hidden", minimum=1)
    th = float_array(theta, "theta", 1)
    u = float_array(U, "U", 2)
    y0 = float_array(Y0, "Y0", 2, allow_empty=True)
    if y0.shape[0] != t0:
        raise ValueError(f"Y0: must have t0 = {t0} rows, got {y0.shape[0]}")
    m = y0.shape[1]
    if m < 1:
        raise ValueError("Y0: must have at least one column")
    n = u.shape[0]
    if n <= t0:
        raise ValueError(f"U: needs more than t0 = {t0} samples, got {n}")
    n_in = na * m + nb * u.shape[1]
    d = n_in * h + h + h * m + m
    if th.shape[0] != d:
        raise ValueError(f"theta: has length {th.shape[0]}, expected {d} for "
                         f"i={n_in}, hidden={h}, outputs={m}")
    dtype = common_dtype(th, u, y0)
    th, u = th.astype(dtype, copy=False), u.astype(dtype, copy=False)
    y = np.zeros((n, m), dtype=dtype)
    y[:t0] = y0
    for t in range(t0, n):
        reg = _row(u, y, t, na, nb, nk)[None, :]
        y[t] = _forward(th, reg, h, m, activation)[0][0]
    return y
