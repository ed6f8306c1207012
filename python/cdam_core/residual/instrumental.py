"""IDIM-IV: instrumental-variable estimation with instruments from a simulated auxiliary model.

IDIM-LS puts the differentiated, filtered measured positions in its regressors; their noise
is correlated with the equation error, so least squares is biased towards zero wherever that
noise is not small (errors-in-variables: a coarse link encoder twice differentiated). IDIM-IV
(Janot, Vandanjon, Gautier, IEEE TCST 2014) replaces the regressors in the normal equations by
*instruments*: the same regressors rebuilt from the positions, velocities and accelerations of
the model itself simulated with the current estimate, which are correlated with the true
regressors and not with the measurement noise. Then estimate -> simulate -> instruments ->
estimate, until the estimates settle.

The literature simulates the auxiliary model in closed loop with the known controller. A tool
that is given only a record does not know the controller, and an open-loop run of an
integrating axis drifts; so the auxiliary model is simulated on consecutive windows of ``H``
samples (the validation windows' horizon, the motion's correlation time) from the filtered
measured state at each window start, driven by the measured inputs (multiple shooting). The
window starts carry measurement noise into the instruments only through their initial states,
and in closed loop the measured torque carries some of the noise the controller fed back: the
instruments are then not strictly uncorrelated with the noise (stated in the report), which is
one reason the choice between IDIM-LS, IDIM-IV and output error is made on held-out data
(:func:`cdam_core.residual.selection` via :class:`~cdam_core.residual.validation.BlockedCV`).

Derivatives of the simulated positions are central differences within each window (the
simulated signals are noise-free, so they need no filter). Rows at rest are left out as in
IDIM-LS (``moving_rows``). The iteration stops when every estimate moves by less than a tenth of
its standard deviation, or after ``MAX_ITERATIONS``. Covariance: the IV formula
s^2 (Z'W)^-1 Z'Z (Z'W)^-T with s^2 the residual variance (white-residual assumption, as
optimistic as IDIM-LS's). A model with errors-in-variables equations is estimated in IDIM-LS's
two stages (:func:`~cdam_core.models.greybox.estimation.stage_split`), the second stage's
covariance carrying the first's.
"""
from __future__ import annotations

import numpy as np

from cdam_core.models.greybox.estimation import Fit, design, stage_split
from cdam_core.residual.benchmark import greybox_of
from cdam_core.residual.output_error import refined_fit

__all__ = ["iv_fit", "MAX_ITERATIONS"]

MAX_ITERATIONS = 20   # a cap, not a tuning: the iteration normally settles in a few steps


def _stack(model, s, eqs, est, rows, weights):
    """(y, W): the weighted equations stacked over ``rows`` for the estimated parameters,
    the fixed parameters' columns moved to the left side."""
    n = np.asarray(s["t"]).size
    ys, Ws = [], []
    for eq, (y, cols) in eqs.items():
        w = float(weights.get(eq, 1.0))
        yy = np.broadcast_to(np.asarray(y, dtype=float), (n,)).copy()
        W = np.zeros((n, len(est)))
        for p, c in cols.items():
            c = np.broadcast_to(np.asarray(c, dtype=float), (n,))
            if p in est:
                W[:, est.index(p)] = c
            else:
                yy -= float(model.fixed.get(p, 0.0)) * c
        ys.append(w * yy[rows])
        Ws.append(w * W[rows])
    return np.concatenate(ys), np.vstack(Ws)


def _iv(y, W, Z) -> tuple:
    """The IV estimate solving Z'W th = Z'y, its covariance s^2 (Z'W)^-1 Z'Z (Z'W)^-T and
    (Z'W)^-1."""
    ZW = Z.T @ W
    if not np.all(np.isfinite(ZW)) or np.linalg.cond(ZW) > 1e12:
        raise ValueError("instruments: Z'W is singular (the auxiliary model does not "
                         "excite every parameter)")
    th = np.linalg.solve(ZW, Z.T @ y)
    e = y - W @ th
    s2 = float(e @ e) / max(y.size - W.shape[1], 1)
    Zi = np.linalg.inv(ZW)
    return th, s2 * Zi @ (Z.T @ Z) @ Zi.T, Zi


def _simulated_signals(fitted: Fit, sig, U, horizon: int, trim: int, integrator: str = "rk4"):
    """``sig`` with each position replaced by the auxiliary model's, simulated on consecutive
    windows and then filtered and differentiated exactly as the measured positions were (the
    instruments must see the filter the regressors saw); and the mask of rows the windows
    cover, clear of the seams between windows by the filter's settling length."""
    model = fitted.model
    n = np.asarray(sig["t"]).size
    dt = float(sig["dt"])
    pos = list(model.positions)
    filt = sig["filter"]
    # a filter's step response settles within about one period of its cut-off: two periods
    # either side of a seam are left out, and a window holds at least eight settling lengths
    settle = max(int(np.ceil(2.0 / (filt.for_signal(p).cutoff_hz * dt))) for p in pos)
    H = max(int(horizon), 8 * settle)
    starts = np.arange(max(trim, 1), n - trim - H, H)
    if starts.size == 0:
        raise ValueError(f"record: no window of {H} samples between the trimmed edges")
    Y = np.column_stack([np.asarray(sig[p + "_raw"], dtype=float) for p in pos])
    x0 = np.column_stack([np.asarray(sig[p], dtype=float)[starts] for p in pos])
    v0 = np.column_stack([np.asarray(sig[p + "_d"], dtype=float)[starts] for p in pos])
    g = greybox_of(fitted, dt)
    P = g.windows(U, Y, starts, H, x0, v0, integrator=integrator)   # rows start+1..start+H
    rows = (starts[None, :] + np.arange(1, H + 1)[:, None]).ravel()
    raw = {name: sig[name] for name in model.signals if name not in pos}
    for j, p in enumerate(pos):
        q = np.array(sig[p], dtype=float, copy=True)
        q[rows] = P[:, :, j].ravel()
        raw[p] = q
    out = model.prepare(sig["t"], raw, filt, sig.get("extra") or None,
                        sig.get("timing", "sampled"))
    out.measured = False   # simulated windows: no encoder noise in their positions
    covered = np.zeros(n, dtype=bool)
    covered[starts[0]:starts[-1] + H + 1] = True
    for s0 in list(starts) + [starts[-1] + H]:
        covered[max(0, s0 - settle):s0 + settle + 1] = False
    return out, covered


def iv_fit(fitted: Fit, sig, U, horizon: int, trim: int, rows=None,
           integrator: str = "rk4") -> tuple[Fit, dict]:
    """IDIM-IV from the IDIM-LS fit ``fitted`` on the prepared record ``sig`` (inputs ``U`` as
    :class:`GreyBox` takes them; ``rows``: a fold's boolean mask; ``integrator``: the auxiliary
    model's windows, "rk4" (the validation windows', the switching terms held over a step) or
    "euler", the model kind's; session 7 ran them by Euler). Returns the fit (residuals
    on every kept row, as IDIM-LS's) and a report (iterations, converged, the LS estimates).
    Raises ValueError when the auxiliary model cannot be simulated or the instruments are
    singular."""
    model, effects = fitted.model, fitted.effects
    n = np.asarray(sig["t"]).size
    est = list(fitted.estimated)
    s_meas, eqs_meas = design(model, sig, effects)
    use = np.zeros(n, dtype=bool)
    use[trim:n - trim] = True
    if rows is not None:
        use &= np.asarray(rows, dtype=bool)
    for e in effects:
        moving = e.moving_rows(s_meas, model) if hasattr(e, "moving_rows") else None
        if moving is not None:
            use &= moving
    weights = dict(getattr(sig, "weights", None) or {})
    current = fitted
    theta = {p: float(fitted.theta[p]) for p in est}
    info = {"iterations": 0, "converged": False, "idim_ls": dict(theta)}
    for it in range(1, MAX_ITERATIONS + 1):
        sim, covered = _simulated_signals(current, sig, U, horizon, trim, integrator)
        r = use & covered
        if int(r.sum()) <= 2 * len(est):
            raise ValueError(f"rows: {int(r.sum())} rows left for the instruments")
        _, eqs_sim = design(model, sim, effects)
        split = stage_split(model, eqs_meas, est)
        if split is None:
            y, W = _stack(model, s_meas, eqs_meas, est, r, weights)
            _, Z = _stack(model, sim, eqs_sim, est, r, weights)
            th, cov, _ = _iv(y, W, Z)
        else:   # two stages, as IDIM-LS (estimation.stage_split)
            clean, eiv, first, second = split
            i1 = np.array([est.index(p) for p in first], dtype=int)
            i2 = np.array([est.index(p) for p in second], dtype=int)
            y, W = _stack(model, s_meas, {e: eqs_meas[e] for e in clean}, est, r, weights)
            _, Z = _stack(model, sim, {e: eqs_sim[e] for e in clean}, est, r, weights)
            th, cov = np.zeros(len(est)), np.zeros((len(est), len(est)))
            th[i1], C1, _ = _iv(y, W[:, i1], Z[:, i1])
            cov[np.ix_(i1, i1)] = C1
            if i2.size:
                y, W = _stack(model, s_meas, {e: eqs_meas[e] for e in eiv}, est, r, weights)
                _, Z = _stack(model, sim, {e: eqs_sim[e] for e in eiv}, est, r, weights)
                th[i2], C2, Zi = _iv(y - W[:, i1] @ th[i1], W[:, i2], Z[:, i2])
                G = Zi @ (Z[:, i2].T @ W[:, i1])   # the first stage carried through (LS's rule)
                cov[np.ix_(i2, i2)] = C2 + G @ C1 @ G.T
        new = dict(zip(est, map(float, th)))
        std = {p: float(np.sqrt(max(cov[j, j], 0.0))) for j, p in enumerate(est)}
        moved = max(abs(new[p] - theta[p]) / std[p] if std[p] > 0 else 0.0 for p in est)
        theta = new
        current = refined_fit(fitted, theta, std, sig)
        info["iterations"] = it
        if moved < 0.1:
            info["converged"] = True
            break
    bounds = dict(getattr(model, "bounds", {}) or {})
    for eff in effects:
        bounds.update(eff.bounds())
    out = [p for p in est if not bounds.get(p, (-np.inf, np.inf))[0] <= theta[p]
           <= bounds.get(p, (-np.inf, np.inf))[1]]
    if out:
        raise ValueError(f"IDIM-IV estimates outside the physical bounds: {', '.join(out)}")
    return current, info
