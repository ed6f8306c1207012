"""The network path: the identified network's residual, analysed as the grey-box one.

A one-hidden-layer BP network (``cdam_core.BPNetwork``, Levenberg-Marquardt) is identified as
the inverse model of one equation of a declared model: inputs are that equation's regressors
(the declared model's columns, parallel-filtered as for IDIM-LS, e.g. Z'' + g and Z' for the
vertical force), target the equation's measured left side (e.g. T cos(phi) cos(theta)). Its
residual is tested against every library effect acting on the equation exactly as in
:mod:`.selection` (error reduction ratio, F-test on the effective sample size, BIC); the winning
effect's regressor is added as a network input, the network is re-identified with the same seed
and settings, and the equation error is reported before and after.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

from cdam_core.residual import diagnostics as dg
from cdam_core.models.greybox.effects import candidates as library_candidates
from cdam_core.models.greybox.estimation import design


def _columns(model, sig, effects, eq, keep):
    s, eqs = design(model, sig, effects)
    y, cols = eqs[eq]
    n = sig["t"].size
    y = np.broadcast_to(np.asarray(y, dtype=float), (n,))[keep]
    return y, {p: np.broadcast_to(np.asarray(c, dtype=float), (n,))[keep] for p, c in cols.items()}


def _train(X, y, hidden, epochs, seed):
    from cdam_core.models.network import BPNetwork
    net = BPNetwork(hidden=hidden, epochs=epochs, seed=seed, threads=1)
    net.fit(X, y[:, None])
    r = y - net.predict(X)[:, 0]
    return net, r


def _err(r, y):
    return {"rmse": float(np.sqrt(np.mean(r ** 2))),
            "nrmse": float(np.linalg.norm(r) / np.linalg.norm(y)) if np.any(y) else float("nan")}


def _test(r, cols: list, alpha):
    """LS of the network residual on an effect's columns: ERR, F on N_eff, p, delta BIC."""
    X = np.column_stack(cols)
    X = X - X.mean(axis=0)
    coef, *_ = np.linalg.lstsq(X, r - r.mean(), rcond=None)
    r1 = r - r.mean() - X @ coef
    sse0, sse1 = float(np.sum((r - r.mean()) ** 2)), float(np.sum(r1 ** 2))
    tau = dg.effective_sample_size(r1)["tau_int"]
    n_eff = r.size / tau
    p = X.shape[1]
    dof = max(n_eff - p, 1.0)
    f = ((sse0 - sse1) / p) / (sse1 / dof) if sse1 > 0 else np.inf
    pval = float(stats.f.sf(f, p, dof))
    dbic = n_eff * np.log(max(sse1, 1e-300) / max(sse0, 1e-300)) + p * np.log(n_eff)
    return {"err": (sse0 - sse1) / float(np.sum(r ** 2)), "f_statistic": float(f),
            "p_value": pval, "delta_bic": float(dbic), "n_eff": float(n_eff),
            "significant": bool(pval < alpha and dbic < 0)}


def network_residual(model, sig: dict, equation: str, hidden: int = 6, epochs: int = 60,
                     seed: int = 0, alpha: float = 0.01, trim: int | None = None,
                     declared_effects=(), candidates=None) -> dict:
    """Identify a BP network on ``equation`` of ``model``, name the effect its residual lacks,
    add that effect's regressor as a network input, re-identify, report before and after.

    ``sig``: prepared signals (``model.prepare``). Searched effects (delay, backlash) are tried
    on a 13-point grid of their range and keep the value that explains most of the residual.
    Returns ``{"equation", "inputs", "error_before", "error_after", "winner", "parameters",
    "evidence", "ranking"}`` (``winner`` None and no ``error_after`` when nothing is
    significant).
    """
    if equation not in model.equation_names:
        raise ValueError(f"equation: {model.name} has no equation {equation!r} "
                         f"(equations: {', '.join(model.equation_names)})")
    if int(hidden) < 1 or int(epochs) < 1:
        raise ValueError("hidden/epochs: must be >= 1")
    n = sig["t"].size
    if trim is None:
        ts = getattr(model, "trim_seconds", None)
        trim = 50 if ts is None else max(50, int(round(ts / sig["dt"])))
    if 2 * trim >= n - 10:
        raise ValueError(f"trim: {trim} leaves too few of the {n} samples")
    keep = slice(trim, n - trim)
    declared_effects = tuple(declared_effects)
    y, cols = _columns(model, sig, declared_effects, equation, keep)
    names = [p for p in cols if np.ptp(cols[p]) > 0]
    X0 = np.column_stack([cols[p] for p in names])
    _, r0 = _train(X0, y, hidden, epochs, seed)
    if candidates is None:
        candidates = library_candidates(model)
    dkeys = {e.key for e in declared_effects}
    ranking = []
    for eff in candidates:
        if eff.key in dkeys:
            continue
        values = [None]
        if eff.search is not None:
            lo, hi = eff.search_bounds(sig, model)
            values = list(np.linspace(lo, hi, 14)[1:])
        best = None
        for v in values:
            e = eff if v is None else eff.with_value(v)
            y1, c1 = _columns(model, sig, declared_effects + (e,), equation, keep)
            # new columns, and for model changes (delay, dead band) what they change
            new = [c for p, c in c1.items() if p not in cols]
            new += [c1[p] - cols[p] for p in cols if p in c1 and not np.array_equal(c1[p], cols[p])]
            if not np.array_equal(y1, y):
                new.append(y - y1)
            new = [c for c in new if np.ptp(c) > 0]
            if not new:
                continue
            res = _test(r0, new, alpha)
            if best is None or res["err"] > best[1]["err"]:
                best = (e, res, new)
        if best is not None:
            ranking.append(best)
    ranking.sort(key=lambda b: -b[1]["err"])
    out = {"equation": equation, "inputs": names, "error_before": _err(r0, y), "winner": None,
           "ranking": [{"effect": e.key, **{k: v for k, v in res.items()}}
                       for e, res, _ in ranking]}
    win = next((b for b in ranking if b[1]["significant"]), None)
    if win is None:
        return out
    e, res, new = win
    X1 = np.column_stack([X0] + new)
    _, r1 = _train(X1, y, hidden, epochs, seed)
    out.update({"winner": e.name, "channel": e.channel, "evidence": res,
                "parameters": {e.search[0]: float(getattr(e, e.search[0]))} if e.search else {},
                "inputs_after": names + [f"{e.key}[{i}]" for i in range(len(new))],
                "error_after": _err(r1, y)})
    return out
