"""The cross-trajectory protocol on the nano-drone flights: train on three trajectory types,
test on the fourth, all four ways (issue [flights]).

For one fold: the training flights are those of the other types; the ARX baseline's orders are
chosen on them alone (``baselines.select_arx``: the last run of each training type, by file
name, is the validation record, the rest is fitted; the chosen orders are refitted on all
training flights), and a full-state ARX(1) (na = nb = nk = 1) is fitted on all training flights.
With ``physics`` the physics flight model (``models.flight.physics.QuadPhysics``, least
squares on all training flights, input delays chosen on them) is fitted twice: ``physics``
integrates the rotational dynamics, ``physics_hold`` holds the body rates over the prediction
(the benchmark paper's physics model). Every model and the naive predictor are scored on every
flight of the test type at every horizon 1..50, on the same rows (k-step from the measured
state with the measured inputs; the benchmark's metrics per group, ``evaluate.groups``).

The residual step of the physics model (``physics_effects_fold``): variants with actuation
effects (the yaw reaction of accelerating rotors, a first-order actuation lag) and the two rate
treatments, chosen on the validation flights of the training types, then all scored on the
test type. Measured on the 17 flights (mean MAE / naive MAE over h = 1, 10, 25, 50 and the
four groups, validation): holding the rates wins in every fold; a lag or the reaction torque
lowers the integrated-rates variant's validation error but not below holding the rates. The lag
chosen from the training flights (``QuadPhysics(lag=None)``) gives no multi-step gain on the
test type (benchmarks/nanodrone_lag.py: under 1 % at h = 50 on every group); thrust and
torque coefficients scaling with the battery voltage at the logged rotor speeds are not
supported either (benchmarks/nanodrone_battery.py: lower on validation in 1 of 8 cases,
by 0.06 %; under 0.1 % on the test type).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cdam_core.evaluate.baselines import ARX_GRID, relative_error, select_arx
from cdam_core.evaluate.groups import NANODRONE_GROUPS
from cdam_core.evaluate.horizons import HorizonScores, score_horizons
from cdam_core.models.arx import FEATURES, ArxModel
from cdam_core.models.arx_direct import ArxDirect
from cdam_core.models.flight.physics import QuadPhysics
from cdam_core.models.kstep_blend import RULES as BLEND_RULES
from cdam_core.models.kstep_blend import GATES
from cdam_core.models.kstep_blend import (KStepBlend, held_out_gate, held_out_ratios,
                                         held_out_score, rule_weights)
from cdam_core.record.realdata.nanodrone import load_nanodrone, trajectory_type
from cdam_core.record.stack import Stack, stack_records

BLENDS = ("none", "validation")
#: where the blend's weights are chosen (``AnchoredFitter``): on the validation flights (one
#: per training type; their types seen in training), type out (each training type held out
#: in turn from the components' training), or auto (type out when the training flights hold
#: two or more types, else on the validation flights)
BLEND_DESIGNS = ("flights", "types", "auto")

__all__ = ["Fold", "cross_trajectory_fold", "mean_over_folds", "physics_effects_fold",
           "AnchoredFitter", "ANCHORED_GRID", "ANCHORED_FIXED", "ANCHORED_BLIND",
           "PHYSICS_VARIANTS", "TYPES"]

TYPES = ("square", "random1", "random2", "multisine")
#: rows of the one-step error history behind ``first_step="mix"`` (1 s at the flights' 100 Hz;
#: measured on the training types of the four folds, type out: the held-out ratios move by
#: under 0.15 % between 50 and 400 rows, benchmarks/nanodrone_rates_onestep.py)
FIRST_MIX_WINDOW = 100


@dataclass
class Fold:
    """One fold's result: scores of ``naive``, ``arx1`` and ``arx`` (chosen orders), and with
    ``physics`` of ``physics`` and ``physics_hold``; ``parameters``: each physics model's
    {name: (value, std)}."""

    test_type: str
    train_files: list[str]
    test_files: list[str]
    orders: tuple
    validation: dict
    scores: HorizonScores
    parameters: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"test_type": self.test_type, "train_files": self.train_files,
                "test_files": self.test_files, "arx_orders": list(self.orders),
                "arx_validation": {",".join(map(str, k)): v for k, v in self.validation.items()},
                "physics_parameters": {name: {k: {"value": v, "std": s}
                                              for k, (v, s) in p.items()}
                                       for name, p in self.parameters.items()},
                **self.scores.to_json()}


def _split(files, test_type, loaded):
    """(training files, test files, stacks of the fit, validation, training and test flights):
    the last run of each training type (by file name) validates, the others fit."""
    files = [Path(f) for f in files]
    loaded = {} if loaded is None else loaded
    for f in files:
        if f not in loaded:
            loaded[f] = load_nanodrone(f)
    test = [f for f in files if trajectory_type(f) == test_type]
    train = [f for f in files if trajectory_type(f) != test_type]
    if not test or not train:
        raise ValueError(f"test_type: {test_type!r} leaves no test or no training flight")
    last = {trajectory_type(f): f for f in sorted(train)}
    valid = sorted(last.values())
    fit = [f for f in train if f not in valid]
    return train, test, tuple(stack_records([loaded[f] for f in x])
                              for x in (fit, valid, train, test))


def cross_trajectory_fold(files, test_type: str, horizon: int = 50, grid=ARX_GRID,
                          select_horizons=(1, 10, 25, 50), loaded: dict | None = None,
                          physics: bool = True, models: dict | None = None) -> Fold:
    """Run one fold (module doc) on the flights ``files``; ``loaded``: a {path: Dataset}
    cache shared between folds (filled here); ``physics``: score the physics models too.
    ``models``: more models of any kind, {name: fit(train, fit, valid) -> fitted Model}, each
    called with the stacks of all training flights, of the fit flights and of the validation
    flights (the last run of each training type) and scored beside the others on the same rows
    (e.g. ``evaluate.papernets.paper_network_fitters()``)."""
    for name in models or {}:
        if name in ("naive", "arx1", "arx", "physics", "physics_hold", "model"):
            raise ValueError(f"models: {name!r} is a name the fold already uses")
    train, test, (st_fit, st_valid, st_train, st_test) = _split(files, test_type, loaded)
    groups = list(NANODRONE_GROUPS)
    arx, orders, val = select_arx(st_fit, st_valid, grid, select_horizons, groups)
    arx1 = ArxModel((1, 1, 1)).fit(st_train.U, st_train.Y, segments=st_train.lengths)
    others = {"arx": arx}
    if physics:
        dt = float(np.median(np.diff(st_train.t)))
        for name, rates in (("physics", "dynamic"), ("physics_hold", "hold")):
            others[name] = QuadPhysics(dt=dt, rates=rates).fit(st_train.U, st_train.Y,
                                                               segments=st_train.lengths)
    for name, fit in (models or {}).items():
        others[name] = fit(st_train, st_fit, st_valid)
    hs = list(range(1, horizon + 1))
    kw = dict(segments=st_test.lengths, free_run=False, groups=groups,
              first=max([arx1.t0] + [m.t0 for m in others.values()]))
    sc = score_horizons(arx1, st_test.U, st_test.Y, st_test.outputs, hs, **kw)
    sc.free_run.clear()
    for store in (sc.rmse, sc.mae, sc.group_rmse, sc.group_mae):
        store["arx1"] = store.pop("model")
    for name, model in others.items():
        sc.add(score_horizons(model, st_test.U, st_test.Y, st_test.outputs, hs, **kw),
               "model", name)
    params = {k: m.parameters() for k, m in others.items() if k.startswith("physics")}
    return Fold(test_type, [str(f) for f in train], [str(f) for f in test], orders, val, sc,
                params)


def mean_over_folds(folds) -> HorizonScores:
    """The folds' scores averaged (each fold weighs alike; ``rows`` summed)."""
    first = folds[0].scores
    out = HorizonScores(list(first.outputs), list(first.horizons), groups=list(first.groups))
    out.rows = [int(sum(f.scores.rows[i] for f in folds)) for i in range(len(first.horizons))]
    for key in ("rmse", "mae", "group_rmse", "group_mae"):
        mine = getattr(out, key)
        for name in getattr(first, key):
            mine[name] = np.mean([getattr(f.scores, key)[name] for f in folds], axis=0)
    return out


#: the physics variants the residual step compares: rates integrated or held, the yaw reaction
#: of accelerating rotors, a first-order actuation lag (s)
PHYSICS_VARIANTS = {"dynamic": {}, "dynamic+reaction": {"reaction": True},
                    "dynamic+lag0.05": {"lag": 0.05}, "dynamic+lag0.1": {"lag": 0.1},
                    "dynamic+lag0.2": {"lag": 0.2},
                    "dynamic+reaction+lag0.1": {"reaction": True, "lag": 0.1},
                    "hold": {"rates": "hold"}, "hold+lag0.05": {"rates": "hold", "lag": 0.05}}


def physics_effects_fold(files, test_type: str, variants=None, horizons=(1, 10, 25, 50),
                         loaded: dict | None = None) -> dict:
    """The residual step of the physics flight model on one fold: each variant (name ->
    ``QuadPhysics`` arguments; default ``PHYSICS_VARIANTS``) is fitted on the fit flights and
    scored on the validation flights (the last run of each training type) by the mean over
    ``horizons`` and groups of its MAE over the naive MAE, all variants on the same rows (from
    the largest t0); the variant with the least validation score is the one chosen. Every
    variant is then refitted on all training flights and scored the same way on the test type
    (reported, never used to choose). Returns {"chosen", "variants": {name: {"validation",
    "test", "test_group_rmse": {h: [per group]}}}}."""
    variants = dict(PHYSICS_VARIANTS if variants is None else variants)
    if not variants:
        raise ValueError("variants: none given")
    _, _, (st_fit, st_valid, st_train, st_test) = _split(files, test_type, loaded)
    dt = float(np.median(np.diff(st_train.t)))
    groups, hs = list(NANODRONE_GROUPS), [int(h) for h in horizons]
    fitted = {name: QuadPhysics(dt=dt, **kw).fit(st_fit.U, st_fit.Y, segments=st_fit.lengths)
              for name, kw in variants.items()}
    first = max(m.t0 for m in fitted.values())

    def relative(model, st):
        sc = score_horizons(model, st.U, st.Y, st.outputs, hs, segments=st.lengths,
                            free_run=False, groups=groups, first=first)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = sc.group_mae["model"] / sc.group_mae["naive"]
        return float(np.mean(np.where(np.isfinite(ratio), ratio, 1.0))), sc

    out = {}
    for name, kw in variants.items():
        valid, _ = relative(fitted[name], st_valid)
        model = QuadPhysics(dt=dt, **kw).fit(st_train.U, st_train.Y, segments=st_train.lengths)
        test, sc = relative(model, st_test)
        out[name] = {"validation": valid, "test": test,
                     "test_group_rmse": {h: sc.group_rmse["model"][i].tolist()
                                         for i, h in enumerate(hs)}}
    chosen = min(out, key=lambda k: (out[k]["validation"], k))
    return {"test_type": test_type, "chosen": chosen, "groups": [g.name for g in groups],
            "first_row": first, "variants": out}


#: the structures of the physics + network model (``models.flight.hybrid.QuadHybrid``) the
#: hybrid fold chooses among on validation flights: the network's prior on the rates (the
#: physics' increment or none) and the weights of the steps' errors (alike, or over the naive
#: error at each step); windows of 50 steps, 8 tanh units, 6 rotor-speed lags (a first grid
#: with windows of 10 steps as well chose 50 on the validation flights of both folds it ran)
HYBRID_GRID = {"hold_flat": {"prior": "hold", "weighting": "flat"},
               "hold_naive": {"prior": "hold", "weighting": "naive"},
               "dynamic_flat": {"prior": "dynamic", "weighting": "flat"},
               "dynamic_naive": {"prior": "dynamic", "weighting": "naive"}}
HYBRID_FIXED = {"hidden": 8, "lags": 6, "epochs": 15, "horizon": 50}


def hybrid_fold(files, test_type: str, grid=None, fixed=None, horizon: int = 50,
                select_horizons=(1, 10, 25, 50), loaded: dict | None = None,
                arx_grid=ARX_GRID) -> dict:
    """The physics + network model on one fold: each structure of ``grid`` (name -> QuadHybrid
    arguments over ``fixed``; default ``HYBRID_GRID``, ``HYBRID_FIXED``) is trained on the fit
    flights and scored on the validation flights (the last run of each training type) by the
    mean over ``select_horizons`` and groups of its MAE over the naive MAE; the least is chosen,
    retrained on all training flights and scored on the test type at every horizon
    1..``horizon`` beside the fold's baselines (``cross_trajectory_fold``: naive, ARX(1), the
    chosen ARX (orders from ``arx_grid``), the physics model with rates integrated and held),
    all on the same rows.
    Returns {"fold": Fold (the hybrid's scores under "hybrid"), "chosen", "validation",
    "fit_seconds"}."""
    import time

    from cdam_core.models.flight.hybrid import QuadHybrid

    grid = dict(HYBRID_GRID if grid is None else grid)
    fixed = dict(HYBRID_FIXED if fixed is None else fixed)
    if not grid:
        raise ValueError("grid: no structure given")
    loaded = {} if loaded is None else loaded
    _, _, (st_fit, st_valid, st_train, st_test) = _split(files, test_type, loaded)
    dt = float(np.median(np.diff(st_train.t)))
    groups, hs = list(NANODRONE_GROUPS), [int(h) for h in select_horizons]
    fitted = {name: QuadHybrid(dt=dt, **{**fixed, **kw}).fit(st_fit.U, st_fit.Y,
                                                               segments=st_fit.lengths)
              for name, kw in grid.items()}
    first = max(m.t0 for m in fitted.values())
    val = {}
    for name, m in fitted.items():
        sc = score_horizons(m, st_valid.U, st_valid.Y, st_valid.outputs, hs,
                            segments=st_valid.lengths, free_run=False, groups=groups,
                            first=first)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = sc.group_mae["model"] / sc.group_mae["naive"]
        val[name] = float(np.mean(np.where(np.isfinite(ratio), ratio, 1.0)))
    chosen = min(val, key=lambda k: (val[k], k))
    t = time.perf_counter()
    model = QuadHybrid(dt=dt, **{**fixed, **grid[chosen]}).fit(st_train.U, st_train.Y,
                                                                 segments=st_train.lengths)
    fit_seconds = time.perf_counter() - t
    fold = cross_trajectory_fold(files, test_type, horizon=horizon, grid=arx_grid,
                                 loaded=loaded,
                                 models={"hybrid": lambda train, fit, valid: model})
    return {"fold": fold, "chosen": chosen, "structure": {**fixed, **grid[chosen]},
            "validation": val, "fit_seconds": fit_seconds,
            "history": model.history_}


#: the structures of the ARX-anchored k-step model (``models.arx_kstep.ArxKStep``) the anchored
#: fitter chooses among on the validation flights (beside the ARX alone); the network does not
#: see the position (``blind``: the dynamics do not depend on where the vehicle is); LM runs at
#: most ``epochs`` epochs on the fit flights, the epoch of least validation k-step error is kept
#: and the final fit on all training flights runs that many
ANCHORED_GRID = {"h8_l2_K50": {"hidden": 8, "lags": 2, "horizon": 50},
                 "h8_l4_K50": {"hidden": 8, "lags": 4, "horizon": 50}}
ANCHORED_FIXED = {"epochs": 20, "net_features": "physics", "weighting": "base", "stride": 100}
ANCHORED_BLIND = ("x", "y", "z")


def _direct(direct, feat, H) -> ArxDirect:
    """The direct predictor of ``direct`` (``AnchoredFitter``'s choice: orders, and step 1's
    own regressors when chosen)."""
    parts = (direct.get("first") or {}).get("parts") or None
    mix = (direct.get("first") or {}).get("mix")
    return ArxDirect(direct["orders"], feat, H,
                     first=None if parts is None else [tuple(p) for p in parts],
                     first_mix=None if mix is None else tuple(mix))


def _records_stack(st: Stack, keep) -> Stack:
    """The rows of ``st`` whose record index is in ``keep`` (its segments whole)."""
    keep = set(int(k) for k in keep)
    sel = [(a, b) for a, b in st.pieces() if int(st.record[a]) in keep]
    if not sel:
        raise ValueError("records: none selected")
    idx = np.concatenate([np.arange(a, b) for a, b in sel])
    return Stack(names=st.names, inputs=st.inputs, outputs=st.outputs, U=st.U[idx],
                 Y=st.Y[idx], t=st.t[idx], lengths=[b - a for a, b in sel],
                 record=st.record[idx], row=st.row[idx], datasets=st.datasets)


def _train_types(train: Stack, need: bool = True):
    """(type of each record name, the sorted types the stack's rows hold); ValueError when
    they are fewer than two (the type-out design's need) and ``need``."""
    rtype = np.array([trajectory_type(n) for n in train.names])
    present = sorted(set(rtype[np.unique(train.record)]))
    if need and len(present) < 2:
        raise ValueError(f"blend_design 'types': the training flights hold {len(present)} "
                         f"type(s); at least two are needed")
    return rtype, present


class AnchoredFitter:
    """``fit(train, fit, valid)`` for ``cross_trajectory_fold(models=...)``: the ARX-anchored
    k-step model, every choice on the training flights, never on the test type.

    The anchor: an ARX whose features (each of ``anchor_features``: raw inputs, physics
    features of four rotor speeds; a kind the inputs do not allow is skipped) and orders (of
    ``arx_grid``) are chosen together on the validation flights (fitted on the fit flights,
    scored as ``select_arx`` scores: the mean over ``select_horizons`` and groups of the MAE
    over the naive MAE). With ``anchor_features=("raw",)`` the anchor is the fold's ARX
    baseline. Each structure of ``grid`` (over ``fixed``) is trained on the fit flights on
    that anchor (error scales per group of ``groups``: the benchmark's position, velocity,
    attitude, rates; the outputs ``blind`` hidden from the network), LM tracking the validation
    flights' k-step error (the best epoch kept). With ``blend="validation"`` (default) each
    candidate is a ``KStepBlend`` of the raw-input ARX (the reference: orders chosen as the
    fold's baseline chooses them), the anchor (when it is not that ARX) and the network model,
    weighted per prediction step (1..max(``select_horizons``, K)) and group by ``blend_rule``
    on the validation flights (one unit per flight); ``blend="none"``: the network model
    alone. Each candidate is scored on the validation flights as the anchor is; the least
    wins. The anchor winning, the model is the anchor fitted on all training flights; else the
    chosen structure retrained on all training flights for its best validation epoch count
    (the ARXs refitted there too), blended.

    Blend rules (``models.kstep_blend.rule_weights``): ``"worst"`` (default): per step and
    group the point of a 0.01 grid of the simplex whose worst unit has the least error
    relative to the raw-input ARX's; ``"pooled"``: least squares pooled over the units.

    Where the final blend's weights come from (``blend_design``, fixed before any test fold
    of session 9 was run):

    - ``"flights"`` (session 8): the weights chosen on the validation flights with the fit
      flights' components (the validation flights' types are among the components' training
      types, so validation never sees an unseen type);
    - ``"types"``: type out inside the training types: for each training type (the file name's
      prefix, ``trajectory_type``), the components (the ARXs with the chosen orders, the
      direct predictor, the chosen network structure trained for its chosen epoch count) are
      fitted on all training flights of the other types, and that type's flights give one
      unit's sums; the weights by ``blend_rule`` over those units (each unit a type none of
      the components trained on: the situation of the test type). With ``direct``, a
      direct multi-step predictor (``models.arx_direct.ArxDirect``: one least-squares fit per
      step 1..max(``select_horizons``, K), the anchor's features, orders of ``arx_grid``
      with the anchor's delay chosen on the validation flights like the anchor's) joins the
      components when its leave-one-type-out score (``models.kstep_blend.held_out_score``:
      weights by the rule on the other held-out types, the RMSE relative to the raw ARX on
      this one, mean over types, steps and groups) is lower with it than without; else it is
      left out. Measured on the 17 flights (docs/examples/nanodrone/anchored/): 0.907-0.936
      with it against 0.966-0.993 without, kept in all four folds. With ``first_step="own"``
      (measured, it did not hold on the test types; below),
      the direct predictor's step 1 has regressors of its own per group (``ArxDirect(first=
      ...)``, ``_first_step``): for each group the one-step ARX of ``arx_grid`` x
      ``anchor_features`` whose one-step RMSE relative to the raw ARX's is least on the mean
      over the held-out training types (each fitted on the other types), the direct's own
      step 1 on ties (no entry then); steps 2.. are unchanged. Why: the raw ARX's orders are
      chosen for the multi-step error (delay 2 on the flights) and are not the best one-step
      predictor; the body rates one step ahead are better predicted from the newest rotor
      speed (delay 1) on three of the four trajectory types. Measured (session 11, rule fixed
      before the four test folds were run; docs/examples/nanodrone/anchored_first_step/): the
      rates' step 1 chose delay 1 in every fold, but random1's flights do not share the
      gain (held out inside the training types: +8 to +12 % against the raw ARX; in the fold
      where random1 is the test type all three held-out types preferred it, the gate opened
      and the test type lost 5.5 %); mean over the four folds at rates h = 1 +0.82 % against
      the ARX (without it +0.011 %), while position, velocity and attitude at h = 1 gained
      (-2.0, -1.1, -1.0 % against the ARX; without it -1.6, -1.1, -0.9 %); steps 2.. equal.
      ``first_step="mix"`` (the default since session 11): that step 1 mixed row by row with
      the raw ARX's (``ArxDirect(first_mix=...)``, ``FIRST_MIX_WINDOW`` rows of past one-step
      errors): the rotor speeds' alignment against the rates moves by 10-20 ms between
      flights, and the mix follows each flight's own. Type out inside the training types it
      was lower than the raw ARX on every held-out type of every fold (rates -0.8 to -10.5 %);
      rule fixed before its test folds (docs/examples/nanodrone/anchored/): rates at h = 1
      -4.7 % against the ARX on the mean of the four folds (per fold -4.8 / -0.6 / -5.5 /
      -6.9 %), below the ARX at 50 / 50 / 50 / 50 horizons on the mean. ``False``: session
      10's model. The gate (session 10,
      ``models.kstep_blend.held_out_gate``): the weights of a step and group are the raw
      ARX's alone unless the held-out types prefer the blend there (the weights the rule
      chooses on the other held-out types have a lower error than the raw ARX's; ``gate``:
      ``"mean"`` (default): on the mean of the types' RMSE ratios, the criterion of the
      direct predictor's decision applied per step and group; ``"every"``: on every type;
      ``"none"``: no gate, session 9's model); the ungated and both gated weightings are
      measured beside (``blends_["types_<rule>"]``, ``blends_["types_<rule>_<gate>"]``);
    - ``"auto"`` (the CLI's default since session 10): ``"types"`` when the training flights
      hold two or more trajectory types, else ``"flights"`` (the type-out design needs two;
      on the four-way protocol, each fold three training types, the type-out design was below
      the ARX at more horizons than the flights design on the mean and in the worst fold:
      docs/examples/nanodrone/anchored/).

    ``cache``: a folder where trained networks are kept and reused (``_trained``).
    ``choices``: one record per call (anchor, orders, validation scores, chosen, epochs, blend
    components and weights, the type-out scores and both rules' weights, seconds)."""

    def __init__(self, grid=None, fixed=None, select_horizons=(1, 10, 25, 50),
                 arx_grid=ARX_GRID, groups=NANODRONE_GROUPS, blind=ANCHORED_BLIND,
                 anchor_features=("raw", "physics"), blend="validation", cache=None,
                 blend_rule="worst", blend_design="flights", direct=False, gate="mean",
                 first_step="mix"):
        self.grid = dict(ANCHORED_GRID if grid is None else grid)
        self.fixed = dict(ANCHORED_FIXED if fixed is None else fixed)
        if not self.grid:
            raise ValueError("grid: no structure given")
        self.select_horizons = tuple(int(h) for h in select_horizons)
        self.arx_grid = arx_grid
        self.groups = list(groups)
        self.blind = tuple(blind)
        self.anchor_features = tuple(anchor_features)
        if not self.anchor_features or any(f not in FEATURES for f in self.anchor_features):
            raise ValueError(f"anchor_features: expected some of {', '.join(FEATURES)}")
        if blend not in BLENDS:
            raise ValueError(f"blend: unknown {blend!r}; use 'none' or 'validation'")
        self.blend = blend
        self.cache = None if cache is None else Path(cache)
        if blend_rule not in BLEND_RULES:
            raise ValueError(f"blend_rule: unknown {blend_rule!r}; use 'worst' or 'pooled'")
        self.blend_rule = blend_rule
        if blend_design not in BLEND_DESIGNS:
            raise ValueError(f"blend_design: unknown {blend_design!r}; use "
                             f"{' or '.join(BLEND_DESIGNS)}")
        if direct and blend_design == "flights":
            raise ValueError("direct: the direct predictor is decided type out; use "
                             "blend_design='types' or 'auto'")
        self.blend_design = blend_design
        self.direct = bool(direct)
        if gate not in ("none", *GATES):
            raise ValueError(f"gate: unknown {gate!r}; use none, {', '.join(GATES)}")
        self.gate = gate
        if first_step not in (False, None, True, "own", "mix"):
            raise ValueError(f"first_step: unknown {first_step!r}; use False, 'own' (True) or "
                             f"'mix'")
        self.first_step = "own" if first_step is True else (first_step or False)
        self.choices = []

    def _trained(self, params, stack, valid=None):
        """ArxKStep(**params) fitted on ``stack`` (LM tracking ``valid``), or the same model
        from the ``cache`` folder: a pickle named by a digest of the parameters and the data (a
        fit is deterministic: same seed, same result, so the cache only saves time)."""
        import hashlib
        import pickle

        from cdam_core.models.arx_kstep import ArxKStep

        path = None
        if self.cache is not None:
            h = hashlib.sha256(repr(sorted((k, repr(v)) for k, v in params.items()
                                           if k != "threads")).encode())
            for st in (stack, valid):
                if st is not None:
                    for a in (st.U, st.Y, np.asarray(st.lengths)):
                        h.update(np.ascontiguousarray(a).tobytes())
            path = self.cache / f"arx_kstep_{h.hexdigest()[:24]}.pkl"
            if path.exists():
                with open(path, "rb") as fh:       # written below by this process
                    return pickle.load(fh)
        m = ArxKStep(**params)
        m.fit(stack.U, stack.Y, segments=stack.lengths,
              validation=None if valid is None else (valid.U, valid.Y, valid.lengths))
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(path.with_suffix(".tmp"), "wb") as fh:
                pickle.dump(m, fh)
            path.with_suffix(".tmp").replace(path)
        return m

    def _labels(self, outputs):
        lab = np.full(len(outputs), -1)
        for g, group in enumerate(self.groups):
            for c in group.columns:
                lab[list(outputs).index(c)] = g
        rest = lab < 0
        lab[rest] = len(self.groups) + np.arange(int(rest.sum()))   # ungrouped: alone
        return [int(v) for v in lab]

    def __call__(self, train, fit, valid):
        import time

        design = self.blend_design
        if design == "types":
            _train_types(train)            # fails before any fit
        elif design == "auto":
            design = "types" if len(_train_types(train, need=False)[1]) >= 2 else "flights"
        t = time.perf_counter()
        self.blends_ = {}
        anchors = {}                       # (features, orders) -> validation score
        for feat in self.anchor_features:
            for orders in self.arx_grid:
                orders = tuple(int(v) for v in orders)
                try:
                    m = ArxModel(orders, feat).fit(fit.U, fit.Y, segments=fit.lengths)
                    anchors[feat, orders] = relative_error(m, valid, self.select_horizons,
                                                           self.groups)
                except ValueError:         # a diverging candidate or features the inputs
                    continue               # do not allow: no candidate
        if not anchors:
            raise ValueError("arx_grid: every anchor candidate failed on the validation "
                             "flights")
        feat, orders = min(anchors, key=lambda a: (anchors[a], self.anchor_features.index(
            a[0]), a[1]))
        # the reference of the blend: the ARX on raw inputs with its orders chosen the same way
        # (the fold's baseline), or the anchor when raw inputs are not a candidate
        raw = [a for a in anchors if a[0] == "raw"]
        ref = min(raw, key=lambda a: (anchors[a], a[1])) if raw else (feat, orders)
        arxs = [ref] + ([(feat, orders)] if (feat, orders) != ref else [])

        def fitted_arxs(st):
            return [ArxModel(o, f).fit(st.U, st.Y, segments=st.lengths) for f, o in arxs]

        common = {"narx": orders, "features": feat, "groups": self._labels(train.outputs),
                  "blind": [list(train.outputs).index(c) for c in self.blind]}
        labels = common["groups"]
        steps = max(self.select_horizons)
        val = {"arx": anchors[feat, orders]}
        epochs, hist, weights = {}, {}, {}
        base = fitted_arxs(fit) if self.blend == "validation" else []
        for name, kw in self.grid.items():
            try:
                m = self._trained({**common, **self.fixed, **kw}, fit, valid)
                if self.blend == "validation":
                    units = None if self.blend_rule == "pooled" else valid.record
                    m = KStepBlend(base + [m], groups=labels).choose(
                        valid.U, valid.Y, valid.lengths, horizon=max(steps, m.horizon),
                        units=units)
                    weights[name] = m.weights_
                    net = m.components_[-1]
                else:
                    net = m
                val[name] = relative_error(m, valid, self.select_horizons, self.groups)
                epochs[name], hist[name] = net.history_["best_epoch"], net.history_
            except ValueError:             # a diverging candidate is no candidate
                val[name] = float("inf")
        chosen = min(val, key=lambda k: (val[k], k != "arx", k))
        if chosen != "arx" and not epochs[chosen]:
            chosen = "arx"                 # no epoch lowered the validation error
        H = max(steps, int({**self.fixed, **self.grid[chosen]}.get("horizon", steps))) \
            if chosen != "arx" else steps
        direct, types, flights_w = None, None, None
        if chosen != "arx" and self.blend == "validation" and design == "types":
            if self.direct:
                direct = self._direct_orders(feat, orders[2], fit, valid, H)
                if self.first_step:
                    direct["first"] = self._first_step(train, ref, direct, feat, labels)
                    if self.first_step == "mix" and direct["first"]["parts"]:
                        direct["first"]["mix"] = [list(ref[1]), ref[0], FIRST_MIX_WINDOW]
            types = self._type_out(train, arxs, direct, feat, H, common, chosen,
                                   epochs[chosen], labels)
            flights_w = weights[chosen]
            weights[chosen] = types["weights"]
        select_seconds = time.perf_counter() - t
        t = time.perf_counter()
        w = weights.get(chosen)
        final = fitted_arxs(train)
        #: the anchor fitted on all training flights (the model when the ARX wins)
        self.anchor_ = final[-1]
        self.network_ = None               #: the network model alone (None: the ARX won)
        keep_direct = bool(types and types["keep_direct"])
        if chosen == "arx":
            model = self.anchor_
        else:
            model = self.network_ = self._trained({**common, **self.fixed, **self.grid[chosen],
                                                   "epochs": epochs[chosen]}, train)
            hist["final"] = model.history_
            if keep_direct:
                final.append(_direct(direct, feat, H).fit(train.U, train.Y,
                                                          segments=train.lengths))
            net = model
            if w is not None:
                model = KStepBlend(final + [net], weights=w, groups=labels)
            #: every weighting measured (reported): the session-8 design's weights on the
            #: ARXs and the network, and both rules' type-out weights
            self.blends_ = {}
            if flights_w is not None:
                self.blends_["flights"] = KStepBlend(final[:len(arxs)] + [net],
                                                     weights=flights_w, groups=labels)
            for r, wr in (types or {}).get("rule_weights", {}).items():
                self.blends_[f"types_{r}"] = KStepBlend(final + [net], weights=np.asarray(wr),
                                                        groups=labels)
            for need, g in (types or {}).get("gates", {}).items():
                self.blends_[f"types_{self.blend_rule}_{need}"] = KStepBlend(
                    final + [net], weights=np.asarray(g["weights"]), groups=labels)
        names = [f"{f} arx {','.join(map(str, o))}" for f, o in arxs]
        if keep_direct:
            names.append(f"{feat} direct {','.join(map(str, direct['orders']))}")
        self.choices.append({"arx_orders": list(orders), "anchor_features": feat,
                             "anchor_validation": {f"{f} {','.join(map(str, o))}": v
                                                   for (f, o), v in anchors.items()},
                             "blend_design": design, "blend_design_asked": self.blend_design,
                             "blend_rule": self.blend_rule,
                             "blend_components": names + ["network"],
                             "validation": val, "chosen": chosen,
                             "epochs": epochs.get(chosen), "structure": {} if chosen == "arx"
                             else {**self.fixed, **self.grid[chosen],
                                   "epochs": epochs[chosen]},
                             "blend_weights": None if w is None or chosen == "arx" else
                             np.asarray(w).tolist(),
                             "direct": direct,
                             "type_out": None if types is None else
                             {**{k: v for k, v in types.items()
                                 if k not in ("weights", "rule_weights", "gates")},
                              "gates_closed": {n: g["closed"] for n, g in
                                               types.get("gates", {}).items()},
                              "other_rule_weights": {r: v for r, v in
                                                     types["rule_weights"].items()
                                                     if r != self.blend_rule}},
                             "select_seconds": select_seconds,
                             "fit_seconds": time.perf_counter() - t,
                             "validation_history": {k: v for k, v in hist.items()
                                                    if k != "final"},
                             "history": hist.get("final")})
        return model

    def _direct_orders(self, feat, nk, fit, valid, H) -> dict:
        """The direct predictor's orders: those of ``arx_grid`` with the anchor's delay
        ``nk`` and features ``feat`` (the delay already chosen on the validation flights; the
        other delay would double the fits), fitted on the fit flights, the least validation
        score as the anchor's."""
        scores = {}
        for o in self.arx_grid:
            o = tuple(int(v) for v in o)
            if o[2] != int(nk):
                continue
            try:
                m = ArxDirect(o, feat, H).fit(fit.U, fit.Y, segments=fit.lengths)
                scores[o] = relative_error(m, valid, self.select_horizons, self.groups)
            except ValueError:
                continue
        if not scores:
            raise ValueError("arx_grid: every direct candidate failed on the validation flights")
        best = min(scores, key=lambda o: (scores[o], o))
        return {"orders": list(best), "validation": {",".join(map(str, o)): v
                                                     for o, v in scores.items()}}

    def _first_step(self, train, ref, direct, feat, labels) -> dict:
        """Step 1's own regressors for the direct predictor (``ArxDirect(first=...)``), chosen
        type out per group: for each training type held out in turn, every candidate of
        ``arx_grid`` x ``anchor_features`` and the reference ARX fitted on the other types'
        flights and scored one step ahead on that type's (the same rows: from the largest t0
        of the candidates); a group's candidate is the least mean over the held-out types of
        its RMSE relative to the reference's, the direct predictor's own step 1 (its orders and
        features, a candidate) on ties; a group whose choice is the direct's own gets no entry.
        Returns {"parts": [[outputs, orders, features]], "scores": {group: {candidate: mean
        ratio}}, "chosen": {group: candidate}}."""
        rtype, present = _train_types(train)
        cands = [(f, tuple(int(v) for v in o)) for f in self.anchor_features
                 for o in self.arx_grid]
        own = (feat, tuple(int(v) for v in direct["orders"]))
        if own not in cands:
            cands.append(own)
        lab = np.asarray(labels)
        groups = list(np.unique(lab))
        ratios = {c: [] for c in cands}
        for held in present:
            sub = _records_stack(train, np.flatnonzero(rtype != held))
            out = _records_stack(train, np.flatnonzero(rtype == held))
            fitted = {}
            for c in [ref] + cands:
                try:
                    fitted[c] = ArxModel(c[1], c[0]).fit(sub.U, sub.Y, segments=sub.lengths)
                except ValueError:       # features the inputs do not allow: no candidate
                    continue
            first = max(m.t0 for m in fitted.values())
            sse = {}
            for c, m in fitted.items():
                E = []
                for a, b in out.pieces():
                    if b - a > first:
                        P = m.predict(out.U[a:b], out.Y[a:b], mode="one_step")
                        E.append(out.Y[a + first:b] - P[first:])
                E = np.vstack(E)
                sse[c] = np.array([np.sum(E[:, lab == g] ** 2) for g in groups])
            for c in cands:
                ratios[c].append(np.sqrt(sse[c] / sse[ref]) if c in sse else
                                 np.full(len(groups), np.inf))
        mean = {c: np.mean(r, axis=0) for c, r in ratios.items()}
        parts, chosen, scores = [], {}, {}
        for j, g in enumerate(groups):
            best = min(cands, key=lambda c: (mean[c][j], c != own))
            chosen[int(g)] = f"{best[0]} {','.join(map(str, best[1]))}"
            scores[int(g)] = {f"{c[0]} {','.join(map(str, c[1]))}": float(mean[c][j])
                              for c in cands}
            if best != own:
                parts.append([[int(i) for i in np.flatnonzero(lab == g)], list(best[1]),
                              best[0]])
        return {"parts": parts, "chosen": chosen, "scores": scores}

    def _type_out(self, train, arxs, direct, feat, H, common, chosen, n_epochs, labels):
        """The type-out design (class doc): per training type, the components fitted on the
        other types' training flights and that type's sums; the weights by the rule, with the
        direct predictor where its held-out score is lower. Returns {"weights", "types",
        "keep_direct", "scores", "rule_weights": {rule: weights}}."""
        rtype, present = _train_types(train)
        Gs, bs, cs = [], [], []
        for held in present:
            sub = _records_stack(train, np.flatnonzero(rtype != held))
            out = _records_stack(train, np.flatnonzero(rtype == held))
            comps = [ArxModel(o, f).fit(sub.U, sub.Y, segments=sub.lengths) for f, o in arxs]
            if direct is not None:
                comps.append(_direct(direct, feat, H).fit(sub.U, sub.Y, segments=sub.lengths))
            comps.append(self._trained({**common, **self.fixed, **self.grid[chosen],
                                        "epochs": n_epochs}, sub))
            G, b, c = KStepBlend(comps, groups=labels).sums(out.U, out.Y, out.lengths, H)
            Gs.append(G[0])
            bs.append(b[0])
            cs.append(c[0])
        G, b, c = np.stack(Gs), np.stack(bs), np.stack(cs)
        scores, keep = {}, False
        if direct is not None:
            jd = len(arxs) - 1                     # the direct predictor's column in G, b
            idx = [j for j in range(b.shape[-1]) if j != jd]
            scores = {"with_direct": held_out_score(G, b, c, labels, self.blend_rule),
                      "without_direct": held_out_score(G[..., idx, :][..., idx], b[..., idx],
                                                       c, labels, self.blend_rule)}
            keep = scores["with_direct"] < scores["without_direct"]
            if not keep:
                G, b = G[..., idx, :][..., idx], b[..., idx]
        W = {r: rule_weights(G, b, c, labels, r) for r in BLEND_RULES}
        weights, gates = W[self.blend_rule], {}
        ratios = held_out_ratios(G, b, c, labels, self.blend_rule)
        for need in GATES:                 # every gate (the chosen one and those beside it)
            gw, kept = held_out_gate(weights, G, b, c, labels, self.blend_rule, need=need,
                                     ratios=ratios)
            gates[need] = {"weights": gw.tolist(), "kept": kept.astype(int).tolist(),
                           "closed": [[int(k) + 1 for k in np.flatnonzero(~kept[:, j])]
                                      for j in range(kept.shape[1])]}
        if self.gate != "none":
            weights = np.asarray(gates[self.gate]["weights"])
        return {"weights": weights, "types": present, "keep_direct": bool(keep),
                "scores": scores, "rule_weights": {r: v.tolist() for r, v in W.items()},
                "gate": None if self.gate == "none" else
                {"need": self.gate, "groups": [int(g) for g in np.unique(labels)],
                 **{k: v for k, v in gates[self.gate].items() if k != "weights"}},
                "gates": gates}
