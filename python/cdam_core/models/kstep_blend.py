"""Predictors blended per prediction step and group of outputs: kind ``kstep_blend``.

Components P_0 .. P_J (fitted models of any kind on the same inputs and outputs, each run k
steps from the measured outputs on its own, as the protocol's k-step prediction defines) are
combined per step k and output i with convex weights::

    y_k,i = sum_j lambda_{k,i,j} P_j,k,i,     lambda >= 0,  sum_j lambda = 1

The weights are the same for every output of a group (``groups``: a label per output) and are
chosen (``choose``) on records held out of the components' training, per step and group:

- pooled (:func:`simplex_weights`): the lambda on the simplex of least summed squared k-step
  error over those records' windows and the group's outputs (a convex quadratic program,
  solved exactly by enumerating its active sets); on those records no group is then worse at
  any step than any single component (each vertex of the simplex is a candidate);
- worst unit (:func:`minimax_weights`, ``units``: a label per row, e.g. the record): the point
  of a grid of the simplex whose largest ratio over the units of its squared error to the
  reference's (component 0) is least; on no unit is a group then worse than the reference at
  any step.

Steps beyond the weights' rows take the last row
(free run). One-step prediction is the step-1 blend.

A blend only reports: every component runs on its own predictions (nothing blended is fed
back), so each keeps its own dynamics.
"""
from __future__ import annotations

import itertools
from typing import ClassVar

import numpy as np

from cdam_core.base.checks import positive_int
from cdam_core.models.protocol import Model
from cdam_core.models.schema import field_array

__all__ = ["KStepBlend", "simplex_weights", "minimax_weights", "blend_sums", "simplex_grid",
           "rule_weights", "unit_errors", "held_out_score", "held_out_ratios",
           "held_out_gate", "GATES", "RULES"]


def _qp_simplex(G, b):
    """argmin_w w'G w - 2 b'w over w >= 0, sum w <= 1 (G symmetric PSD, n x n): the best
    feasible KKT point over every active set (free variables; sum constraint on or off)."""
    n = b.size
    best, best_f = np.zeros(n), 0.0
    for r in range(1, n + 1):
        for S in itertools.combinations(range(n), r):
            S = list(S)
            Gs, bs = G[np.ix_(S, S)], b[S]
            cands = [np.linalg.lstsq(Gs, bs, rcond=None)[0]]
            K = np.zeros((r + 1, r + 1))
            K[:r, :r], K[:r, r], K[r, :r] = Gs, 1.0, 1.0
            sol = np.linalg.lstsq(K, np.concatenate([bs, [1.0]]), rcond=None)[0]
            cands.append(sol[:r])
            for ws in cands:
                if np.any(ws < -1e-12) or ws.sum() > 1 + 1e-12:
                    continue
                w = np.zeros(n)
                w[S] = np.clip(ws, 0.0, None)
                if w.sum() > 1:
                    w /= w.sum()
                f = w @ G @ w - 2 * b @ w
                if f < best_f - 1e-15 * max(1.0, abs(best_f)):
                    best, best_f = w, f
    return best


def blend_sums(P, Y):
    """Per output, the sums the weights need from one step's predictions of the J + 1
    components ``P`` (J + 1, rows, m) and the measured ``Y`` (rows, m): (G (m, J, J),
    b (m, J)), G_jl = sum d_j d_l, b_j = sum d_j e, d_j = P_j - P_0, e = Y - P_0."""
    P = np.asarray(P, float)
    D = P[1:] - P[0]
    e = np.asarray(Y, float) - P[0]
    return np.einsum("jri,lri->ijl", D, D), np.einsum("jri,ri->ij", D, e)


def simplex_weights(G, b, labels):
    """Weights (steps, m, J + 1) on the simplex from per-step sums (``blend_sums`` summed over
    records): G (steps, m, J, J), b (steps, m, J); per step and group (``labels``, one per
    output) the sums over the group's outputs, then ``_qp_simplex``; lambda_0 = 1 - sum of
    the others."""
    G, b = np.asarray(G, float), np.asarray(b, float)
    steps, m, J = b.shape
    lab = np.asarray(labels)
    if lab.size != m:
        raise ValueError(f"groups: {lab.size} labels for {m} outputs")
    W = np.zeros((steps, m, J + 1))
    for k in range(steps):
        for g in np.unique(lab):
            sel = lab == g
            w = _qp_simplex(G[k, sel].sum(axis=0), b[k, sel].sum(axis=0))
            W[k, sel, 1:] = w
            W[k, sel, 0] = 1.0 - w.sum()
    return W


def simplex_grid(J, resolution):
    """Every w with w_j in {0, 1/r, .., 1} and sum w <= 1 (J columns), w = 0 first."""
    pts = [p for p in itertools.product(range(resolution + 1), repeat=J) if sum(p) <= resolution]
    return np.asarray(pts, dtype=float).reshape(-1, J) / resolution


def minimax_weights(G, b, c, labels, resolution: int = 100):
    """Weights (steps, m, J + 1) on the simplex from per-unit sums (units: e.g. one record of
    each kind): G (units, steps, m, J, J), b (units, steps, m, J) as ``blend_sums`` gives them,
    c (units, steps, m) the reference's sum of squared errors. Per step and group (``labels``)
    the point of ``simplex_grid(J, resolution)`` whose largest ratio over the units of its
    squared error to the reference's is least (the first such point: ties keep the
    reference)."""
    G, b, c = np.asarray(G, float), np.asarray(b, float), np.asarray(c, float)
    n_units, steps, m, J = b.shape
    lab = np.asarray(labels)
    if lab.size != m:
        raise ValueError(f"groups: {lab.size} labels for {m} outputs")
    pts = simplex_grid(J, int(resolution))
    W = np.zeros((steps, m, J + 1))
    for k in range(steps):
        for g in np.unique(lab):
            sel = lab == g
            Gg, bg, cg = G[:, k, sel].sum(axis=1), b[:, k, sel].sum(axis=1), c[:, k, sel].sum(1)
            f = (cg[:, None] - 2 * bg @ pts.T
                 + np.einsum("pj,ujl,pl->up", pts, Gg, pts))        # (units, points)
            ratio = f / np.where(cg > 0, cg, 1.0)[:, None]
            w = pts[int(np.argmin(ratio.max(axis=0)))]
            W[k, sel, 1:] = w
            W[k, sel, 0] = 1.0 - w.sum()
    return W


RULES = ("worst", "pooled")


def rule_weights(G, b, c, labels, rule: str, resolution: int = 100):
    """Weights (steps, m, J + 1) from per-unit sums (``KStepBlend.sums``) by ``rule``:
    ``"worst"`` (``minimax_weights`` over the units) or ``"pooled"`` (``simplex_weights`` of
    the sums over the units)."""
    if rule == "worst":
        return minimax_weights(G, b, c, labels, resolution)
    if rule == "pooled":
        return simplex_weights(np.sum(G, axis=0), np.sum(b, axis=0), labels)
    raise ValueError(f"rule: unknown {rule!r}; use {' or '.join(RULES)}")


def unit_errors(W, G, b, c):
    """Each unit's summed squared error (units, steps, m) of the weights W (steps, m, J + 1)
    from its sums (``KStepBlend.sums``): c - 2 b'w + w'G w, w the weights of components
    1..J."""
    w = np.asarray(W, float)[..., 1:]
    return (np.asarray(c, float) - 2 * np.einsum("uhij,hij->uhi", b, w)
            + np.einsum("hij,uhijl,hil->uhi", w, G, w))


def held_out_ratios(G, b, c, labels, rule: str, resolution: int = 100):
    """Leave-one-unit-out ratios of a rule (units, steps, groups): for each unit, the weights
    chosen by ``rule`` on the other units and that unit's RMSE relative to the reference's
    (component 0) per step and group (groups in the order of ``np.unique(labels)``; 1: the
    reference's error). Needs at least two units."""
    G, b, c = np.asarray(G, float), np.asarray(b, float), np.asarray(c, float)
    nu = b.shape[0]
    if nu < 2:
        raise ValueError(f"units: {nu} given; a held-out score needs at least two")
    lab = np.asarray(labels)
    out = np.zeros((nu, b.shape[1], np.unique(lab).size))
    for u in range(nu):
        rest = [v for v in range(nu) if v != u]
        W = rule_weights(G[rest], b[rest], c[rest], labels, rule, resolution)
        f = unit_errors(W, G[u:u + 1], b[u:u + 1], c[u:u + 1])[0]        # (steps, m)
        for j, g in enumerate(np.unique(lab)):
            num, den = f[:, lab == g].sum(axis=1), c[u][:, lab == g].sum(axis=1)
            out[u, :, j] = np.sqrt(np.clip(num, 0, None) / np.where(den > 0, den, 1.0))
    return out


def held_out_score(G, b, c, labels, rule: str, resolution: int = 100) -> float:
    """Leave-one-unit-out score of a rule: ``held_out_ratios`` averaged over units, steps and
    groups (1: the reference; lower is better). Needs at least two units."""
    return float(np.mean(held_out_ratios(G, b, c, labels, rule, resolution)))


GATES = ("every", "mean")


def held_out_gate(W, G, b, c, labels, rule: str, resolution: int = 100, need: str = "every",
                  ratios=None):
    """The weights W (steps, m, J + 1) with each step's and group's weights replaced by the
    reference alone (component 0) where the held-out units do not prefer the blend: the blend
    is kept at step k in group g only when the weights ``rule`` chooses on the other units
    have a lower error there than the reference on every unit (``need="every"``:
    ``held_out_ratios`` < 1 for every unit) or on the mean over the units (``need="mean"``:
    their mean < 1, the criterion ``held_out_score`` applies to the whole curve). ``ratios``:
    ``held_out_ratios``' result when already computed. Returns (gated weights, kept
    (steps, groups) bool)."""
    if need not in GATES:
        raise ValueError(f"need: unknown {need!r}; use {' or '.join(GATES)}")
    W = np.array(W, dtype=float, copy=True)
    lab = np.asarray(labels)
    r = held_out_ratios(G, b, c, labels, rule, resolution) if ratios is None else \
        np.asarray(ratios, float)
    kept = np.all(r < 1.0, axis=0) if need == "every" else np.mean(r, axis=0) < 1.0
    for j, g in enumerate(np.unique(lab)):
        for k in np.flatnonzero(~kept[:, j]):
            W[k, lab == g] = 0.0
            W[k, lab == g, 0] = 1.0
    return W, kept


class KStepBlend(Model):
    """Fitted components blended per step and group (module doc).

    Args:
        components: models (any kinds) of the same inputs and outputs; the first is the
            reference (its weight is what the others leave).
            ``fit`` refits each of them (the weights kept).
        weights: (steps, outputs, components) convex weights, or None (chosen by ``choose``).
        groups: a group label per output (None: each output alone).
    """

    kind = "kstep_blend"
    fits_segments = True
    #: kind -> class of the components a file may hold: the model file's registry, set by
    #: ``models.file`` (which imports every kind; importing it here would be a cycle)
    component_kinds: ClassVar[dict] = {}

    def __init__(self, components=(), weights=None, groups=None):
        self.components = components
        self.weights = weights
        self.groups = groups
        comps = list(components)
        if not comps:
            raise ValueError("components: none given")
        for j, c in enumerate(comps):
            if not isinstance(c, Model):
                raise ValueError(f"components[{j}]: expected a model")
            if not c.dynamic:
                raise ValueError(f"components[{j}]: a static map has no k-step prediction")
        if groups is not None and np.ndim(groups) != 1:
            raise ValueError("groups: expected one label per output")
        if weights is not None:
            w = np.asarray(weights, dtype=float)
            if w.ndim != 3 or w.shape[0] < 1 or w.shape[2] != len(comps):
                raise ValueError(f"weights: expected (steps, outputs, {len(comps)})")
            if not np.all(np.isfinite(w)) or np.any(w < -1e-12) or \
                    np.any(np.abs(w.sum(axis=2) - 1) > 1e-9):
                raise ValueError("weights: each step's and output's weights must be >= 0 "
                                 "and sum to 1")
        self.components_ = comps
        if all(c.is_fitted() for c in comps):
            self._setup()

    def _setup(self):
        """Sizes from the fitted components, checked against each other and the weights."""
        comps = self.components_
        for j, c in enumerate(comps):
            if (c.n_inputs_, c.n_outputs_) != (comps[0].n_inputs_, comps[0].n_outputs_):
                raise ValueError(f"components[{j}]: other inputs or outputs than the first")
        m = comps[0].n_outputs_
        if self.groups is not None and len(self.groups) != m:
            raise ValueError(f"groups: {len(self.groups)} labels for {m} outputs")
        if self.weights is not None:
            w = np.asarray(self.weights, dtype=float)
            if w.shape[1] != m:
                raise ValueError(f"weights: {w.shape[1]} outputs, the components have {m}")
            self.weights_ = w.copy()
        self.n_inputs_, self.n_outputs_ = comps[0].n_inputs_, m
        self.y_start_ = getattr(comps[0], "y_start_", None)

    @property
    def t0(self) -> int:
        return max(c.t0 for c in self.components_)

    def _labels(self):
        m = self.n_outputs_
        return np.arange(m) if self.groups is None else \
            np.unique(np.asarray(self.groups), return_inverse=True)[1]

    def _w(self, k):
        """Weights (m, J + 1) of step k >= 1."""
        if getattr(self, "weights_", None) is None:
            raise ValueError("KStepBlend: no weights; call choose(U, Y, segments) first")
        return self.weights_[min(int(k), self.weights_.shape[0]) - 1]

    def _fit(self, U, Y, bounds=None):
        """Every component refitted on (U, Y); the weights kept (given or chosen before)."""
        if getattr(self, "weights_", None) is None and self.weights is None:
            raise ValueError("weights: none; fit the components, then choose(U, Y) on records "
                             "held out of their training")
        for c in self.components_:
            c.fit(U, Y, segments=bounds)
        self._setup()

    # -- the components' rollouts, aligned ---------------------------------------------------
    def _joint_rollout(self, U, Y, horizon, segments=None, first=1):
        """(k, rows, P (J + 1, rows, m)) for k = 1..horizon: every component's rollout on the
        same origins and chunks."""
        U, Y = np.asarray(U, float), np.asarray(Y, float)
        start = max(self.t0, 1, int(first))
        width, m = self.t0 + int(horizon), self.n_outputs_
        chunk = max(256, (1 << 22) // (width * (m + U.shape[1]) * len(self.components_)))
        gens = [c.rollout(U, Y, horizon, segments=segments, first=start, chunk=chunk)
                for c in self.components_]
        for parts in zip(*gens):
            k, rows = parts[0][0], parts[0][1]
            if any(p[0] != k or not np.array_equal(p[1], rows) for p in parts):
                raise RuntimeError("components: rollouts not aligned")   # pragma: no cover
            yield k, rows, np.stack([p[2] for p in parts])

    def sums(self, U, Y, segments=None, horizon: int = 50, units=None):
        """The sums the weights need from records (U, Y, segments) held out of the
        components' training: (G (units, horizon, m, J, J), b (units, horizon, m, J),
        c (units, horizon, m)) as ``blend_sums`` gives them per step (c: the reference's
        summed squared error), one block per label of ``units`` (a label per row; None: one
        unit)."""
        horizon = positive_int(horizon, "horizon")
        if not all(c.is_fitted() for c in self.components_):
            raise ValueError("components: fit every component before choosing the weights")
        self._setup()
        m, J = self.n_outputs_, len(self.components_) - 1
        Y = np.asarray(Y, float)
        if units is None:
            code = np.zeros(len(Y), int)
        else:
            if np.shape(units) != (len(Y),):
                raise ValueError(f"units: expected one label per row ({len(Y)})")
            code = np.unique(np.asarray(units), return_inverse=True)[1].ravel()
        nu = int(code.max()) + 1 if code.size else 1
        G, b = np.zeros((nu, horizon, m, J, J)), np.zeros((nu, horizon, m, J))
        c = np.zeros((nu, horizon, m))
        n = 0
        for k, rows, P in self._joint_rollout(U, Y, horizon, segments):
            for u in range(nu):
                r = code[rows] == u
                g, v = blend_sums(P[:, r], Y[rows[r]])
                G[u, k - 1] += g
                b[u, k - 1] += v
                c[u, k - 1] += np.sum((Y[rows[r]] - P[0, r]) ** 2, axis=0)
            n += rows.size
        if not n:
            raise ValueError(f"U: no window of {horizon} steps in the records")
        return G, b, c

    def choose(self, U, Y, segments=None, horizon: int = 50, units=None,
               resolution: int = 100):
        """Choose the weights (``horizon`` steps) on records (U, Y, segments) held out of the
        components' training (module doc); returns self. ``units``: a label per row (e.g. the
        record, or the record's kind): then per step and group the weights on a grid of the
        simplex (``resolution``) whose worst unit's error relative to the reference is least
        (``minimax_weights``) instead of the least squares pooled over the rows."""
        G, b, c = self.sums(U, Y, segments, horizon, units)
        rule = "pooled" if units is None else "worst"
        self.weights_ = rule_weights(G, b, c, self._labels(), rule, resolution)
        return self

    # -- prediction ----------------------------------------------------------------------------
    def rollout(self, U, Y, horizon: int, segments=None, first: int = 1, chunk=None):
        """``Model.rollout``: each step's component predictions blended."""
        self._w(1)
        for k, rows, P in self._joint_rollout(U, Y, horizon, segments, first):
            yield k, rows, np.einsum("ij,jri->ri", self._w(k), P)

    def _one_step(self, U, Y):
        t0 = self.t0
        parts = [c._one_step(U, Y)[t0 - c.t0:] for c in self.components_]
        return np.einsum("ij,jri->ri", self._w(1), np.stack(parts))

    def _k_step(self, U, Y, k):
        P = np.array(Y, dtype=float, copy=True)
        lo = self.t0 + k - 1               # the rows every component predicts
        if P.shape[0] > lo:
            parts = [c._k_step(U, Y, k)[lo:] for c in self.components_]
            P[lo:] = np.einsum("ij,jri->ri", self._w(k), np.stack(parts))
        return P

    def _free_run(self, U, Y0):
        t0, n = self.t0, U.shape[0]
        parts = []
        for c in self.components_:                   # each from the same t0 measured rows
            ct = c.t0
            parts.append(c._free_run(U[t0 - ct:], Y0[t0 - ct:t0]))
        steps = np.arange(1, n - t0 + 1)
        W = np.stack([self._w(j) for j in steps]) if steps.size else \
            np.zeros((0, self.n_outputs_, len(parts)))
        return np.einsum("tij,jti->ti", W, np.stack(parts))

    def parameters(self) -> dict:
        """The reference component's parameters."""
        return dict(self.components_[0].parameters())

    # -- file ------------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        self._w(1)
        return {"components": [{"kind": c.kind, "model": c.to_dict()}
                               for c in self.components_],
                "groups": None if self.groups is None else [int(g) for g in self._labels()],
                "weights": [[[float(v) for v in row] for row in step]
                            for step in self.weights_]}

    @classmethod
    def from_dict(cls, d: dict) -> "KStepBlend":
        KINDS = cls.component_kinds
        comps = []
        for j, c in enumerate(d["components"]):
            kind = c.get("kind") if isinstance(c, dict) else None
            if kind not in KINDS or kind == cls.kind:
                raise ValueError(f"model.components[{j}].kind: unknown {kind!r}")
            try:
                comps.append(KINDS[kind].from_dict(c["model"]))
            except ValueError as exc:
                raise ValueError(str(exc).replace("model.", f"model.components[{j}].", 1)) \
                    from None
        if not comps:
            raise ValueError("model.components: none given")
        m, J = comps[0].n_outputs_, len(comps)
        steps = len(d["weights"]) if isinstance(d["weights"], list) else 0
        w = field_array(np.asarray(d["weights"], dtype=float).ravel().tolist(),
                        "model.weights", (steps * m * J,)).reshape(steps, m, J)
        try:
            return cls(comps, w, d["groups"])
        except ValueError as exc:
            raise ValueError(f"model.{exc}") from None
