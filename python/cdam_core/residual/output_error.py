"""Output-error refinement by multiple shooting, and the choice between it and IDIM-LS.

IDIM-LS fits the equations on differentiated, filtered measurements; what a user runs is the
model's *simulation*. The refinement starts from the IDIM estimates and minimises the error of
simulated windows (the held-out validation's windows: ``H`` samples from the measured state,
each window's initial state projected out by least squares) over the estimated parameters with
``scipy.optimize.least_squares`` (trust-region reflective, the model's physical bounds,
a forward-difference Jacobian with scipy's steps whose columns are simulated in one batch:
every perturbed parameter set is a group of lanes of one rollout, ``GreyBox.windows``). The
residuals are every window's samples after its state fit (over sqrt(samples per window), so
the cost is half the sum of the windows' mean squared errors). Session 7 gave least squares
one residual per window, its root mean square: at an optimum where the windows hold noise
that residual is flat in the parameters (sqrt(s^2 + quadratic)), Gauss-Newton's J'J misses
the curvature, and the fit crawled and stopped early (generator B, seed 1: Kd +1.96 %, Dm
+0.71 % after 35 evaluations; on the samples: Kd -0.21 %, Dm +0.11 % after 3).

Standard deviations: at the optimum the estimate solves sum_w J_w' e_w = 0 (e_w: window w's
residual samples, J_w their sensitivities, differences at the optimum in one batched
simulation). Its covariance is the sandwich A^-1 B A^-1 with A = sum_w J_w' J_w
(Gauss-Newton) and B = sum_w (J_w' e_w)(J_w' e_w)', the windows as clusters
(cluster-robust), times W / (W - p) (W windows, p parameters). Why clusters: a window's
residuals are correlated (the state fit absorbs part of the noise, quantisation and the
filtered start are coloured, an unmodelled term drifts over a window), which the textbook
s^2 (J'J)^-1 takes as independent samples; the windows do not overlap and span at least the
motion's correlation time, so they are taken as independent of one another. The sandwich
needs no noise model (it is the empirical spread of the windows' scores). Session 7's
s^2 (J'J)^-1 on the per-window root mean squares had the flat Jacobian above in it: sigmas
of 30-40 % where the errors were < 1.3 %. Coverage on the independent generator: see the
report of [greybox] 19 (session 8) and tests/residual/test_oe_covariance.py.

The final estimate's (:func:`joint_refine`, every window's state an unknown beside the
parameters) are the same sandwich of that joint problem at its optimum
(:func:`joint_covariance`): per window the residual e_w, the parameters' sensitivities Jp_w
and the window's own state sensitivities Js_w; the states projected out exactly
(Jp_w - Js_w Js_w^+ Jp_w; as each window's states enter its own residuals alone and their
scores are zero at the optimum, this is the parameters' block of the whole problem's
sandwich), then A and B as above. The sensitivities: central differences over several
multiples of a first pass's sigma (1/4 to 4), per parameter the median sigma; a single step
(the optimiser's, or one sigma) left one parameter of a record 40-65 % off the others now
and then (README joint: Fc seed 2 0.27 % at the optimiser's step against 0.79-0.81 % at
1/4-4 sigma; Kd seed 4 0.14 % at one sigma against 0.24 % at the others): a friction switch
crossed by that step's difference. Measured (session 12) on the README's joint, seeds 0-19 of
the independent generator less 6, 7 and 15 (17 records, so each spread is uncertain by about
18 %; seeds 6 and 15 found no dry friction then, with the structures compared on IDIM-LS fold
fits, and find it since within 0.5 %, selection.structure_estimator: over the 19 seeds less 7, with
the Coulomb sign 0 at rest, Fc 0.77 / 0.87 %, Dm 0.32 / 0.33 %; seed 7's windows are fitted 10 %
better at its estimate, Fc -9.8 %, than at the truth), mean relative sigma against the spread of
the errors over the seeds: Im 0.026 / 0.056 %, Dm 0.31 / 0.30 %, Ks 0.020 / 0.021 %, Kd 0.23 /
0.20 %, Fc 0.76 / 0.81 %, I 0.018 / 0.020 %, Dl 0.116 / 0.120 %, G 0.056 / 0.057 % (ratios
0.88-1.18, Im 0.47). Im's spread is mostly the rollout the loop chooses per seed: +0.07 % on
average on the 7 seeds whose windows hold the friction's sign, -0.02 % on the 10 that
simulate stick-slip; on those 10 alone the ratios are 1.04-1.85 (Im 1.18), on the 7 held
0.59-1.47: a model approximation that varies between records, which no sigma of one record
sees. Few clusters are not the reason for ratios below 1: the delete-one-window jackknife
(CR3) gives within 4 % of the same (seeds 0-5, 8, 9). On the link-PD joint at 250 Hz
(tests/residual/test_independent_joint.py, condition C, stick-slip on every seed, seeds
0-7): ratios 0.77-1.57. The nested fit's
sandwich at the joint estimate (session 11's sigmas) was 1.6-8.1 times the spread on the
README joint (Fc 5.4 %, Dm 1.5 %, Kd 1.6 %) and 1.2-3.1 times on C.

When to stop: a move of a tenth of a standard deviation changes the cost (half the sum of
squared residuals, F = dof s^2 / 2 at the optimum for independent residuals) by about
0.005 s^2, a share 0.01 / dof of F; smaller improvements are statistically nothing, so that
share is scipy's ``ftol`` (dof: residual samples minus parameters). Then the sandwich's
sigma is formed and, where a tenth of it along the valley (the other parameters following:
0.005 sigma_j^2 / (A^-1)_jj) is a smaller share of F than that ``ftol``, the fit continues
with the smaller share (at most ``MAX_RESTARTS`` times, within ``MAX_EVALUATIONS``).

Which estimate the final model keeps is decided on held-out data like everything else: the
refinement is run on four blocks and scored on the fifth (``BlockedCV`` with
``estimator="oe"``), against IDIM-LS's windows, one-sided Wilcoxon at ``alpha``.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from cdam_core.models.greybox.estimation import apply_fit

__all__ = ["refine", "refined_fit"]

MAX_EVALUATIONS = 80   # a cap, not a tuning: the stop is the tenth-of-a-sigma rule (above)
MAX_RESTARTS = 3       # continuations after the sandwich's sigma is known (a cap)
DIFF_STEP = 1e-4   # relative step of the forward differences (scipy's diff_step)
# an estimate this close to a bound, in units of its starting value, has ended on it: the
# sandwich's sigma is not defined there (a numerical tolerance: the same as the relative
# difference step, below which the fit's Jacobian cannot tell the two apart)
BOUND_TOL = DIFF_STEP
STATE_STEP = 1e-4  # joint_refine's state steps, in units of its state offsets
# joint_covariance's central differences, in first-pass sigmas: steps on the estimate's own
# scale (module doc); several, their sigmas' median per parameter
SIGMA_SCALES = (0.25, 0.5, 1.0, 2.0, 4.0)


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

    n_res = {}

    def residual(x, starts=starts):
        """Every window's residual samples after its state fit, over sqrt(samples per
        window): the cost is half the sum of the windows' mean squared errors."""
        g.set_parameters(dict(zip(names, x * scale)))
        try:
            e = np.asarray(shooting(g, U, Y, starts, samples=True), dtype=float)
        except ValueError as exc:           # a diverging trial point: a large, finite error
            if starts.size not in n_res:    # ... but the start itself: nothing to refine
                raise ValueError(f"output error: the starting estimate's windows cannot be "
                                 f"simulated ({exc})") from exc
            return np.full(n_res[starts.size], 1e3)
        e = e.reshape(starts.size, -1)
        n_res[starts.size] = e.size
        return e.ravel() / np.sqrt(e.shape[1])

    full = list(g.theta_)
    cols = [full.index(p) for p in names]

    def jacobian(x, starts=starts):
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
            E = np.asarray(shooting(g, U, Y, starts, thetas=TH, samples=True), dtype=float)
            E = E.reshape(len(names) + 1, -1) / np.sqrt(E.size / ((len(names) + 1) * starts.size))
            f0, F = E[0], E[1:]
        except ValueError:
            f0 = residual(x, starts)
            F = np.array([residual(x + h[j] * np.eye(len(names))[j], starts)
                          for j in range(len(names))])
        return ((F - f0[None, :]) / h[:, None]).T

    r0 = residual(x0)
    W = starts.size
    ftol = 0.01 / max(r0.size - len(names), 1)
    sol = least_squares(residual, x0, jac=jacobian, bounds=(lo, hi), max_nfev=MAX_EVALUATIONS,
                        ftol=ftol)
    evaluations = int(sol.nfev)
    sd = A = None
    for _ in range(MAX_RESTARTS + 1):      # stop at a tenth of the sandwich's sigma (above)
        try:
            sd, A, n = window_covariance(g, U, Y, starts, shooting, names, sol.x, scale, lo, hi)
        except (ValueError, np.linalg.LinAlgError):
            sd = None
            break
        F = 0.5 * float(sol.fun @ sol.fun)
        # a move of a tenth of sigma_j along the valley (the others following) changes F by
        # 0.005 sigma_j^2 / (A^-1)_jj / n: the smallest such change, as a share of F
        need = 0.005 * float(np.min(sd ** 2 / np.diag(np.linalg.pinv(A)))) / n / max(F, 1e-300)
        if not np.isfinite(need) or need >= ftol or evaluations >= MAX_EVALUATIONS:
            break
        ftol = max(need, 1e-15)
        sol = least_squares(residual, sol.x, jac=jacobian, bounds=(lo, hi),
                            max_nfev=MAX_EVALUATIONS - evaluations, ftol=ftol)
        evaluations += int(sol.nfev)
    theta = dict(zip(names, map(float, sol.x * scale)))
    g.set_parameters(theta)
    at_bound = [p for p, b in zip(names, _at_bound(sol.x, lo, hi)) if b]
    std = {p: float(sd[j] * scale[j]) if sd is not None and np.isfinite(sd[j]) and sd[j] > 0
           and p not in at_bound else float("nan") for j, p in enumerate(names)}
    return theta, {"window_rms_before": float(np.sqrt(r0 @ r0 / W)),
                   "window_rms_after": float(np.sqrt(sol.fun @ sol.fun / W)),
                   "evaluations": evaluations, "status": sol.message, "std": std,
                   "std_method": "cluster-robust sandwich, windows as clusters",
                   "at_bound": at_bound}


def _bounded_start(g, names, bounds: dict, n_states: int) -> tuple:
    """(scale, lower, upper, start) of a least-squares problem over ``g``'s parameters
    ``names`` (in units of their current values, strictly inside finite bounds) followed by
    ``n_states`` unbounded state offsets starting at zero."""
    th0 = np.array([g.theta_[p] for p in names], dtype=float)
    scale = np.where(np.abs(th0) > 0, np.abs(th0), 1.0)
    lo = np.r_[np.array([bounds.get(p, (-np.inf, np.inf))[0] for p in names]) / scale,
               np.full(n_states, -np.inf)]
    hi = np.r_[np.array([bounds.get(p, (-np.inf, np.inf))[1] for p in names]) / scale,
               np.full(n_states, np.inf)]
    P = len(names)
    gap = 1e-9 * (1.0 + np.abs(th0 / scale))
    z0 = np.r_[np.clip(th0 / scale, np.where(np.isfinite(lo[:P]), lo[:P] + gap, -np.inf),
                       np.where(np.isfinite(hi[:P]), hi[:P] - gap, np.inf)), np.zeros(n_states)]
    return scale, lo, hi, z0


def joint_refine(g, U, Y, starts, bounds: dict, norm, horizon: int, dt: float,
                 integrator: str, at_bound: dict | None = None) -> dict:
    """Multiple shooting with the windows' initial states as decision variables beside the
    parameters: GreyBox ``g``'s estimated parameters and every window's state (positions and
    velocities, as offsets from the measured position and the backward difference) minimise
    the windows' simulation error together, one sparse least-squares problem
    (``scipy.optimize.least_squares``, trust-region reflective with LSMR; the Jacobian's state
    columns are each window's own, forward differences with every window's state component
    perturbed in one batch). Started from ``g`` (the nested refinement's optimum, :func:`refine`)
    and the measured states; leaves ``g`` at the optimum and returns a report.

    Why beside :func:`refine`: there each window's state is fitted by one linearised
    least-squares step inside the cost. Where the motion switches (a dry friction's sign) the
    step's linearisation error is larger for the true model than for a smoother one, so the
    nested cost is lowest at dry friction traded for viscous. Measured (session 11) on the
    README's joint (independent generator, seed 0): window error at the truth against the
    nested estimate 7.88e-7 / 7.74e-7 after one state step, 6.21e-7 / 6.42e-7 after four;
    the nested estimate Fc -17 %, Dm +5.2 %, this one every parameter within 0.4 %. (Iterating
    the nested state fit instead made the cost move in steps with the parameters: the rigid
    axis of tests/residual/test_simulation_error.py then gave Fc -8 %.)

    The report's ``std``: the standard deviations of this problem at its optimum
    (:func:`joint_covariance`, module doc), NaN where they cannot be formed and for a parameter
    at one of its bounds (this optimum's own, and those in ``at_bound``, ``{parameter: distance}``,
    the nested refinement's, while this estimate is within that distance of the bound, the
    nested fit's tolerance in its own units: this problem's units are the nested optimum's,
    near zero for an estimate on a bound at zero): there the windows' scores do not sum to zero
    and the sandwich does not hold (random joint seed 2, Dl at its bound 0: sigma 7e-17). A
    parameter the joint fit moves off the nested fit's bound is not on it (random joint seed
    22, stick-slip: Kd at 0 in the nested fit, 0.37 in the joint one, was reported without a
    sigma)."""
    names = list(g.estimated_)
    P = len(names)
    scale, lo, hi, z0 = _bounded_start(g, names, bounds, 2 * Y.shape[1] * starts.size)
    win = _JointWindows(g, U, Y, starts, names, scale, norm, horizon, dt, integrator)
    W, n_res, k = starts.size, win.n_res, P + 2 * win.m

    def residual(z):
        try:
            return win.errors(z).reshape(-1)
        except ValueError:                  # a diverging trial point: a large, finite error
            return np.full(n_res, 1e3)

    # the Jacobian's sparsity, row by row: the P parameter columns, then the 2m state columns
    # of the row's window (the values in the same order)
    rows = np.arange(n_res)
    jac_rows = np.repeat(rows, k)
    jac_cols = np.c_[np.tile(np.arange(P), (n_res, 1)),
                     P + 2 * win.m * (rows // (n_res // W))[:, None]
                     + np.arange(2 * win.m)].ravel()

    def jacobian(z):
        try:
            _, D = win.sensitivities(z, _steps(z[:P], lo[:P], hi[:P]), STATE_STEP)
        except ValueError:
            D = np.zeros((k, W, n_res // W))
        return sparse.csr_matrix((np.transpose(D, (1, 2, 0)).ravel(), (jac_rows, jac_cols)),
                                 shape=(n_res, z0.size))

    r0 = residual(z0)
    sol = least_squares(residual, z0, jac=jacobian, bounds=(lo, hi), method="trf",
                        tr_solver="lsmr", x_scale="jac", max_nfev=MAX_EVALUATIONS,
                        ftol=0.01 / max(n_res - z0.size, 1))
    theta = dict(zip(names, map(float, sol.x[:P] * scale)))
    g.set_parameters(theta)
    try:
        sd = joint_covariance(win, sol.x, lo[:P], hi[:P])
    except (ValueError, np.linalg.LinAlgError):
        sd = np.full(P, np.nan)
    near = dict(at_bound or {})
    est = sol.x[:P] * scale[:P]
    gap = np.minimum(est - lo[:P] * scale[:P], hi[:P] * scale[:P] - est)
    at_bound = [p for p, b, d in zip(names, _at_bound(sol.x[:P], lo[:P], hi[:P]), gap)
                if b or (p in near and d <= near[p])]
    std = {p: float(sd[j] * scale[j]) if np.isfinite(sd[j]) and sd[j] > 0 and p not in at_bound
           else float("nan") for j, p in enumerate(names)}
    return {"at_bound": at_bound, "window_rms_before": float(np.sqrt(r0 @ r0 / W)),
            "window_rms_after": float(np.sqrt(sol.fun @ sol.fun / W)),
            "evaluations": int(sol.nfev), "status": sol.message, "std": std,
            "std_method": "cluster-robust sandwich, windows as clusters, each window's "
                          "state projected out",
            "method": "multiple shooting, the windows' states estimated with the parameters"}


class _JointWindows:
    """The windows of :func:`joint_refine`'s problem: decision vector z = the estimated
    parameters ``names`` over ``scale``, then per window its state offsets (positions over
    sqrt(norm), velocities over sqrt(norm) / (horizon dt)) from the measured position and the
    backward difference; residuals per window over sqrt(norm) / sqrt(horizon outputs)."""

    def __init__(self, g, U, Y, starts, names, scale, norm, horizon, dt, integrator):
        self.g, self.U, self.Y, self.starts = g, U, Y, starts
        self.H, self.m, self.W = int(horizon), Y.shape[1], starts.size
        self.P, self.scale, self.integrator = len(names), scale, integrator
        full = list(g.theta_)
        self.cols = [full.index(p) for p in names]
        self.base = np.array([g.theta_[p] for p in full], dtype=float)
        self.sx = np.sqrt(np.asarray(norm, dtype=float))   # state offsets in the outputs' scale
        self.sv = self.sx / (self.H * float(dt))
        self.w = 1.0 / self.sx / np.sqrt(self.H * self.m)
        self.idx = starts[None, :] + np.arange(1, self.H + 1)[:, None]
        self.xm = Y[starts].astype(float)
        self.vm = (Y[starts] - Y[starts - 1]) / float(dt)
        self.n_res = self.W * self.H * self.m

    def _batch(self, z, G):
        """(thetas, positions, velocities) of ``G`` groups at ``z``."""
        o = z[self.P:].reshape(self.W, 2 * self.m)
        th = self.base.copy()
        th[self.cols] = z[:self.P] * self.scale
        return (np.tile(th, (G, 1)), np.tile(self.xm + o[:, :self.m] * self.sx, (G, 1)),
                np.tile(self.vm + o[:, self.m:] * self.sv, (G, 1)))

    def _run(self, TH, X, V) -> np.ndarray:                # (groups, W, H m)
        out = self.g.windows(self.U, self.Y, np.tile(self.starts, TH.shape[0]), self.H, X, V,
                             integrator=self.integrator,
                             thetas=TH).reshape(self.H, TH.shape[0], self.W, self.m)
        return np.transpose((out - self.Y[self.idx][:, None]) * self.w, (1, 2, 0, 3)).reshape(
            TH.shape[0], self.W, self.H * self.m)

    def errors(self, z) -> np.ndarray:
        """The residuals at ``z``, (W, H m)."""
        return self._run(*self._batch(z, 1))[0]

    def sensitivities(self, z, h, hs, central: bool = False) -> tuple:
        """(residuals (W, H m), their differences (P + 2m, W, H m)) at ``z``: forward
        (``central`` False) or central differences, steps ``h`` for the parameters and ``hs``
        for every window's state components (each component of every window perturbed in one
        group), every group of one batched simulation."""
        P, m, W = self.P, self.m, self.W
        k = P + 2 * m
        signs = (1.0, -1.0) if central else (1.0,)
        TH, X, V = self._batch(z, 1 + k * len(signs))
        for i, sg in enumerate(signs):
            g0 = 1 + i * k
            for j in range(P):
                TH[g0 + j, self.cols[j]] = (z[j] + sg * h[j]) * self.scale[j]
            for j in range(m):
                X[(g0 + P + j) * W:(g0 + P + j + 1) * W, j] += sg * hs * self.sx[j]
                V[(g0 + P + m + j) * W:(g0 + P + m + j + 1) * W, j] += sg * hs * self.sv[j]
        R = self._run(TH, X, V)
        step = np.r_[h, np.full(2 * m, hs)][:, None, None]
        D = (R[1:1 + k] - R[1 + k:]) / (2 * step) if central else (R[1:] - R[:1]) / step
        return R[0], D


def joint_covariance(win: _JointWindows, z, lo, hi) -> np.ndarray:
    """Standard deviations (scaled coordinates) of :func:`joint_refine`'s parameters at its
    optimum ``z`` (module doc): per window the residual e_w, the parameters' sensitivities
    Jp_w and the window's own state sensitivities Js_w; the states projected out exactly
    (Jp_w - Js_w Js_w^+ Jp_w), then the cluster-robust sandwich over windows. A first pass
    with the optimiser's forward steps, then central differences over :data:`SIGMA_SCALES`
    times that pass's sigma (as :func:`window_covariance`'s second pass, each step at least
    the optimiser's, at most a tenth of the value, inside the bounds) and per parameter the
    median of their sigmas: a friction switch that one step's difference crosses moves that
    step's sigma (module doc), the median leaves it out."""
    P = win.P
    h = _steps(z[:P], lo, hi)
    first = _projected_sandwich(*win.sensitivities(z, h, STATE_STEP), P)
    sds = []
    for f in SIGMA_SCALES:
        wide = _wide_steps(f * first, h, z[:P], lo, hi)
        if np.all(wide > 0):
            sds.append(_projected_sandwich(*win.sensitivities(z, wide, STATE_STEP, central=True),
                                           P))
    return np.median(sds, axis=0) if sds else first


def _projected_sandwich(e, D, P: int) -> np.ndarray:
    """sqrt(diag(cov)) of the cluster-robust sandwich (:func:`_cluster_sandwich`) of the first
    ``P`` of the sensitivities ``D`` (columns, W, n) with the rest (each window's own nuisance
    columns) projected out per window (their singular directions above ``sqrt(eps)`` of the
    largest, as the nested state fit's cut)."""
    J = np.transpose(D, (1, 2, 0))                                  # (W, n, columns)
    Jp, Js = J[..., :P], J[..., P:]
    Q, s, _ = np.linalg.svd(Js, full_matrices=False)
    keep = s > np.sqrt(np.finfo(float).eps) * s[:, :1]
    Q = Q * keep[:, None, :]
    Jp = Jp - Q @ (np.transpose(Q, (0, 2, 1)) @ Jp)
    return _cluster_sandwich(Jp, e)[0]


def window_covariance(g, U, Y, starts, shooting, names, x, scale, lo, hi) -> tuple:
    """Standard deviations (scaled coordinates) of the parameters ``names`` at the scaled
    optimum ``x`` (module doc), the Gauss-Newton matrix A and the samples per window: the
    windows' residuals after the state fit and their sensitivities, the cluster-robust
    sandwich over windows. Two passes: forward differences at the optimiser's steps, then
    central differences over one standard deviation of that first pass (at least the
    optimiser's step, at most a tenth of the value, inside the bounds): a plain sign's
    switching instants move with the parameters, so differences over 1e-4 of a value see the
    jumps of single switches (measured on a link-PD record with dry friction: the stiffness'
    sigma 0.0003 % against an error of 0.17 %); the spread that matters is that of the
    estimate, so the sensitivities are taken over its scale."""
    h = _steps(x, lo, hi)
    sd, A, n = _sandwich(g, U, Y, starts, shooting, names, x, scale, h, central=False)
    wide = _wide_steps(sd, h, x, lo, hi)
    if np.all(wide > 0):
        sd, A, n = _sandwich(g, U, Y, starts, shooting, names, x, scale, wide, central=True)
    return sd, A, n


def _wide_steps(sd, h, x, lo, hi) -> np.ndarray:
    """The second pass's steps: one first-pass standard deviation ``sd``, at least the
    optimiser's step ``h``, at most a tenth of the value, inside the bounds."""
    room = np.minimum(x - lo, hi - x)
    wide = np.clip(sd, np.abs(h), 0.1 * np.maximum(np.abs(x), np.abs(h)))
    return np.where(np.isfinite(wide), np.minimum(wide, 0.999 * room), np.abs(h))


def _sandwich(g, U, Y, starts, shooting, names, x, scale, h, central: bool) -> tuple:
    """(sqrt(diag(A^-1 B A^-1 W / (W - p))), A, samples per window) in the scaled
    coordinates (module doc), the sensitivities by forward (``central`` False) or central
    differences of steps ``h``, every perturbed parameter set a group of one batched
    simulation."""
    full = list(g.theta_)
    cols = [full.index(p) for p in names]
    P = len(names)
    signs = (1.0, -1.0) if central else (1.0,)
    TH = np.tile(np.array([g.theta_[p] for p in full]), (1 + P * len(signs), 1))
    TH[:, cols] = x * scale
    for i, sg in enumerate(signs):
        for j in range(P):
            TH[1 + i * P + j, cols[j]] = (x[j] + sg * h[j]) * scale[j]
    R = shooting(g, U, Y, starts, thetas=TH, samples=True)      # (groups, W, H m)
    e = R[0]
    if central:
        D = (R[1:1 + P] - R[1 + P:]) / (2 * h[:, None, None])
    else:
        D = (R[1:] - e[None]) / h[:, None, None]
    sd, A = _cluster_sandwich(np.transpose(D, (1, 2, 0)), e)
    return sd, A, e.shape[1]


def _cluster_sandwich(J, e) -> tuple:
    """(sqrt(diag(A^-1 B A^-1 W / (W - p))), A) of sensitivities ``J`` (W, n, p) and
    residuals ``e`` (W, n): A = sum_w J_w' J_w, B the windows' scores J_w' e_w (module doc)."""
    A = np.einsum("wnp,wnq->pq", J, J)
    score = np.einsum("wnp,wn->wp", J, e)
    W, P = score.shape
    Ai = np.linalg.pinv(A)
    cov = Ai @ (score.T @ score) @ Ai * (W / max(W - P, 1))
    return np.sqrt(np.maximum(np.diag(cov), 0.0)), A


def _at_bound(x, lo, hi) -> np.ndarray:
    """Which scaled estimates ``x`` (units of their starting values) ended on a bound: within
    :data:`BOUND_TOL` of it. The trust-region reflective method approaches a bound
    geometrically and stops strictly inside it (random joint seed 2: Dl at 3.8e-7 of its
    starting value, so scipy's ``active_mask``, at ``xtol`` 1e-8, did not flag it)."""
    return (x - lo <= BOUND_TOL) | (hi - x <= BOUND_TOL)


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




def runs(mask, trim: int, min_length: int) -> list:
    """Contiguous (start, stop) row ranges where ``mask`` is true, clear of the record's
    ``trim`` edges and at least ``min_length`` rows long."""
    m = np.asarray(mask, dtype=bool).copy()
    n = m.size
    m[:max(int(trim), 1)] = False
    m[max(n - int(trim), 0):] = False
    d = np.diff(np.r_[0, m.astype(np.int8), 0])
    out = [(int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1))]
    return [(a, b) for a, b in out if b - a >= int(min_length)]


def simulation_refine(g, U, Y, segments, bounds: dict, norm, integrator: str,
                      chunk: int) -> tuple[dict, dict]:
    """Full-length simulation-error refinement of GreyBox ``g`` (fitted): each segment
    ``(a, b)`` of the record simulated open loop from row ``a`` to row ``b - 1``, the estimated
    parameters and each run's initial state (positions and velocities, started at the measured
    position and the backward difference of rows ``a - 1``, ``a``) chosen by
    ``scipy.optimize.least_squares`` (trust-region reflective, the physical ``bounds``) to
    minimise the mean over samples and outputs of the squared error, each output over ``norm``
    (its variance scale). The initial state is estimated because a differenced velocity's
    noise is carried by an integrating axis into a lasting position error (measured on the
    test's plain-numpy axis, 0.1 mm encoder noise at 1 kHz: the run from the measured state at
    the true parameters has a normalised RMS error 0.075; fitted from it the parameters trade
    it away, Fv -1.6 %, Fc +2.5 %). Where the multiple-shooting refinement (:func:`refine`)
    fits the dynamics over the motion's correlation time, this one fits what a free run of the
    model accumulates (a small friction error turns into a drift): which of them, if either,
    the loop keeps is decided on held-out data (``BlockedCV``, ``estimator="sim"``).

    Forward differences of relative step :data:`DIFF_STEP` for the parameters (measured on the
    test's axis: 1e-3 stopped at Fv +1.2 %, M +5 %, where 1e-4 reaches 0.2 %), every column
    simulated in one batch. Standard deviations: the cluster-robust sandwich (as
    :func:`refine`'s) with the runs' ``chunk``-sample pieces as clusters; pieces of one run
    share its drift, so these are optimistic. Returns (theta, info)."""
    names = list(g.estimated_)
    P = len(names)
    m = Y.shape[1]
    segments = [(int(a), int(b)) for a, b in segments if b - a >= 3]
    if not segments:
        raise ValueError("segments: no run of at least 3 rows to simulate")
    S = len(segments)
    dt = float(g.dt)
    w = 1.0 / np.sqrt(np.asarray(norm, dtype=float))
    # the initial states' offsets in units of the outputs' scale (positions) and of that scale
    # over ``chunk`` samples (velocities)
    sx = np.sqrt(np.asarray(norm, dtype=float))
    sv = sx / (max(int(chunk), 1) * dt)
    scale, lo, hi, x0 = _bounded_start(g, names, bounds, 2 * m * S)
    full = list(g.theta_)
    cols = [full.index(p) for p in names]
    n_res = sum((b - a - 1) * m for a, b in segments)
    base = np.array([g.theta_[p] for p in full])

    def state(x, i):
        a = segments[i][0]
        off = x[P + 2 * m * i:P + 2 * m * (i + 1)]
        return Y[a] + off[:m] * sx, (Y[a] - Y[a - 1]) / dt + off[m:] * sv

    def run(i, TH, X0, V0):
        a, b = segments[i]
        out = g.windows(U, Y, np.repeat([a], TH.shape[0]), b - a - 1, X0, V0,
                        integrator=integrator, thetas=TH)                 # (L, G, m)
        return ((out - Y[a + 1:b][:, None]) * w).transpose(1, 0, 2).reshape(TH.shape[0], -1) \
            / np.sqrt(n_res)

    def theta_rows(x, h=None):
        TH = np.tile(base, (1 if h is None else P + 1, 1))
        TH[:, cols] = x[:P] * scale
        if h is not None:
            for j in range(P):
                TH[j + 1, cols[j]] = (x[j] + h[j]) * scale[j]
        return TH

    def residual(x):
        try:
            TH = theta_rows(x)
            return np.concatenate([run(i, TH, *(z[None] for z in state(x, i)))[0]
                                   for i in range(S)])
        except ValueError:                  # a diverging trial point: a large, finite error
            return np.full(n_res, 1e3 / np.sqrt(n_res))

    def jacobian(x):
        h = _steps(x[:P], lo[:P], hi[:P], DIFF_STEP)
        hs = 1e-4
        J = np.zeros((n_res, P + 2 * m * S))
        row = 0
        TH = theta_rows(x, h)
        TH = np.vstack([TH, np.repeat(TH[:1], 2 * m, axis=0)])
        for i in range(S):
            xs, vs = state(x, i)
            X0 = np.repeat(xs[None], TH.shape[0], axis=0)
            V0 = np.repeat(vs[None], TH.shape[0], axis=0)
            for j in range(m):
                X0[P + 1 + j, j] += hs * sx[j]
                V0[P + 1 + m + j, j] += hs * sv[j]
            try:
                E = run(i, TH, X0, V0)
            except ValueError:
                E = np.full((TH.shape[0], (segments[i][1] - segments[i][0] - 1) * m),
                            1e3 / np.sqrt(n_res))
            k = E.shape[1]
            J[row:row + k, :P] = ((E[1:P + 1] - E[0]) / h[:, None]).T
            J[row:row + k, P + 2 * m * i:P + 2 * m * (i + 1)] = ((E[P + 1:] - E[0]) / hs).T
            row += k
        return J

    r0 = residual(x0)
    # stop where an improvement is statistically nothing (as :func:`refine`'s first stop)
    ftol = 0.01 / max(n_res - x0.size, 1)
    sol = least_squares(residual, x0, jac=jacobian, bounds=(lo, hi), max_nfev=MAX_EVALUATIONS,
                        ftol=ftol)
    theta = dict(zip(names, map(float, sol.x[:P] * scale)))
    g.set_parameters(theta)
    # the sandwich over chunks of the runs (clusters), at the optimum's Jacobian
    J, e = np.asarray(sol.jac), np.asarray(sol.fun)
    k = max(int(chunk), 1) * m
    cid = np.concatenate([np.arange((b - a - 1) * m) // k + i * (n_res + 1)
                          for i, (a, b) in enumerate(segments)])
    _, cid = np.unique(cid, return_inverse=True)
    Sc = np.zeros((cid.max() + 1, J.shape[1]))
    np.add.at(Sc, cid, J * e[:, None])
    Ai = np.linalg.pinv(J.T @ J)
    C = Sc.shape[0]
    cov = Ai @ (Sc.T @ Sc) @ Ai * (C / max(C - J.shape[1], 1))
    sd = np.sqrt(np.maximum(np.diag(cov)[:P], 0.0))
    std = {p: float(sd[j] * scale[j]) if np.isfinite(sd[j]) and sd[j] > 0 else float("nan")
           for j, p in enumerate(names)}
    return theta, {"rms_before": float(np.sqrt(r0 @ r0)), "rms_after": float(np.sqrt(e @ e)),
                   "segments": [[a, b] for a, b in segments], "evaluations": int(sol.nfev),
                   "status": sol.message, "std": std, "integrator": integrator,
                   "std_method": f"cluster-robust sandwich, {int(chunk)}-sample pieces of the "
                                 "runs as clusters (optimistic: pieces of a run share its drift)"}
