"""The ARX-anchored k-step model on the nano-drone benchmark's cross-trajectory protocol, beside
naive, the chosen ARX and (optionally) the physics + network model (quad_hybrid).

    python docs/examples/nanodrone/anchored_crossfold.py OUT_DIR [--types square,random1,...]
        [--quick] [--cache DIR] [--no-quad-hybrid]

Per fold (``cdam_core.evaluate.crossfold.AnchoredFitter`` through ``cross_trajectory_fold``),
every choice on the validation flights of the training types (the last run of each type; the
test type never seen): the anchor ARX's features (raw rotor speeds or their physics features)
and orders; for each network structure of ``ANCHORED_GRID``, the network on the anchor's
k-step residual trained on the fit flights, its epoch count where the validation flights'
k-step error is least; the blend (kind ``kstep_blend``) of the raw-input ARX, the anchor,
the direct multi-step predictor (kind ``arx_direct``, kept where it lowers the type-out score)
and the network with convex weights per prediction step 1..50 and group chosen type out (each
training type held out in turn from the components' training; the point of a 0.01 grid of the
simplex whose worst held-out type has the least error relative to the raw-input ARX's:
``AnchoredFitter(blend_design="types", blend_rule="worst", direct=True)``, fixed before the
session-9 run; session 10's gate: a step's and group's weights the raw ARX's alone unless the
held-out types prefer the blend there on the mean, ``gate="mean"``); the structure of least validation score (MAE / naive,
mean over h = 1, 10, 25, 50 and the groups), all its parts retrained on all training flights.
Scored beside it on the test type at every horizon 1..50 on the same rows: naive, ``arx`` (the
fold's baseline: raw inputs, orders chosen on the training flights), ``anchor`` (the anchor
ARX alone), ``network`` (the anchor + network model without the blend) and quad_hybrid (its
defaults; left out with ``--no-quad-hybrid``), and two other weightings of the same components
(``VARIANTS``: session 8's weights on the validation flights; the type-out sums under the pooled
rule; the type-out weights without the gate, session 9's model; the gate on every held-out
type). Prints and writes (OUT_DIR/index.md,
results.json) the RMSE per group at h = 1, 5, 10, 20, 50 per fold and the mean over the folds,
and per group the horizons where the anchored model is below each of the others; with the
committed papernets results (docs/examples/papernets/results.json) beside it, the horizons
where it is below every paper network's mean curve. ``--quick``: tiny settings (checks the
output, numbers not meaningful). ``--cache DIR``: trained networks kept there and reused when
parameters and data match (training is deterministic: the same seed gives the same network).
The folds can run as separate processes (``--types square,random1`` into A, ``--types
random2,multisine`` into B; each writes its folds to folds.pkl) and be joined with ``--merge A
B`` (the page of all folds).
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from cdam_core.base.jsonio import write_json_atomic, write_text_atomic  # noqa: E402
from cdam_core.evaluate.crossfold import (ANCHORED_FIXED, ANCHORED_GRID,  # noqa: E402
                                          TYPES, AnchoredFitter, cross_trajectory_fold,
                                          mean_over_folds)
from cdam_core.evaluate.groups import NANODRONE_GROUPS as ANCHORED_GROUPS  # noqa: E402
from cdam_core.models.flight.hybrid import QuadHybrid  # noqa: E402
from cdam_core.record.realdata.nanodrone import nanodrone_files  # noqa: E402

AT = (1, 5, 10, 20, 50)
SHOWN = ("naive", "arx", "anchor", "network", "quad_hybrid", "anchored_flights",
         "anchored_types_pooled", "anchored_ungated", "anchored_gate_every", "anchored")
#: the weightings measured beside the model (reported, never chosen on the test type):
#: session 8's design (weights on the validation flights, rule "worst") and the type-out
#: design under the other rule
VARIANTS = {"anchored_flights": "flights", "anchored_types_pooled": "types_pooled",
            "anchored_ungated": "types_worst", "anchored_gate_every": "types_worst_every"}
PAPERNETS = Path(__file__).resolve().parents[1] / "papernets" / "results.json"


def rmse_table(scores, names=SHOWN, at=AT) -> str:
    """Markdown: RMSE per group (columns) of each predictor at each horizon of ``at``."""
    groups = [g.name for g in scores.groups]
    lines = ["| predictor | h | " + " | ".join(groups) + " |", "|---|---|" + "---|" * len(groups)]
    for name in names:
        if name not in scores.group_rmse:
            continue
        for h in at:
            r = scores.group_rmse[name][scores.horizons.index(h)]
            lines.append(f"| {name} | {h} | " + " | ".join(f"{v:.4g}" for v in r) + " |")
    return "\n".join(lines)


def blend_table(choice, scores, at=(1, 5, 10, 20, 50)) -> list[str]:
    """Markdown: the blend's weights per group (one output of each) at the steps ``at``."""
    if not choice.get("blend_weights"):
        return []
    W = np.asarray(choice["blend_weights"])
    parts = choice["blend_components"]
    where = ("type out (each training type held out in turn)"
             if choice.get("blend_design") == "types" else "on the validation flights")
    lines = ["Blend weights (" + " / ".join(parts) + f") chosen {where}:", "",
             "| h | " + " | ".join(g.name for g in scores.groups) + " |",
             "|---|" + "---|" * len(scores.groups)]
    for h in at:
        row = W[min(h, W.shape[0]) - 1]
        cells = [" / ".join(f"{v:.2f}" for v in row[scores.outputs.index(g.columns[0])])
                 for g in scores.groups]
        lines.append(f"| {h} | " + " | ".join(cells) + " |")
    return lines


def _type_out_text(c) -> str:
    """The direct predictor's orders and the type-out scores of one fold's choice."""
    out = ""
    if c.get("direct"):
        out += f"; direct orders {tuple(c['direct']['orders'])}"
        first = (c["direct"].get("first") or {}).get("chosen")
        if first:
            names = [g.name for g in ANCHORED_GROUPS]
            out += "; its step 1 " + ", ".join(
                f"{names[int(g)] if int(g) < len(names) else g} {v}" for g, v in first.items())
    t = c.get("type_out")
    if t and t.get("scores"):
        out += ("; type-out score with direct {with_direct:.4f}, without {without_direct:.4f}"
                .format(**t["scores"]) + (" (kept)" if t["keep_direct"] else " (left out)"))
    return out


def wins(scores, against, model="anchored", extra=None) -> list[str]:
    """Per group and other predictor: the horizons (of 1..50) where ``model`` is lower."""
    g = scores.group_rmse
    others = {k: np.asarray(g[k]) for k in against if k in g}
    others.update(extra or {})
    lines = []
    for j, group in enumerate(gr.name for gr in scores.groups):
        parts = []
        for name, curve in others.items():
            a, o = np.asarray(g[model])[:, j], curve[:, j]
            # equal: within 1e-9 relative (the same component's predictions, refitted)
            equal = np.abs(a - o) <= 1e-9 * np.abs(o)
            below = (a < o) & ~equal
            equal = int(equal.sum())
            parts.append(f"{name} {int(below.sum())}/{below.size}"
                         + (f" (equal at {equal})" if equal else ""))
        lines.append(f"- {group}: below " + ", ".join(parts))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("out", help="output folder (created)")
    ap.add_argument("--types", default=",".join(TYPES))
    ap.add_argument("--quick", action="store_true", help="tiny settings (output check only)")
    ap.add_argument("--cache", default=None,
                    help="folder of trained networks (reused when parameters and data match)")
    ap.add_argument("--no-quad-hybrid", action="store_true",
                    help="leave the physics + network model (quad_hybrid) out")
    ap.add_argument("--first-step", default="mix", choices=("none", "own", "mix"),
                    help="the direct predictor's step 1: with regressors of its own per group "
                         "chosen type out (own), that mixed row by row with the raw ARX's by "
                         "their recent one-step errors (mix, the default: AnchoredFitter's), or "
                         "the direct's own (none, session 10's model)")
    ap.add_argument("--merge", nargs="+", default=None,
                    help="join the folds.pkl of earlier runs' folders (no training)")
    args = ap.parse_args(argv)
    if args.merge:
        folds, choices, md = [], [], []
        for d in args.merge:
            with open(Path(d) / "folds.pkl", "rb") as fh:   # written by this script
                f, c, m = pickle.load(fh)
            folds += f
            choices += c
            md += m
        return _write(Path(args.out), folds, choices, md, ANCHORED_FIXED)
    try:
        files = nanodrone_files(None)
    except FileNotFoundError as exc:
        print(f"anchored_crossfold.py: error: the nano-drone flights are not here: {exc}; set "
              f"CDAM_SHARED_DATA to the folder holding nanodrone/", file=sys.stderr)
        return 3
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fixed = dict(ANCHORED_FIXED, epochs=2) if args.quick else None
    hybrid_kw = dict(epochs=2) if args.quick else {}
    fitter = AnchoredFitter(fixed=fixed, cache=args.cache, blend_design="types",
                            blend_rule="worst", direct=True, first_step=False if args.first_step == "none" else args.first_step)

    def quad_hybrid(train, fit, valid):
        dt = float(np.median(np.diff(train.t)))
        return QuadHybrid(dt=dt, **hybrid_kw).fit(train.U, train.Y, segments=train.lengths)

    loaded, folds, md = {}, [], []
    for test_type in [t.strip() for t in args.types.split(",") if t.strip()]:
        t0 = time.perf_counter()
        models = {} if args.no_quad_hybrid else {"quad_hybrid": quad_hybrid}
        models["anchored"] = fitter
        models["anchor"] = lambda train, fit, valid: fitter.anchor_   # the anchor ARX alone
        models["network"] = lambda train, fit, valid: fitter.network_ or fitter.anchor_
        for name, key in VARIANTS.items():
            models[name] = lambda train, fit, valid, key=key: \
                fitter.blends_.get(key, fitter.anchor_)
        f = cross_trajectory_fold(files, test_type, loaded=loaded, physics=False,
                                  models=models)
        folds.append(f)
        c = fitter.choices[-1]
        head = (f"## Test type {test_type} (ARX orders {tuple(f.orders)}; anchor: "
                f"{c['anchor_features']} ARX {tuple(c['arx_orders'])}; anchored: chosen "
                f"{c['chosen']}, epochs {c['epochs']}; validation MAE / naive "
                + ", ".join(f"{k} {v:.4f}" for k, v in c["validation"].items())
                + _type_out_text(c)
                + f"; selection {c['select_seconds']:.0f} s, final fit {c['fit_seconds']:.0f} s;"
                f" fold {time.perf_counter() - t0:.0f} s)")
        body = [rmse_table(f.scores), "", *blend_table(c, f.scores), "",
                "Horizons (of 1..50) where anchored is below:", "",
                *wins(f.scores, ("naive", "arx", "anchor", "quad_hybrid", *VARIANTS))]
        print(head + "\n\n" + "\n".join(body) + "\n", flush=True)
        md += [head, "", *body, ""]
    with open(out / "folds.pkl", "wb") as fh:
        pickle.dump((folds, fitter.choices, md), fh)
    return _write(out, folds, fitter.choices, md, fitter.fixed)


def _write(out, folds, choices, md, fixed) -> int:
    """The mean over the folds, the page and results.json."""
    out.mkdir(parents=True, exist_ok=True)
    mean = mean_over_folds(folds)
    first_on = any(((c.get("direct") or {}).get("first") or {}).get("chosen") for c in choices)
    extra = {}
    if PAPERNETS.exists() and len(folds) == len(TYPES):
        js = json.loads(PAPERNETS.read_text())["mean"]
        nets = {k: np.stack([np.asarray(v[g.name]) for g in mean.groups], axis=1)
                for k, v in js["group_rmse"].items()
                if k.endswith(("_static", "_narx", "_chosen"))}   # {group: curve} per net
        if nets:
            extra["paper networks (best of each h)"] = np.min(np.stack(list(nets.values())), 0)
    body = [rmse_table(mean), "", "Horizons (of 1..50) where anchored is below:", "",
            *wins(mean, ("naive", "arx", "anchor", "quad_hybrid", *VARIANTS), extra=extra)]
    print("## Mean over the folds\n\n" + "\n".join(body), flush=True)
    page = ["# ARX-anchored k-step model on the cross-trajectory protocol", "",
            "Produced by `python docs/examples/nanodrone/anchored_crossfold.py OUT_DIR`. RMSE "
            "per group (position m, velocity m/s, attitude rad, rates rad/s) on the test type, "
            "k-step from the measured state with the measured rotor speeds, all predictors on "
            "the same rows. anchored: kind kstep_blend of the raw-input ARX (arx), the anchor "
            "ARX (features and orders chosen on the validation flights) and the network on "
            "its k-step residual (kind arx_kstep, structures " + json.dumps(ANCHORED_GRID)
            + " over " + json.dumps(fixed) + "; the epoch count: the validation "
            "flights' best), the direct multi-step predictor (kind arx_direct) where it lowers the "
            "type-out score" + (" (its step 1 with regressors of its own per group, chosen "
                                "type out among the ARX grid's one-step fits: --first-step, "
                                "AnchoredFitter first_step, session 11, rule fixed before that "
                                "session's test folds; with --first-step mix, the default, mixed "
                                "row by row with the raw ARX's by their one-step errors over the "
                                "100 rows before)" if first_on else "")
            + ", convex weights per step and group chosen type out (each "
            "training type held out in turn from the components' training: the 0.01-grid "
            "point of the simplex whose worst held-out type has the least error relative to "
            "the raw-input ARX's; rule and design fixed before session 9's test folds were "
            "run), each step's and group's weights the raw ARX's alone unless the held-out "
            "types prefer it there on the mean of their RMSE ratios (the gate, session 10: "
            "models.kstep_blend.held_out_gate, need mean; no threshold; added after session "
            "9's test folds had shown rates at h = 1 above the ARX); anchored_gate_every: the "
            "gate on every held-out type instead (measured first in session 10); "
            "anchored_flights: session 8's weights (chosen on the validation flights with "
            "the fit flights' components, rule worst); anchored_types_pooled: the type-out "
            "sums under the pooled least-squares rule; anchored_ungated: the type-out weights "
            "without session 10's gate (each step and group the raw ARX's alone unless "
            "every held-out type prefers the blend there), the session-9 model; network: the "
            "arx_kstep model alone; the paper networks' "
            "curves are the committed "
            "docs/examples/papernets/results.json (same folds and test flights).", "",
            f"## Mean over the {len(folds)} folds", "", *body, "", *md]
    write_text_atomic(out / "index.md", "\n".join(page) + "\n")
    write_json_atomic(out / "results.json", {
        "folds": [{"test_type": f.test_type, "arx_orders": list(f.orders), "anchored": c,
                   "group_rmse": {k: np.asarray(v).tolist() for k, v in
                                  f.scores.group_rmse.items()}}
                  for f, c in zip(folds, choices)],
        "mean": {"groups": [g.name for g in mean.groups], "horizons": mean.horizons,
                 "group_rmse": {k: np.asarray(v).tolist() for k, v in mean.group_rmse.items()},
                 "group_mae": {k: np.asarray(v).tolist() for k, v in mean.group_mae.items()}}})
    print(f"report: {out / 'index.md'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
