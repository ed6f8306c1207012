"""Output-error refinement by multiple shooting, and the choice between it and IDIM-LS.

IDIM-LS fits the equations on differentiated, filtered measurements; what a user runs is the
model's *simulation*. The refinement starts from the IDIM estimates and minimises the error of
simulated windows (the held-out validation's windows: ``H`` samples from the measured state,
each window's initial state projected out by least squares) over the estimated parameters with
``scipy.optimize.least_squares`` (trust-region reflective, the model's physical bounds,
a forward-difference Jacobian with scipy's steps whose columns are simulated in one batch:
every perturbed parameter set is a group of lanes of one rollout, ``GreyBox.windows``).

Standard deviations: the cost is the sum over windows and samples of the squared residual
e (after each window's state fit), so at the optimum theta the estimate solves
sum_w J_w' e_w = 0 (J_w: the window's residual sensitivities, forward differences at the
optimum, one batched simulation). Its covariance is the sandwich A^-1 B A^-1 with
A = sum_w J_w' J_w (Gauss-Newton) and B = sum_w (J_w' e_w)(J_w' e_w)', the windows as
clusters (cluster-robust), times W / (W - p) (W windows, p parameters). Why clusters: a
window's residuals are correlated (the state fit absorbs part of the noise, quantisation and
the filtered start are coloured, an unmodelled term drifts over a window), which the textbook
s^2 (J'J)^-1 takes as independent samples; the windows themselves do not overlap and span at
least the motion's correlation time, so they are treated as independent of one another. The
sandwich needs no noise model and no variance estimate (it is the empirical spread of the
windows' scores). Before (session 7): sqrt(diag(s^2 (J'J)^-1)) on the per-window root mean
squares, whose Jacobian vanishes at an optimum where the windows hold only noise (r_w =
sqrt(s^2 + quadratic) is flat there): sigmas 30-40 % where the errors were < 1.3 %.
Measured on the independent generator (tests/residual/joint_generator.py, nine conditions x
seeds): see :func:`window_covariance`'s caller in the README's joint example and the report.

When to stop: a move of a tenth of a standard deviation changes the cost (half the sum of
squared window errors, F = dof s^2 / 2 at the optimum) by about 0.005 s^2, a share 0.01 / dof
of F; smaller improvements are statistically nothing, so that share is scipy's ``ftol`` (dof:
windows minus parameters). The default 1e-8 spent most of the evaluations on such moves
(generator B, a fold: 80 evaluations, the cost 0.3 % lower after evaluation 35).

Which estimate the final model keeps is decided on held-out data like everything else: the
refinement is run on four blocks and scored on the fifth (``BlockedCV`` with
``estimator="oe"``), against IDIM-LS's windows, one-sided Wilcoxon at ``alpha``.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.optimize import least_squares

from cdam_core.models.greybox.estimation import apply_fit

__all__ = ["refine", "refined_fit"]

MAX_EVALUATIONS = 80   # a cap, not a tuning: the stop is the tenth-of-a-sigma rule (above)
DIFF_STEP = 1e-4   # relative step of the forward differences (scipy's diff_step)


def refine(g, U, Y, starts, shooting, bounds: dict) -> tuple[dict, dict]:
    """Minimise the multiple-shooting error of GreyBox ``g`` (fitted) over its estimated
    parameters on the windows at ``starts``; ``shooting(g, U, Y, starts)`` returns each
    window's mean squared error after the initial-state projection. Returns (theta, info)."""
    names = list(g.estimated_)
    th0 = np.array([g.theta_[p] for p in names], dtype=float)
    scale = np.where(np.abs(th0) > 0, np.abs(th0), 1.0)
    lo = np.array([bounds.get(p, (-np.inf, np.inf))[0] for p in names]) / scale
    hi = np.array([bounds.get(p, (-np.inf, np.inf))[1] for p in names]) / scale
    gap = 1e-9 * (1.0 + np.abs(th0 / scale))      # strictly inside finite bounds
    x0 = np.clip(th0 / scale, np.where(np.isfinite(lo), lo + gap, -np.inf),
                 np.where(np.isfinite(hi), hi - gap, np.inf))

    def residual(x):
        g.set_parameters(dict(zip(names, x * scale)))
        try:
            e = shooting(g, U, Y, starts)
        except ValueError:                  # a diverging trial point: a large, finite error
            return np.full(starts.size, 1e3)
        return np.sqrt(np.maximum(e, 0.0))

    full = list(g.theta_)
    cols = [full.index(p) for p in names]

    def jacobian(x):
        """Forward differences (scipy's '2-point' steps, turned back at a bound), every
        column's windows simulated in one batch with the base point; column by column when
        the batch cannot be simulated (a trial point that diverges)."""
        h = _steps(x, lo, hi)
        base = np.array([g.theta_[p] for p in full])
        TH = np.tile(base, (len(names) + 1, 1))
        TH[0, cols] = x * scale
        for j in range(len(names)):
            TH[j + 1, cols] = x * scale
            TH[j + 1, cols[j]] = (x[j] + h[j]) * scale[j]
        try:
            E = np.sqrt(np.maximum(shooting(g, U, Y, starts, thetas=TH), 0.0))
            f0, F = E[0], E[1:]
        except ValueError:
            f0 = residual(x)
            F = np.array([residual(x + h[j] * np.eye(len(names))[j]) for j in range(len(names))])
        return ((F - f0[None, :]) / h[:, None]).T

    r0 = residual(x0)
    ftol = 0.01 / max(starts.size - len(names), 1)
    sol = least_squares(residual, x0, jac=jacobian, bounds=(lo, hi), max_nfev=MAX_EVALUATIONS,
                        ftol=ftol)
    theta = dict(zip(names, map(float, sol.x * scale)))
    g.set_parameters(theta)
    try:
        std = window_covariance(g, U, Y, starts, shooting, names, sol.x, scale, lo, hi)
    except (ValueError, np.linalg.LinAlgError):
        std = {p: float("nan") for p in names}
    g.set_parameters(theta)
    # the session-7 figure, for comparison: s^2 (J'J)^-1 on the windows' root mean squares
    s2 = float(sol.fun @ sol.fun) / max(sol.fun.size - len(names), 1)
    d = np.diag(np.linalg.pinv(sol.jac.T @ sol.jac)) * s2
    naive = {p: float(np.sqrt(d[j]) * scale[j]) if d[j] > 0 else float("nan")
             for j, p in enumerate(names)}
    return theta, {"window_rms_before": float(np.sqrt(np.mean(r0 ** 2))),
                   "window_rms_after": float(np.sqrt(np.mean(sol.fun ** 2))),
                   "evaluations": int(sol.nfev), "status": sol.message, "std": std,
                   "std_method": "cluster-robust sandwich, windows as clusters",
                   "std_windows_rms": naive}


def window_covariance(g, U, Y, starts, shooting, names, x, scale, lo, hi) -> dict:
    """Standard deviations of the parameters ``names`` at the scaled optimum ``x`` (module
    doc): the windows' residuals after the state fit and their forward-difference
    sensitivities from one batched simulation, the cluster-robust sandwich over windows."""
    full = list(g.theta_)
    cols = [full.index(p) for p in names]
    h = _steps(x, lo, hi)
    TH = np.tile(np.array([g.theta_[p] for p in full]), (len(names) + 1, 1))
    TH[:, cols] = x * scale
    for j in range(len(names)):
        TH[j + 1, cols[j]] = (x[j] + h[j]) * scale[j]
    R = shooting(g, U, Y, starts, thetas=TH, samples=True)      # (p + 1, W, H m)
    e = R[0]
    J = np.transpose((R[1:] - e[None]) / h[:, None, None], (1, 2, 0))   # (W, H m, p)
    A = np.einsum("wnp,wnq->pq", J, J)
    score = np.einsum("wnp,wn->wp", J, e)
    W, P = score.shape
    Ai = np.linalg.pinv(A)
    cov = Ai @ (score.T @ score) @ Ai * (W / max(W - P, 1))
    return {p: float(np.sqrt(cov[j, j]) * scale[j]) if cov[j, j] > 0 else float("nan")
            for j, p in enumerate(names)}


def _steps(x, lo, hi, rel: float = DIFF_STEP) -> np.ndarray:
    """scipy.optimize.least_squares' forward-difference steps for ``diff_step`` ``rel``
    (scipy.optimize._numdiff: rel sign(x) |x|, sqrt(eps) sign(x) max(1, |x|) where that is no
    step, turned back or shortened at a bound), as the step actually taken: (x + h) - x."""
    sign = np.where(x >= 0, 1.0, -1.0)
    h = rel * sign * np.abs(x)
    h = np.where((x + h) - x == 0, np.sqrt(np.finfo(float).eps) * sign * np.maximum(1.0, np.abs(x)),
                 h)
    lower, upper = x - lo, hi - x
    out = (x + h < lo) | (x + h > hi)
    fitting = np.abs(h) <= np.maximum(lower, upper)
    h = np.where(out & fitting, -h, h)
    h = np.where(~fitting & (upper >= lower), upper, h)
    h = np.where(~fitting & (upper < lower), -lower, h)
    return (x + h) - x


def refined_fit(fitted, theta: dict, std: dict, sig: dict):
    """The IDIM ``Fit`` with the refined parameters, its equation residuals recomputed on the
    prepared signals ``sig`` (those the fit was made on)."""
    full = dict(fitted.theta)
    full.update(theta)
    return apply_fit(dataclasses.replace(fitted, theta=full, std={**fitted.std, **std}), sig)
