"""IDIM-LS estimation of a declared model (plus effects) and its free-run (output) simulation.

Estimation: stack every equation's rows ``y = Phi theta`` over the record (the first and last
``trim`` samples, where the zero-phase filter and the differences have edge effects, are left
out), move fixed parameters to the left side, solve with ``numpy.linalg.lstsq``. Weighted
(IDIM-WLS, Gautier): when the prepared signals hold ``weights`` (``{equation: w}``, set by
:func:`set_equation_weights` as 1 / the RMS of each equation's ordinary least-squares
residual), each equation's rows are multiplied by its weight, so a noisy equation (the link
equations of the flight model, whose body accelerations are twice-differentiated position
noise) does not bias the parameters it shares with a clean one (the cable stiffness in the
motor equation). The residuals stay in physical units; :attr:`Fit.sse` is the weighted sum.
Two stages (a model's ``eiv_equations``, errors-in-variables equations: the flight model's link
equations): in a block that holds them beside clean equations, the parameters with a column in
a clean equation are estimated from the clean equations alone, then the EIV equations estimate
the remaining parameters with those held (lexicographic least squares, the limit of the
weighted stack as the EIV weight tends to 0; :func:`stage_split`); sums of squares over clean
and EIV equations together read the clean ones (:meth:`Fit.wsse`).
Free run: integrate the same equations forward from the measured inputs alone (semi-implicit
Euler, ``substeps`` per sample chosen so that h * |lambda|max <= 0.5 for the linearised model).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from cdam_core.models.greybox.declared import identity as _ident, memo as _memo
from cdam_core.models.greybox.effects import Effect


def _cached(memo, key, held, compute):
    if memo is None:
        return compute()
    got = memo.get(key)
    return memo.put(key, held, compute()) if got is None else got


def _hashable(x) -> bool:
    try:
        hash(x)
    except TypeError:
        return False
    return True


def apply_effects(model, sig: dict, effects) -> dict:
    s = sig.copy()
    memo = _memo(sig, "transform", 64)
    for stage in ("transform_inputs", "transform_state"):
        for e in effects:
            fn = getattr(e, stage)
            if getattr(type(e), stage, None) is getattr(Effect, stage):
                continue   # the identity: the effect only adds columns
            if memo is None or not _hashable(e):
                s = fn(s, model)
                continue
            key = (stage, id(model), e, _ident(s))
            got = memo.get(key)
            if got is None:
                got = fn(s, model)
                if got is not s:   # a transform (not the identity): kept for the next fit
                    memo.put(key, (model, e, tuple(s.values())), got)
            s = got
    if memo is not None and effects:   # a copy of its own, as without the memo
        out = sig.copy()
        out.clear()
        out.update(s)
        s = out
    return s


class _Columns:
    """Low-passed columns of one record (parallel filtering), found by content: a slot per
    (equation, column, filter) holds the last used (source, filtered, id) entries; a source is
    matched by identity, else by equal values. Equal ids mean equal content (the signatures
    :func:`fit` compares to take a block over from an earlier fit)."""

    PER_SLOT = 32   # a 1-D search's points and the current model's column (least recently used out)
    PROBES = 4

    _ids = itertools.count(1)   # content ids unique in the process (a base from any record)

    def __init__(self):
        self.slots: dict = {}

    def _probes(self, a) -> list:
        n = a.shape[0]
        return [a.item(i * (n - 1) // (self.PROBES - 1)) for i in range(self.PROBES)]

    def find(self, slot, a):
        entries = self.slots.get(slot)
        if not entries:
            return None
        i = next((i for i, e in enumerate(entries) if e[0] is a), None)
        if i is None:
            probes = self._probes(a)
            i = next((i for i, e in enumerate(entries)
                      if e[3] == probes and np.array_equal(e[0], a)), None)
        if i is None:
            return None
        hit = entries[i]
        if i != len(entries) - 1:   # most recently used last
            del entries[i]
            entries.append(hit)
        return hit

    def add(self, slot, a, filtered):
        e = (a, filtered, next(self._ids), self._probes(a))
        entries = self.slots.setdefault(slot, [])
        entries.append(e)
        if len(entries) > self.PER_SLOT:
            del entries[0]
        return e


def design(model, sig: dict, effects=()) -> tuple[dict, dict]:
    """The transformed signals and ``{equation: (y, {parameter: column})}`` with effects added.

    The model's equations, each effect's columns and the low-passed columns are kept per
    record (``sig.cache``) and found again by the identity of the signals they came from
    (:class:`Memo`), the low-passed ones by content (:class:`_Columns`): a structure search
    re-fits the same columns many times."""
    s = apply_effects(model, sig, effects)
    key = _ident(s)
    held = (model, tuple(s.values()))
    eqs0 = _cached(_memo(sig, "equations", 32), (id(model), key), held,
                   lambda: model.equations(s))
    eqs = {k: (y, dict(cols)) for k, (y, cols) in eqs0.items()}
    memo = _memo(sig, "regressors", 256)
    for e in effects:
        cols_e = _cached(memo if _hashable(e) else None, (id(model), e, key), (held, e),
                         lambda: e.regressors(s, model))
        for eq, cols in cols_e.items():
            if eq not in eqs:
                raise ValueError(f"effects: {e.key} adds to unknown equation {eq!r}")
            eqs[eq][1].update(cols)
    if getattr(model, "parallel_filter", False) and "filter" in s:
        n = np.asarray(s["t"]).size
        cache = sig.cache.get("lowpass") if hasattr(sig, "cache") else None
        if not isinstance(cache, _Columns):
            cache = _Columns()
            if hasattr(sig, "cache"):
                sig.cache["lowpass"] = cache
        out, sigs = {}, {}
        for eq, (y, cols) in eqs.items():
            f = model.equation_filter(eq, s)
            names = ["__y"] + list(cols)
            arrs = [np.broadcast_to(np.asarray(c, dtype=float), (n,)) if not (
                isinstance(c, np.ndarray) and c.dtype == float and c.shape == (n,)) else c
                for c in [y] + list(cols.values())]
            slots = [(eq, nm, f) for nm in names]
            got = [cache.find(slot, a) for slot, a in zip(slots, arrs)]
            todo = [i for i, g in enumerate(got) if g is None]
            if todo:
                filtered = f.lowpass(np.column_stack([arrs[i] for i in todo]), s["dt"])
                for j, i in enumerate(todo):
                    got[i] = cache.add(slots[i], arrs[i], filtered[:, j])
            out[eq] = (got[0][1], dict(zip(names[1:], (g[1] for g in got[1:]))))
            sigs[eq] = tuple((nm, g[2]) for nm, g in zip(names, got))
        eqs = out
        if hasattr(s, "signatures"):
            s.signatures = sigs
    return s, eqs


def _reference(model, eq, s, theta, y, n, keep):
    ref = model.reference(eq, s, theta)
    if ref is None:   # the equation's own (filtered) left side
        return np.broadcast_to(np.asarray(y, dtype=float), (n,))[keep]
    return np.broadcast_to(np.asarray(ref, dtype=float), (n,))[keep]


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
    columns: dict = field(default_factory=dict)   # equation -> estimated parameters in it
    weights: dict = field(default_factory=dict)   # equation -> WLS weight (missing: 1)
    std: dict = field(default_factory=dict)       # estimated parameter -> standard deviation
    # physical feasibility: parameters whose unconstrained estimate broke the model's bounds
    # (then refitted with the bounds: ``unconstrained`` holds the first estimates)
    violations: list = field(default_factory=list)
    unconstrained: dict = field(default_factory=dict)
    # sums of squares already formed: id(array) -> (array, sum); a structure search asks the
    # current fit for them once per candidate (residual arrays are never changed in place)
    _squares: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def _sq(self, a) -> float:
        hit = self._squares.get(id(a))
        if hit is None or hit[0] is not a:
            hit = self._squares[id(a)] = (a, np.sum(a ** 2))
        return hit[1]

    def _stage(self, equations) -> list:
        """``equations`` as the two-stage (lexicographic) objective reads them: where they hold
        clean equations, the model's errors-in-variables equations are left out (they
        estimate nothing the clean ones determine: the limit of a vanishing EIV weight, to
        first order); EIV equations alone are read as they are."""
        eqs = list(self.residuals if equations is None else equations)
        eiv = set(getattr(self.model, "eiv_equations", ()) or ())
        clean = [e for e in eqs if e not in eiv]
        return clean if clean and eiv else eqs

    def wsse(self, equations=None) -> float:
        """Weighted sum of squared residuals over ``equations`` (default: all; see
        :meth:`_stage` for a model with errors-in-variables equations)."""
        return float(sum(self.weights.get(e, 1.0) ** 2 * self._sq(self.residuals[e])
                         for e in self._stage(equations)))

    def wref(self, equations=None) -> float:
        """Weighted sum of squares of the reference signals over ``equations`` (as
        :meth:`wsse`)."""
        return float(sum(self.weights.get(e, 1.0) ** 2 * self._sq(self.references[e])
                         for e in self._stage(equations)))

    @property
    def sse(self) -> float:
        return self.wsse()

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


def _components(eqs: dict, est: list) -> list:
    """Groups of equations linked by shared estimated parameters (independent LS blocks)."""
    parent = {eq: eq for eq in eqs}

    def root(e):
        while parent[e] != e:
            parent[e] = parent[parent[e]]
            e = parent[e]
        return e
    owner = {}
    estset = set(est)
    for eq, (_, cols) in eqs.items():
        for p in cols:
            if p in estset:
                if p in owner:
                    parent[root(eq)] = root(owner[p])
                else:
                    owner[p] = eq
    groups: dict = {}
    for eq in eqs:
        groups.setdefault(root(eq), []).append(eq)
    return list(groups.values())


def fit(model, sig: dict, effects=(), trim: int = 50, base: "Fit | None" = None,
        bounded: bool = False, rows=None) -> Fit:
    """Estimate the parameters of ``model`` with ``effects`` by linear least squares.

    Estimates outside the physical bounds of the model and its effects (``bounds``) are
    listed in :attr:`Fit.violations` (with the estimates in :attr:`Fit.unconstrained`); with
    ``bounded`` the blocks holding them are refitted by bounded least squares. Structure
    searches compare unconstrained fits (a bound would bend the search landscape near a
    parameter whose true value is at its bound, as a motor damping of nearly zero is); the
    model handed to users is the bounded refit.

    Equations that share no estimated parameter are independent least-squares blocks; with
    ``base`` (an earlier fit on the same record) a block whose equations are unchanged (same
    columns, checked by content for the parallel-filtered models) is taken over from ``base``
    instead of being solved again. The estimates are the same either way.

    ``rows``: a boolean mask over the samples; only rows where it is true (and outside the
    trimmed edges) are fitted (cross-validation folds). The residuals are then those rows'.
    """
    effects = tuple(effects)
    n = sig["t"].size
    trim = int(trim)
    if trim < 0 or 2 * trim >= n - 10:
        raise ValueError(f"trim: {trim} leaves too few of the {n} samples")
    keep = slice(trim, n - trim)
    s, eqs = design(model, sig, effects)
    if rows is not None:
        rows = np.asarray(rows)
        if rows.dtype != bool or rows.shape != (n,):
            raise ValueError(f"rows: expected a boolean mask of {n} samples")
    if rows is not None:
        inner = np.zeros(n, dtype=bool)
        inner[keep] = True
        keep = np.flatnonzero(inner & rows)
        if keep.size < 10:
            raise ValueError(f"rows: {keep.size} rows left to fit")
        base = None   # blocks are reused only between fits of the same rows
    # rows an effect cannot describe (a sign term at rest) are left out of the estimation;
    # the residuals still cover every kept row (comparable between fits)
    use = None
    for e in effects:
        moving = e.moving_rows(s, model) if hasattr(e, "moving_rows") else None
        if moving is not None:
            use = moving[keep] if use is None else use & moving[keep]
    if use is not None:
        if int(use.sum()) < 10:
            raise ValueError(f"effects: {int(use.sum())} rows in motion left to fit")
        base = None
    names = []
    for _, cols in eqs.values():
        names += [p for p in cols if p not in names]
    est = [p for p in names if p not in model.fixed]
    sigs = getattr(s, "signatures", None)
    weights = dict(getattr(sig, "weights", None) or {})
    if base is not None and base.weights != weights:
        base = None
    if base is not None and bounded and base.violations:
        base = None   # its blocks were solved without the bounds
    bsigs = getattr(base.signals, "signatures", None) if base is not None else None
    # Normal equations per block, assembled equation by equation (each equation holds only
    # its own columns), formed with einsum (single-threaded: on a busy machine a threaded BLAS
    # on a tall matrix is 10x slower), solved on unit-norm columns so the small systems stay
    # well conditioned.
    theta = dict(model.fixed)
    resid, conds, std = {}, [], {}
    violations, unconstrained = [], {}
    bounds = dict(getattr(model, "bounds", {}) or {})
    for e in effects:
        bounds.update(e.bounds())
    gram = solved = None
    if sigs is not None and use is None:   # kept by the rows and the columns' content ids
        rows_key = (keep.start, keep.stop) if isinstance(keep, slice) \
            else (keep.size, hash(keep.tobytes()))
        gram = (_memo(sig, "gram", 64), rows_key, keep)
        solved = _memo(sig, "blocks", 256)
    for comp in _components(eqs, est):
        if (sigs is not None and bsigs is not None and isinstance(base.keep, slice)
                and base.keep == keep
                and all(bsigs.get(eq) == sigs[eq] for eq in comp)):
            for eq in comp:
                resid[eq] = base.residuals[eq]
                for p in base.columns.get(eq, []):
                    theta[p] = base.theta[p]
                    if p in base.std:
                        std[p] = base.std[p]
                    if p in base.unconstrained:
                        unconstrained[p] = base.unconstrained[p]
                        violations.append(p)
            continue
        ps_all = [p for p in est if any(p in eqs[eq][1] for eq in comp)]
        key = None
        if solved is not None:   # the same block solved by an earlier fit on this record
            key = (tuple((eq, sigs[eq], weights.get(eq, 1.0)) for eq in comp), rows_key,
                   tuple((p, model.fixed[p]) for eq in comp for p in eqs[eq][1]
                         if p in model.fixed),
                   tuple(bounds.get(p) for p in ps_all), bool(bounded))
            got = solved.get(key)
            if got is not None and (isinstance(keep, slice) or np.array_equal(got[0], keep)):
                _, th_b, res_b, std_b, cond_b, bad_b, unc_b = got
                unconstrained.update(unc_b)
                violations += bad_b
                if cond_b is not None:
                    conds.append(cond_b)
                theta.update(th_b)
                resid.update(res_b)
                std.update(std_b)
                continue
        index = {p: j for j, p in enumerate(ps_all)}
        k = len(ps_all)
        # two stages when the block holds errors-in-variables equations beside clean ones
        split = stage_split(model, {eq: eqs[eq] for eq in comp}, ps_all)
        A = np.zeros((2, k, k))   # normal equations of the clean [0] and the EIV [1] rows
        b = np.zeros((2, k))
        blocks = []
        for eq in comp:
            y, cols = eqs[eq]
            y = np.broadcast_to(np.asarray(y, dtype=float), (n,))[keep].copy()
            for p, c in cols.items():
                if p in model.fixed:
                    y -= model.fixed[p] * np.asarray(c, dtype=float)[keep]
            ps = [p for p in cols if p in index]
            X, XtX = _columns(eq, ps, cols, n, keep, y.size, use, sigs, gram)
            if not np.all(np.isfinite(y)):
                raise ValueError("signals: the regressors contain NaN or Inf")
            ix = np.array([index[p] for p in ps], dtype=int)
            w2 = weights.get(eq, 1.0) ** 2
            Xu, yu = (X, y) if use is None else (X[use], y[use])
            st = int(split is not None and eq in split[1])
            A[st][np.ix_(ix, ix)] += w2 * XtX
            b[st, ix] += w2 * np.einsum("ij,i->j", Xu, yu)
            blocks.append((eq, y, X, ix))
        scale = np.sqrt(np.diag(A[0] + A[1])).copy()
        scale[scale == 0] = 1.0
        if split is None:
            A, b = A[0] + A[1], b[0] + b[1]
            As = A / np.outer(scale, scale)
            th = np.linalg.lstsq(As, b / scale, rcond=None)[0] / scale if k else np.zeros(0)
        else:
            i1 = np.array([index[p] for p in split[2]], dtype=int)
            i2 = np.array([index[p] for p in split[3]], dtype=int)
            th = _two_stage(A, b, scale, i1, i2)
        lo = np.array([bounds.get(p, (-np.inf, np.inf))[0] for p in ps_all])
        hi = np.array([bounds.get(p, (-np.inf, np.inf))[1] for p in ps_all])
        # a violation counts beyond rounding: in the unit-norm column scaling, further outside
        # the bound than 1e-9 of the block's largest scaled estimate
        tol = 1e-9 * float(np.max(np.abs(th * scale))) if k else 0.0
        bad = [p for j, p in enumerate(ps_all)
               if (lo[j] - th[j]) * scale[j] > tol or (th[j] - hi[j]) * scale[j] > tol]
        unc_b = {p: float(th[index[p]]) for p in bad}
        unconstrained.update(unc_b)
        violations += bad
        if bad and bounded:   # refit this block with the bounds (bounded linear least squares)
            ub = [(eq, y, X, ix) if use is None else (eq, y[use], X[use], ix)
                  for eq, y, X, ix in blocks]
            if split is None:
                th = _bounded(ub, weights, k, scale, lo, hi)
            else:   # stage by stage, each with its parameters' bounds
                th = np.zeros(k)
                th[i1] = _bounded(_restrict([u for u in ub if u[0] not in split[1]], i1, th),
                                  weights, i1.size, scale[i1], lo[i1], hi[i1])
                if i2.size:
                    th[i2] = _bounded(_restrict([u for u in ub if u[0] in split[1]], i2, th),
                                      weights, i2.size, scale[i2], lo[i2], hi[i2])
        cond_b = None
        if k:
            parts = [A] if split is None else [A[0][np.ix_(i1, i1)], A[1][np.ix_(i2, i2)]]
            sc = [scale] if split is None else [scale[i1], scale[i2]]
            cond_b = max(_cond(P / np.outer(c, c)) for P, c in zip(parts, sc) if c.size)
            conds.append(cond_b)
        theta.update(zip(ps_all, map(float, th)))
        wsse, rows = np.zeros(2), np.zeros(2, dtype=int)
        for eq, y, X, ix in blocks:
            resid[eq] = y - np.einsum("ij,j->i", X, th[ix])
            ru = resid[eq] if use is None else resid[eq][use]
            st = int(split is not None and eq in split[1])
            wsse[st] += weights.get(eq, 1.0) ** 2 * float(ru @ ru)
            rows[st] += ru.size
        if split is None:
            std.update(_std(As, scale, float(wsse.sum()), int(rows.sum()), ps_all))
        else:
            std.update(_two_stage_std(A, scale, i1, i2, wsse, rows, ps_all))
        for j, p in enumerate(ps_all):   # at an active bound the covariance formula does not hold
            if bad and bounded and (th[j] <= lo[j] or th[j] >= hi[j]):
                std[p] = float("nan")
        if key is not None:
            solved.put(key, (), (keep, {p: theta[p] for p in ps_all},
                                 {eq: resid[eq] for eq in comp}, {p: std[p] for p in ps_all},
                                 cond_b, list(bad), unc_b))
    if base is not None and len(conds) < len(_components(eqs, est)):
        conds.append(base.cond)
    resid = {eq: resid[eq] for eq in eqs}
    refs = {eq: _reference(model, eq, s, theta, eqs[eq][0], n, keep) for eq in eqs}
    return Fit(model, effects, theta, est, resid, refs, s, keep, max(conds) if conds else 1.0,
               {eq: [p for p in cols if p in est] for eq, (_, cols) in eqs.items()}, weights,
               std, violations, unconstrained)


def _columns(eq, ps, cols, n, keep, rows, use, sigs, gram) -> tuple:
    """An equation's estimated columns over the kept rows and their Gram matrix (over the rows
    in use); with ``gram`` = (a :class:`Memo`, the rows' key, the rows) kept by the rows and
    the columns' content ids (``sigs``)."""
    key = None
    if gram is not None and gram[0] is not None:
        ids = dict(sigs[eq])
        key = (eq, tuple((p, ids[p]) for p in ps)) + gram[1]
        got = gram[0].get(key)
        if got is not None and (isinstance(keep, slice) or np.array_equal(got[2], keep)):
            return got[:2]
    X = np.empty((rows, len(ps)))
    for j, p in enumerate(ps):
        X[:, j] = np.broadcast_to(np.asarray(cols[p], dtype=float), (n,))[keep]
    if not np.all(np.isfinite(X)):
        raise ValueError("signals: the regressors contain NaN or Inf")
    Xu = X if use is None else X[use]
    out = (X, np.einsum("ij,ik->jk", Xu, Xu))
    if key is not None:
        gram[0].put(key, (), out + (gram[2],))
    return out


def stage_split(model, eqs: dict, est) -> tuple | None:
    """The two stages of a block of equations (the model's ``eiv_equations``: errors-in-variables
    equations, whose regressors hold noisy twice-differentiated signals): ``(clean equations,
    EIV equations, first-stage parameters, second-stage parameters)``, or None when the block
    has no EIV equation, no clean one, or they share no estimated parameter (one stage is then
    the same). First stage: every estimated parameter with a column in a clean equation,
    estimated from the clean equations alone; second stage: the rest, from the EIV equations
    with the first stage's values held (:func:`fit`)."""
    eiv_all = set(getattr(model, "eiv_equations", ()) or ())
    eiv = [eq for eq in eqs if eq in eiv_all]
    clean = [eq for eq in eqs if eq not in eiv_all]
    if not eiv or not clean:
        return None
    first = [p for p in est if any(p in eqs[eq][1] for eq in clean)]
    if not any(p in eqs[eq][1] for eq in eiv for p in first):
        return None
    return clean, eiv, first, [p for p in est if p not in first]


def _solve(A, b, scale) -> np.ndarray:
    """Least squares from normal equations on unit-norm columns (numpy's lstsq, its default
    singular-value cut: a parameter the rows do not determine gets the minimum-norm value)."""
    if A.shape[0] == 0:
        return np.zeros(0)
    return np.linalg.lstsq(A / np.outer(scale, scale), b / scale, rcond=None)[0] / scale


def _two_stage(A, b, scale, i1, i2) -> np.ndarray:
    """Lexicographic least squares: the first-stage parameters ``i1`` from the clean rows'
    normal equations ``A[0], b[0]``, then the second-stage ``i2`` from the EIV rows' ``A[1],
    b[1]`` with the first stage held (module docstring of :mod:`.flight`, ``eiv_equations``)."""
    th = np.zeros(scale.size)
    th[i1] = _solve(A[0][np.ix_(i1, i1)], b[0][i1], scale[i1])
    if i2.size:
        rhs = b[1][i2] - A[1][np.ix_(i2, i1)] @ th[i1]
        th[i2] = _solve(A[1][np.ix_(i2, i2)], rhs, scale[i2])
    return th


def _cov(A, scale) -> np.ndarray:
    """(Phi'W Phi)^-1 from the normal matrix ``A`` through its unit-norm column scaling."""
    return np.linalg.pinv(A / np.outer(scale, scale), hermitian=True) / np.outer(scale, scale)


def _two_stage_std(A, scale, i1, i2, wsse, rows, names) -> dict:
    """Standard deviations of the two-stage estimate. First stage: the least-squares formula on
    the clean rows (s1^2 from their weighted SSE over rows - k1). Second stage: its own
    least-squares term s2^2 M^-1 (M the EIV rows' normal matrix of the second-stage parameters)
    plus the first stage's uncertainty carried through the held values, G C1 G' with
    G = M^-1 A21 (Murphy and Topel's two-step correction, the two stages' errors taken as
    independent: different equations, different noise)."""
    out = {}
    k1, k2 = i1.size, i2.size
    if rows[0] <= k1:
        return {p: float("nan") for p in names}
    C1 = wsse[0] / (rows[0] - k1) * _cov(A[0][np.ix_(i1, i1)], scale[i1])
    cov = np.zeros((scale.size, scale.size))
    cov[np.ix_(i1, i1)] = C1
    if k2:
        Mi = _cov(A[1][np.ix_(i2, i2)], scale[i2])
        G = Mi @ A[1][np.ix_(i2, i1)]
        s2 = wsse[1] / (rows[1] - k2) if rows[1] > k2 else float("nan")
        cov[np.ix_(i2, i2)] = s2 * Mi + G @ C1 @ G.T
    d = np.diag(cov)
    for j, p in enumerate(names):
        out[p] = float(np.sqrt(d[j])) if d[j] > 0 else float("nan")
    return out


def _cond(As) -> float:
    sv = np.sqrt(np.maximum(np.linalg.eigvalsh(As)[::-1], 0.0))
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


def _restrict(blocks, sel, th) -> list:
    """Rows of ``blocks`` ((eq, y, X, ix) over a block's parameters) for the parameters ``sel``
    only, the other parameters' columns moved to the left side at their values in ``th``."""
    pos = {int(j): i for i, j in enumerate(sel)}
    out = []
    for eq, y, X, ix in blocks:
        inside = np.array([int(j) in pos for j in ix], dtype=bool)
        y2 = y - X[:, ~inside] @ th[ix[~inside]] if (~inside).any() else y
        out.append((eq, y2, X[:, inside], np.array([pos[int(j)] for j in ix[inside]], dtype=int)))
    return out


def _bounded(blocks, weights, k, scale, lo, hi) -> np.ndarray:
    """Weighted least squares of one block with bounds (scipy.optimize.lsq_linear on the
    column-scaled rows)."""
    from scipy.optimize import lsq_linear
    rows = []
    rhs = []
    for eq, y, X, ix in blocks:
        w = weights.get(eq, 1.0)
        A = np.zeros((y.size, k))
        A[:, ix] = w * X / scale[ix]
        rows.append(A)
        rhs.append(w * y)
    res = lsq_linear(np.vstack(rows), np.concatenate(rhs), bounds=(lo * scale, hi * scale),
                     method="bvls")
    return res.x / scale


def _std(As: np.ndarray, scale: np.ndarray, wsse: float, rows: int, names: list) -> dict:
    """Standard deviations sqrt(diag(s^2 (Phi'W Phi)^-1)), s^2 = weighted SSE / (rows - k),
    the usual least-squares covariance (residuals taken as white: an optimistic figure when
    they are not; the report states so). NaN where the parameter is not identifiable."""
    k = len(names)
    if k == 0 or rows <= k:
        return {p: float("nan") for p in names}
    s2 = wsse / (rows - k)
    cov = np.linalg.pinv(As, hermitian=True) / np.outer(scale, scale)
    d = np.diag(cov)
    return {p: float(np.sqrt(s2 * d[j])) if d[j] > 0 else float("nan")
            for j, p in enumerate(names)}


def set_equation_weights(sig: dict, fitted: Fit) -> dict:
    """Store IDIM-WLS weights in the prepared signals ``sig``: each equation's weight is
    1 / the RMS of its residual in ``fitted`` (scaled so the largest weight is 1); later
    :func:`fit` calls on ``sig`` use them. Returns the weights."""
    rms = {eq: float(np.sqrt(np.mean(r ** 2))) for eq, r in fitted.residuals.items()}
    pos = [v for v in rms.values() if v > 0]
    floor = min(pos) if pos else 1.0
    w = {eq: floor / max(v, floor) for eq, v in rms.items()}
    # (errors-in-variables equations need no further factor: :func:`fit` solves them in a
    # second stage, see :func:`stage_split`)
    if not hasattr(sig, "weights"):
        raise ValueError("sig: expected prepared signals (a Signals from model.prepare)")
    sig.weights = w
    return w


def apply_fit(fitted: Fit, sig: dict, trim: int | None = None) -> Fit:
    """The equation errors of an already estimated model on another record (no re-estimation)."""
    model = fitted.model
    n = sig["t"].size
    first = fitted.keep.start if isinstance(fitted.keep, slice) else int(fitted.keep[0])
    trim = first if trim is None else int(trim)
    if trim < 0 or 2 * trim >= n - 10:
        raise ValueError(f"trim: {trim} leaves too few of the {n} samples")
    keep = slice(trim, n - trim)
    s, eqs = design(model, sig, fitted.effects)
    resid, refs = {}, {}
    for eq, (y, cols) in eqs.items():
        pred = sum(fitted.theta[p] * np.asarray(c, dtype=float) for p, c in cols.items())
        resid[eq] = (np.broadcast_to(np.asarray(y, dtype=float), (n,)) - pred)[keep]
        refs[eq] = _reference(model, eq, s, fitted.theta, y, n, keep)
    return Fit(model, fitted.effects, dict(fitted.theta), list(fitted.estimated), resid, refs, s,
               keep, fitted.cond, dict(fitted.columns), dict(fitted.weights),
               dict(fitted.std), list(fitted.violations), dict(fitted.unconstrained))
