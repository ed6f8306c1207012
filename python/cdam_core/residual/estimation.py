"""IDIM-LS estimation of a declared model (plus effects) and its free-run (output) simulation.

Estimation: stack every equation's rows ``y = Phi theta`` over the record (the first and last
``trim`` samples, where the zero-phase filter and the differences have edge effects, are left
out), move fixed parameters to the left side, solve with ``numpy.linalg.lstsq``.
Free run: integrate the same equations forward from the measured inputs alone (semi-implicit
Euler, ``substeps`` per sample chosen so that h * |lambda|max <= 0.5 for the linearised model).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ._checks import as_signal, as_time


def apply_effects(model, sig: dict, effects) -> dict:
    s = dict(sig)
    for e in effects:
        s = e.transform_inputs(s, model)
    for e in effects:
        s = e.transform_state(s, model)
    return s


def design(model, sig: dict, effects=()) -> tuple[dict, dict]:
    """The transformed signals and ``{equation: (y, {parameter: column})}`` with effects added."""
    s = apply_effects(model, sig, effects)
    eqs = {k: (y, dict(cols)) for k, (y, cols) in model.equations(s).items()}
    for e in effects:
        for eq, cols in e.regressors(s, model).items():
            if eq not in eqs:
                raise ValueError(f"effects: {e.key} adds to unknown equation {eq!r}")
            eqs[eq][1].update(cols)
    return s, eqs


@dataclass
class Fit:
    """A least-squares fit: estimates, residuals per equation and the settings used."""

    model: object
    effects: tuple
    theta: dict                 # every parameter (estimated and fixed)
    estimated: list             # names of the estimated parameters
    residuals: dict             # equation -> residual over the kept samples
    references: dict            # equation -> reference signal (normalisation)
    signals: dict               # transformed signals
    keep: slice
    cond: float

    @property
    def sse(self) -> float:
        return float(sum(np.sum(r ** 2) for r in self.residuals.values()))

    @property
    def n_rows(self) -> int:
        return int(sum(r.size for r in self.residuals.values()))

    @property
    def k(self) -> int:
        return len(self.estimated)

    def equation_error(self) -> dict:
        """``{equation: {"rmse", "nrmse"}}``; nrmse = ||e|| / ||reference|| (EMPS relative error)."""
        out = {}
        for eq, r in self.residuals.items():
            ref = self.references[eq]
            den = float(np.linalg.norm(ref))
            out[eq] = {"rmse": float(np.sqrt(np.mean(r ** 2))),
                       "nrmse": float(np.linalg.norm(r) / den) if den > 0 else float("nan")}
        return out


def fit(model, sig: dict, effects=(), trim: int = 50) -> Fit:
    """Estimate the parameters of ``model`` with ``effects`` by linear least squares."""
    effects = tuple(effects)
    n = sig["t"].size
    trim = int(trim)
    if trim < 0 or 2 * trim >= n - 10:
        raise ValueError(f"trim: {trim} leaves too few of the {n} samples")
    keep = slice(trim, n - trim)
    s, eqs = design(model, sig, effects)
    names = []
    for _, cols in eqs.values():
        names += [p for p in cols if p not in names]
    est = [p for p in names if p not in model.fixed]
    ys, rows = [], []
    for eq, (y, cols) in eqs.items():
        y = np.broadcast_to(np.asarray(y, dtype=float), (n,))[keep].copy()
        for p, c in cols.items():
            if p in model.fixed:
                y -= model.fixed[p] * np.asarray(c, dtype=float)[keep]
        X = np.zeros((y.size, len(est)))
        for j, p in enumerate(est):
            if p in cols:
                X[:, j] = np.asarray(cols[p], dtype=float)[keep]
        ys.append(y)
        rows.append(X)
    y_all, X_all = np.concatenate(ys), np.vstack(rows)
    if not np.all(np.isfinite(X_all)):
        raise ValueError("signals: the regressors contain NaN or Inf")
    # Normal equations on unit-norm columns, formed with einsum (single-threaded): on a busy
    # machine a threaded BLAS on a tall (N x k) matrix is 10x slower than this, and with unit
    # columns the k x k system stays well conditioned (cond reported below).
    scale = np.sqrt(np.einsum("ij,ij->j", X_all, X_all))
    scale[scale == 0] = 1.0
    Xs = X_all / scale
    A = np.einsum("ij,ik->jk", Xs, Xs)
    theta_est = np.linalg.lstsq(A, np.einsum("ij,i->j", Xs, y_all), rcond=None)[0] / scale
    sv = np.sqrt(np.maximum(np.linalg.eigvalsh(A)[::-1], 0.0)) if A.size else np.ones(1)
    theta = dict(model.fixed)
    theta.update(zip(est, map(float, theta_est)))
    resid, refs, i0 = {}, {}, 0
    for (eq, _), y in zip(eqs.items(), ys):
        m = y.size
        resid[eq] = y - np.einsum("ij,j->i", X_all[i0:i0 + m], theta_est)
        refs[eq] = np.broadcast_to(np.asarray(model.reference(eq, s, theta), dtype=float), (n,))[keep]
        i0 += m
    return Fit(model, effects, theta, est, resid, refs, s, keep,
               float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"))


# ----------------------------------------------------------------------------------------
# free-run simulation
# ----------------------------------------------------------------------------------------
def _state(model, pos, vel, acc, u: dict, extra: dict, t: float) -> dict:
    s = {"t": t, "extra": extra}
    s.update(u)
    for p, x, v, a in zip(model.positions, pos, vel, acc):
        s[p], s[p + "_d"], s[p + "_dd"] = x, v, a
    return model.augment(s)


def _eq_error(model, effects, theta, s) -> np.ndarray:
    for e in effects:
        s = e.transform_state(s, model)
    eqs = {k: (y, dict(c)) for k, (y, c) in model.equations(s).items()}
    for e in effects:
        for eq, cols in e.regressors(s, model).items():
            eqs[eq][1].update(cols)
    return np.array([float(y) - sum(theta[p] * float(c) for p, c in cols.items())
                     for y, cols in eqs.values()])


def simulate(fitted: Fit, t, inputs: dict, x0=None, v0=None, extra: dict | None = None,
             substeps: int | None = None) -> dict:
    """Free-run the fitted model from ``inputs`` alone; returns ``{position: array}``.

    ``x0`` and ``v0`` are the initial positions and velocities (default: first input-record
    values given in ``inputs`` for positions, zero velocity).
    """
    model, effects, theta = fitted.model, fitted.effects, fitted.theta
    t = as_time(t)
    n = t.size
    u_all = {"t": t}
    for name in model.inputs:
        if name not in inputs:
            raise ValueError(f"inputs: missing {name!r}")
        u_all[name] = as_signal(inputs[name], f"inputs[{name}]", n)
    ex_all = {k: as_signal(v, f"extra[{k}]", n) for k, v in (extra or {}).items()}
    for e in effects:
        u_all = e.transform_inputs(u_all, model)
    npos = len(model.positions)
    if x0 is None:
        x0 = [float(as_signal(inputs[p], p)[0]) if p in inputs else 0.0 for p in model.positions]
    x = np.array(x0, dtype=float).reshape(npos)
    v = np.zeros(npos) if v0 is None else np.array(v0, dtype=float).reshape(npos)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
        raise ValueError("x0/v0: not finite")
    dt = float(np.mean(np.diff(t)))

    def uk(k):
        return {name: u_all[name][k] for name in model.inputs}, {c: a[k] for c, a in ex_all.items()}

    u0, e0 = uk(0)
    zero = np.zeros(npos)
    base = _eq_error(model, effects, theta, _state(model, x, v, zero, u0, e0, t[0]))
    A = np.empty((npos, npos))   # e(acc) = base - A acc (the accelerations enter linearly)
    for j in range(npos):
        a = zero.copy()
        a[j] = 1.0
        A[:, j] = base - _eq_error(model, effects, theta, _state(model, x, v, a, u0, e0, t[0]))
    if np.linalg.cond(A) > 1e12:
        raise ValueError("theta: the estimated inertia matrix is singular; cannot simulate")
    Ainv = np.linalg.inv(A)

    def accel(xx, vv, u, ex, tk, effs=effects):
        return Ainv @ _eq_error(model, effs, theta, _state(model, xx, vv, zero, u, ex, tk))

    if substeps is None:  # |eigenvalues| of the linearised base model (effects left out)
        J = np.zeros((2 * npos, 2 * npos))
        J[:npos, npos:] = np.eye(npos)
        a0 = accel(x, v, u0, e0, t[0], ())
        for j in range(2 * npos):
            h = 1e-6
            xx, vv = x.copy(), v.copy()
            (xx if j < npos else vv)[j % npos] += h
            J[npos:, j] = (accel(xx, vv, u0, e0, t[0], ()) - a0) / h
        lam = float(np.max(np.abs(np.linalg.eigvals(J))))
        substeps = max(1, int(np.ceil(dt * lam / 0.5)))
    substeps = int(substeps)
    if substeps < 1:
        raise ValueError("substeps: must be >= 1")
    h = dt / substeps
    out = np.empty((n, npos))
    out[0] = x
    for k in range(n - 1):
        u, ex = uk(k)
        for _ in range(substeps):
            v = v + h * accel(x, v, u, ex, t[k])
            x = x + h * v
        if not np.all(np.isfinite(x)) or np.max(np.abs(x)) > 1e9:
            raise ValueError(f"simulation diverged at t = {t[k]:g} s")
        out[k + 1] = x
    return {p: out[:, i] for i, p in enumerate(model.positions)}


def free_run_error(fitted: Fit, sig: dict, substeps: int | None = None) -> tuple[dict, dict]:
    """Simulate over the record of ``sig`` and compare with the measured positions.

    The simulation starts at sample ``fitted.keep.start`` (after the derivative filter's edge).
    Returns (``{position: {"rmse", "nrmse"}}`` with nrmse = rmse / std(measured), simulated).
    """
    model = fitted.model
    # start after the filter's edge (``trim`` samples), from the filtered position and velocity
    k0 = min(fitted.keep.start, sig["t"].size - 3)
    x0 = [sig[p][k0] for p in model.positions]
    v0 = [sig[p + "_d"][k0] for p in model.positions]
    sim = simulate(fitted, sig["t"][k0:], {u: sig[u][k0:] for u in model.inputs}, x0=x0, v0=v0,
                   extra={k: v[k0:] for k, v in sig.get("extra", {}).items()}, substeps=substeps)
    out = {}
    for p in model.positions:
        e = sim[p] - sig[p + "_raw"][k0:]
        sd = float(np.std(sig[p + "_raw"][k0:]))
        rmse = float(np.sqrt(np.mean(e ** 2)))
        out[p] = {"rmse": rmse, "nrmse": rmse / sd if sd > 0 else float("nan")}
    return out, sim


def apply_fit(fitted: Fit, sig: dict, trim: int | None = None) -> Fit:
    """The equation errors of an already estimated model on another record (no re-estimation)."""
    model = fitted.model
    n = sig["t"].size
    trim = fitted.keep.start if trim is None else int(trim)
    if trim < 0 or 2 * trim >= n - 10:
        raise ValueError(f"trim: {trim} leaves too few of the {n} samples")
    keep = slice(trim, n - trim)
    s, eqs = design(model, sig, fitted.effects)
    resid, refs = {}, {}
    for eq, (y, cols) in eqs.items():
        pred = sum(fitted.theta[p] * np.asarray(c, dtype=float) for p, c in cols.items())
        resid[eq] = (np.broadcast_to(np.asarray(y, dtype=float), (n,)) - pred)[keep]
        refs[eq] = np.broadcast_to(np.asarray(model.reference(eq, s, fitted.theta), dtype=float),
                                   (n,))[keep]
    return Fit(model, fitted.effects, dict(fitted.theta), list(fitted.estimated), resid, refs, s,
               keep, fitted.cond)
