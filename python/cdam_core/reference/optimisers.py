"""BOA, IBOA and CABC, numpy reference (twins of cpp/include/cdam/optim/*.hpp).

The algorithms, every reconstructed choice and the order in which random numbers are drawn are
documented in the C++ headers (boa.hpp, iboa.hpp, cabc.hpp, kmeans.hpp, chaos.hpp); this file
follows them step by step with the shared :class:`~cdam_core.reference.rng.Rng`, so that for
the same seed and options the best-fitness-per-iteration curve equals the C++ one (to rounding:
sums are ordered differently, so agreement is to about 1e-12 relative, not bit for bit).

Populations are (n, D) arrays, one row per individual (the same memory as C++'s D x n
column-major matrix). Objectives are callables ``f(x) -> float`` of a (D,) vector (minimised);
:class:`BpObjective` is the BP fitness: training MSE sum((T - Y)^2) / (N m) of the network
whose parameters are x.

Options (a dict; unknown keys raise ValueError), with the C++ defaults:
- all: ``n`` = 20 (population; for CABC the colony size Np, n // 2 food sources),
  ``iterations`` = 50 (Tmax), ``lb`` = -1, ``ub`` = 1.
- boa, iboa: ``p`` = 0.8, ``c`` = 0.01, ``a`` = 0.1, ``form`` = "author" | "paper".
- iboa: ``clusters`` = 3, ``kmeans_iters`` = 10, ``phi`` = 0.1, ``chaos_candidates`` = 5,
  ``chaos_form`` = "convex" | "additive", ``chaos_scale`` = 0.1.
- cabc: ``limit`` = 20, ``scout_candidates`` = 5, ``scout_radius`` = 0.1.

Every function returns a dict: best (D,), best_fitness, curve (iterations + 1: after the
initialisation, then after each iteration), evaluations, positions (n, D), fitness (n,).
"""
from __future__ import annotations

import math

import numpy as np

from cdam_core.reference._checks import activation as check_activation
from cdam_core.reference._checks import float_array, integer, real, same_rows
from cdam_core.reference.mlp import _forward
from cdam_core.reference.rng import Rng

__all__ = ["BpObjective", "boa", "iboa", "cabc", "kmeans", "LogisticMap", "DEFAULTS"]

_COMMON = {"n": 20, "iterations": 50, "lb": -1.0, "ub": 1.0}
_BOA = {"p": 0.8, "c": 0.01, "a": 0.1, "form": "author"}
_IBOA = {"clusters": 3, "kmeans_iters": 10, "phi": 0.1, "chaos_candidates": 5,
         "chaos_form": "convex", "chaos_scale": 0.1}
_CABC = {"limit": 20, "scout_candidates": 5, "scout_radius": 0.1}
DEFAULTS = {"boa": {**_COMMON, **_BOA}, "iboa": {**_COMMON, **_BOA, **_IBOA},
            "cabc": {**_COMMON, **_CABC}}
_INTS = {"n", "iterations", "clusters", "kmeans_iters", "chaos_candidates", "limit",
         "scout_candidates"}
_CHOICES = {"form": ("author", "paper"), "chaos_form": ("convex", "additive")}


def _options(algo: str, options) -> dict:
    o = dict(DEFAULTS[algo])
    for k, v in dict(options or {}).items():
        if k not in o:
            raise ValueError(f"options: unknown key {k!r} for {algo} (known: {', '.join(sorted(o))})")
        if k in _INTS:
            o[k] = integer(v, f"options[{k!r}]")
        elif k in _CHOICES:
            if v not in _CHOICES[k]:
                raise ValueError(f"options[{k!r}]: unknown {v!r}; use one of {_CHOICES[k]}")
            o[k] = v
        else:
            o[k] = real(v, f"options[{k!r}]")
    n = o["n"]
    if o["iterations"] < 0:
        raise ValueError("options['iterations']: must be >= 0")
    if not o["lb"] < o["ub"]:
        raise ValueError("options['lb']: must be < options['ub']")
    if algo == "cabc":
        if n < 4:
            raise ValueError("options['n']: CABC needs n >= 4 (two food sources)")
        if o["limit"] < 0 or not 1 <= o["scout_candidates"] <= n or not o["scout_radius"] > 0:
            raise ValueError("options: need limit >= 0, 1 <= scout_candidates <= n, "
                             "scout_radius > 0")
        return o
    if n < 2:
        raise ValueError("options['n']: BOA needs n >= 2")
    if not 0 <= o["p"] <= 1 or not o["c"] > 0:
        raise ValueError("options: need 0 <= p <= 1 and c > 0")
    if algo == "iboa" and (not 1 <= o["clusters"] <= n or o["kmeans_iters"] < 1
                           or not 0 <= o["chaos_candidates"] <= n or not o["chaos_scale"] > 0):
        raise ValueError("options: need 1 <= clusters <= n, kmeans_iters >= 1, "
                         "0 <= chaos_candidates <= n, chaos_scale > 0")
    return o


class BpObjective:
    """BP fitness: MSE sum((T - Y)^2) / (N m) of the network (i-hidden-m) given by theta.

    X (N, i) and T (N, m) are the normalised training inputs and targets.
    """

    def __init__(self, X, T, hidden: int, activation: str = "tansig"):
        self.X = float_array(X, "X", 2, dtype=np.float64)
        self.T = float_array(T, "T", 2, dtype=np.float64)
        same_rows(self.X, self.T, "X", "T")
        self.hidden = integer(hidden, "hidden", minimum=1)
        self.activation = check_activation(activation)
        i, m = self.X.shape[1], self.T.shape[1]
        self.dim = i * self.hidden + self.hidden + self.hidden * m + m

    def __call__(self, theta) -> float:
        th = np.asarray(theta, dtype=np.float64)
        if th.shape != (self.dim,):
            raise ValueError(f"theta: expected shape ({self.dim},), got {th.shape}")
        y = _forward(th, self.X, self.hidden, self.T.shape[1], self.activation)[0]
        e = self.T - y
        return float(np.sum(e * e) / e.size)


class LogisticMap:
    """z <- (4 z)(1 - z) with the guard of chaos.hpp; seed() takes one draw."""

    FALLBACK = 0.123456789

    def __init__(self, z: float = 0.7):
        self.z = z

    @staticmethod
    def guard(v: float) -> float:
        eps = 1e-12
        if (not (eps < v < 1.0 - eps) or abs(v - 0.25) < eps or abs(v - 0.5) < eps
                or abs(v - 0.75) < eps):
            return LogisticMap.FALLBACK
        return v

    def seed(self, rng: Rng) -> None:
        self.z = self.guard(0.05 + 0.9 * rng.uniform())

    def next(self) -> float:
        self.z = self.guard(4.0 * self.z * (1.0 - self.z))
        return self.z

    def take(self, count: int) -> np.ndarray:
        return np.array([self.next() for _ in range(count)])


def kmeans(x: np.ndarray, k: int, iters: int, rng: Rng):
    """Lloyd's k-means on the rows of x (kmeans.hpp: seeding draws, ties, empty clusters).

    Returns (centres (k, D), labels (n,)).
    """
    n = x.shape[0]
    perm = list(range(n))
    centres = np.empty((k, x.shape[1]))
    for c in range(k):
        j = c + rng.index(n - c)
        perm[c], perm[j] = perm[j], perm[c]
        centres[c] = x[perm[c]]
    label = np.full(n, -1)
    for _ in range(iters):
        d2 = np.array([[np.sum((x[i] - centres[c]) ** 2) for c in range(k)] for i in range(n)])
        new = np.argmin(d2, axis=1)  # first minimum: ties to the lowest index
        if np.array_equal(new, label):
            break
        label = new
        for c in range(k):
            members = np.flatnonzero(label == c)
            if members.size == 0:
                continue
            acc = np.zeros(x.shape[1])
            for i in members:
                acc += x[i]
            acc /= float(members.size)
            centres[c] = acc
    return centres, label


class _Swarm:
    def __init__(self, x, fit):
        self.x = x
        self.fit = fit
        self.trial = x.copy()
        self.trial_fit = fit.copy()
        b = int(np.argmin(fit))
        self.best = x[b].copy()
        self.best_fit = float(fit[b])
        self.evaluations = len(fit)


def _evaluate(f, X) -> np.ndarray:
    return np.array([float(f(row)) for row in X])


def _uniform_init(f, dim, o, rng) -> _Swarm:
    lb, ub = o["lb"], o["ub"]
    x = lb + (ub - lb) * rng.uniform_array(o["n"] * dim).reshape(o["n"], dim)
    return _Swarm(x, _evaluate(f, x))


def _boa_move(s, from_x, i, fp, o, rng, paper) -> np.ndarray:
    n = from_x.shape[0]
    if rng.uniform() < o["p"]:
        if paper:
            r1 = rng.uniform()
            r = r1 * r1
        else:
            r1 = rng.uniform()
            r2 = rng.uniform()
            r = r1 * r2
        v = from_x[i] + (r * s.best - from_x[i]) * fp
    else:
        e = rng.uniform()
        r = e * e
        j = rng.index(n)
        k = rng.index(n - 1)
        if k >= j:
            k += 1
        v = from_x[i] + (r * from_x[j] - from_x[k]) * fp
    return np.clip(v, o["lb"], o["ub"])


def _boa_iterate(s: _Swarm, f, o, rng, c: float) -> float:
    a = o["a"]
    if o["form"] == "author":
        for i in range(s.x.shape[0]):
            fp = c * math.pow(abs(s.trial_fit[i]), a)
            s.trial[i] = _boa_move(s, s.x, i, fp, o, rng, False)
            fv = float(f(s.trial[i]))
            s.evaluations += 1
            s.trial_fit[i] = fv
            if fv <= s.fit[i]:
                s.x[i] = s.trial[i]
                s.fit[i] = fv
            if fv <= s.best_fit:
                s.best = s.trial[i].copy()
                s.best_fit = fv
    else:
        for i in range(s.x.shape[0]):
            fp = c * math.pow(abs(s.fit[i]), a)
            s.trial[i] = _boa_move(s, s.x, i, fp, o, rng, True)
        s.trial_fit = _evaluate(f, s.trial)
        s.evaluations += s.x.shape[0]
        s.x = s.trial.copy()
        s.fit = s.trial_fit.copy()
        for i in range(s.x.shape[0]):
            if s.fit[i] <= s.best_fit:
                s.best = s.x[i].copy()
                s.best_fit = float(s.fit[i])
    return c + 0.025 / (c * o["iterations"])


def _result(s: _Swarm, curve, live=None) -> dict:
    live = s.x.shape[0] if live is None else live
    return {"best": s.best.copy(), "best_fitness": s.best_fit, "curve": np.array(curve),
            "evaluations": s.evaluations, "positions": s.x[:live].copy(),
            "fitness": np.array(s.fit[:live])}


def _check_objective(objective, dim):
    if not callable(objective):
        raise ValueError("objective: must be callable f(x) -> float")
    return integer(dim, "dim", minimum=1)


def boa(objective, dim: int, *, seed: int = 0, options=None) -> dict:
    """BOA (boa.hpp): author's semantics by default, ``options['form'] = 'paper'`` for the
    paper's equations."""
    dim = _check_objective(objective, dim)
    o = _options("boa", options)
    rng = Rng(seed)
    s = _uniform_init(objective, dim, o, rng)
    c = o["c"]
    curve = [s.best_fit]
    for _ in range(o["iterations"]):
        c = _boa_iterate(s, objective, o, rng, c)
        curve.append(s.best_fit)
    return _result(s, curve)


def _competitive(s: _Swarm, f, o, rng) -> None:
    n, D = s.x.shape
    k = o["clusters"]
    centres, label = kmeans(s.x, k, o["kmeans_iters"], rng)
    winner = [-1] * k
    for i in range(n):
        c = label[i]
        if winner[c] < 0 or s.fit[i] < s.fit[winner[c]]:
            winner[c] = i
    phi = o["phi"]
    losers, cands = [], []
    for i in range(n):
        c = label[i]
        w = winner[c]
        if w == i:
            continue
        r1 = rng.uniform_array(D)
        r2 = rng.uniform_array(D)
        xl = s.x[i]
        cands.append(np.clip(xl + r1 * (s.x[w] - xl) + phi * r2 * (centres[c] - xl),
                             o["lb"], o["ub"]))
        losers.append(i)
    if not losers:
        return
    fits = _evaluate(f, cands)
    s.evaluations += len(losers)
    for q, i in enumerate(losers):
        if fits[q] <= s.fit[i]:
            s.x[i] = cands[q]
            s.fit[i] = fits[q]
        if s.fit[i] <= s.best_fit:
            s.best = s.x[i].copy()
            s.best_fit = float(s.fit[i])


def _elite(s: _Swarm, f, o, chaos: LogisticMap, t: int) -> None:
    m = o["chaos_candidates"]
    if m == 0:
        return
    lb, ub = o["lb"], o["ub"]
    T = float(o["iterations"])
    lam = (T - t + 1.0) / T if T > 0 else 1.0
    cands = []
    for _ in range(m):
        z = chaos.take(s.x.shape[1])
        if o["chaos_form"] == "convex":
            v = (1.0 - lam) * s.best + lam * (lb + z * (ub - lb))
        else:
            v = s.best + o["chaos_scale"] * (ub - lb) * (2.0 * z - 1.0)
        cands.append(np.clip(v, lb, ub))
    fits = _evaluate(f, cands)
    s.evaluations += m
    b = int(np.argmin(fits))
    if fits[b] < s.best_fit:
        s.best = cands[b].copy()
        s.best_fit = float(fits[b])
        w = int(np.argmax(s.fit))
        s.x[w] = s.best
        s.fit[w] = s.best_fit


def iboa(objective, dim: int, *, seed: int = 0, options=None) -> dict:
    """IBOA (iboa.hpp): BOA + k-means competitive learning + chaotic elite learning."""
    dim = _check_objective(objective, dim)
    o = _options("iboa", options)
    rng = Rng(seed)
    s = _uniform_init(objective, dim, o, rng)
    chaos = LogisticMap()
    chaos.seed(rng)
    c = o["c"]
    curve = [s.best_fit]
    for t in range(1, o["iterations"] + 1):
        c = _boa_iterate(s, objective, o, rng, c)
        _competitive(s, objective, o, rng)
        _elite(s, objective, o, chaos, t)
        curve.append(s.best_fit)
    return _result(s, curve)


def cabc(objective, dim: int, *, seed: int = 0, options=None) -> dict:
    """Chaotic ABC (cabc.hpp): chaotic initialisation, employed, onlooker and chaotic scout."""
    dim = _check_objective(objective, dim)
    o = _options("cabc", options)
    rng = Rng(seed)
    sn = o["n"] // 2
    lb, ub = o["lb"], o["ub"]
    chaos = LogisticMap()
    chaos.seed(rng)
    x = np.empty((sn, dim))
    for i in range(sn):
        x[i] = lb + chaos.take(dim) * (ub - lb)
    s = _Swarm(x, _evaluate(objective, x))
    counter = [0] * sn

    def neighbour(i):
        j = rng.index(dim)
        k = rng.index(sn - 1)
        if k >= i:
            k += 1
        phi = -1.0 + 2.0 * rng.uniform()
        v = s.x[i].copy()
        v[j] = min(max(s.x[i, j] + phi * (s.x[i, j] - s.x[k, j]), lb), ub)
        fv = float(objective(v))
        s.evaluations += 1
        if fv < s.fit[i]:
            s.x[i] = v
            s.fit[i] = fv
            counter[i] = 0
            if fv < s.best_fit:
                s.best = v.copy()
                s.best_fit = fv
        else:
            counter[i] += 1

    curve = [s.best_fit]
    for _ in range(o["iterations"]):
        for i in range(sn):
            neighbour(i)
        w = [1.0 / (1.0 + fi) if fi >= 0 else 1.0 + abs(fi) for fi in s.fit]
        total = 0.0
        for wi in w:
            total += wi
        for _ in range(sn):
            u = rng.uniform() * total
            pick, acc = sn - 1, 0.0
            for i in range(sn):
                acc += w[i]
                if acc > u:
                    pick = i
                    break
            neighbour(pick)
        scout = int(np.argmax(counter))
        if counter[scout] > o["limit"]:
            R = o["scout_radius"]
            cands = [np.clip(s.best + R * (ub - lb) * (2.0 * chaos.take(dim) - 1.0), lb, ub)
                     for _ in range(o["scout_candidates"])]
            fits = _evaluate(objective, cands)
            s.evaluations += len(cands)
            b = int(np.argmin(fits))
            s.x[scout] = cands[b]
            s.fit[scout] = fits[b]
            counter[scout] = 0
            if fits[b] < s.best_fit:
                s.best = cands[b].copy()
                s.best_fit = float(fits[b])
        curve.append(s.best_fit)
    return _result(s, curve)
