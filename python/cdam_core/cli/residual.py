"""`cdam residual`: fit a declared model, name the missing effects, report before and after."""
from __future__ import annotations

import json
import sys
import math
from pathlib import Path

from cdam_core.base.jsonio import write_text_atomic
from cdam_core.cli.common import CliError, add_outputs, check_io, elapsed_ticker
from cdam_core.record.columns import parse_column_map


def _split(s):
    return [x.strip() for x in s.split(",") if x.strip()] if s else []


def parse_fixed(text: str | None) -> dict:
    """``"m=1.8,Jz=0.02"`` -> ``{"m": 1.8, "Jz": 0.02}`` (known parameters)."""
    out = {}
    for item in _split(text):
        if "=" not in item:
            raise ValueError(f"--fixed: expected name=value, got {item!r}")
        k, v = (x.strip() for x in item.split("=", 1))
        if not k or not v:
            raise ValueError(f"--fixed: empty name or value in {item!r}")
        try:
            out[k] = float(v)
        except ValueError:
            raise ValueError(f"--fixed: {k}: not a number: {v!r}") from None
    return out


def signal_map(spec) -> dict:
    """``--map`` (the record.columns syntax: text or a JSON file) -> ``{signal: column}``.
    A scale factor is refused: the saved model reads its columns as they are."""
    out = {}
    for k, (col, f) in parse_column_map(spec, "--map").items():
        if f != 1.0:
            raise ValueError(f"--map: {k}={col}*{f:g}: cdam residual reads the columns as they "
                             f"are (a factor would not reach the saved model); scale the record")
        out[k] = col
    return out


def run(args) -> int:
    from cdam_core.record.dataset import read_dataset
    from cdam_core.report.residual import to_json, write_report
    from cdam_core.residual import analyse
    from cdam_core.models.greybox.registry import get_model

    check_io(inputs=[("DATA", args.data), ("--test", args.test)],
             files=[("--json", args.json), ("--save", args.save), ("--simulated", args.simulated)],
             folders=[("--report", args.report)])
    if args.simulated and not args.test:
        raise CliError("--simulated: needs --test (the record simulated)")
    if args.firmware and not args.save:
        raise CliError("--firmware: needs --save (the model refitted for the board)")
    if args.simulated and not str(args.simulated).lower().endswith(".csv"):
        raise CliError(f"--simulated: expected a .csv file name, got {args.simulated!r}")
    if args.n_init < 1:
        raise CliError(f"--n-init: must be >= 1, got {args.n_init}")
    if args.cutoff is not None and not (math.isfinite(args.cutoff) and args.cutoff > 0):
        raise CliError(f"--cutoff: expected a positive frequency in Hz, got {args.cutoff}")
    if not 0 < args.alpha < 1:
        raise CliError(f"--alpha: expected a significance level in (0, 1), got {args.alpha}")
    model = get_model(args.model)  # fails early, clearly, for an unknown model
    mapping = dict(model.defaults)
    given = signal_map(args.map)
    for k in given:
        if k not in model.signals:
            raise ValueError(f"--map: {args.model} has no signal {k!r} "
                             f"(signals: {', '.join(model.signals)})")
    mapping.update(given)
    inputs = _split(args.inputs)
    outputs = _split(args.outputs)
    ds = read_dataset(args.data, inputs=inputs or None, outputs=outputs or None)
    for name, col in mapping.items():
        if col not in ds.columns:
            raise ValueError(f"--map: column {col!r} (for {name}) not in {args.data}; "
                             f"columns: {', '.join(ds.columns)}")
    units = ds.units
    model.check_units({name: (col, units.get(col)) for name, col in mapping.items()},
                      str(args.data))
    signals = {name: ds.column(col) for name, col in mapping.items()}
    signal_units = {name: u for name, col in mapping.items() if (u := units.get(col))}
    used = set(mapping.values())
    extra = {c: ds.column(c) for c in inputs if c not in used}
    fixed = parse_fixed(args.fixed)
    # effects the sidecar's model declares are part of the declared model
    from cdam_core.models.greybox.effects import LIBRARY
    meta = getattr(ds, "meta", None) or {}
    declared = [e for e in ((meta.get("model") or {}).get("effects") or []) if e in LIBRARY]
    # declared terms (an offset, gravity, the cable damping) the sidecar asserts are kept even
    # when the held-out data do not support them
    terms = list((meta.get("model") or {}).get("terms") or []) \
        if isinstance(meta.get("model"), dict) else []
    # numpy's BLAS on one thread: the loop solves many small systems, where BLAS threads only
    # contend for the cores (a 20 s flight: 58 s of CPU time on two threads, 18 s on one), and
    # the result is then the same as `cdam batch`'s residual tasks (one thread each)
    from threadpoolctl import threadpool_limits
    with threadpool_limits(1, user_api="blas"), \
            elapsed_ticker(args, f"fitting {args.model} and testing {len(LIBRARY)} library "
                                 f"effects on {len(ds)} samples"):
        sel = analyse(args.model, ds.t, signals, extra=extra or None, cutoff_hz=args.cutoff,
                      alpha=args.alpha, free_run=not args.no_free_run, fixed=fixed or None,
                      declared=declared, keep_terms=terms, estimator=_estimator(args),
                      stick_slip=args.stick_slip,
                      timing=args.timing, units=signal_units)
    js = to_json(sel)
    js["source"] = str(args.data)
    js["declared_effects"] = declared
    if args.test:
        with threadpool_limits(1, user_api="blas"):
            js["test"] = _test(args, mapping, inputs, sel)
    if args.save:
        js["saved_model"] = _save(args.save, sel, mapping, ds, args)
    if args.json:
        write_text_atomic(args.json, json.dumps(js, indent=2))
    if args.report:
        units = {name: u for name, col in mapping.items() if (u := ds.units.get(col))}
        write_report(sel, args.report, title=Path(args.data).name, source=str(args.data),
                     units=units)
    for line in _summary(js):
        print(line)
    if not js.get("complete", True):
        print("cdam residual: analysis incomplete: a free run could not be computed (see "
              "'unavailable' in the JSON); everything else was written", file=sys.stderr)
        return 1
    return 0


def _estimator(args) -> str:
    """--estimator, with --output-error its older spelling of ``oe``."""
    if args.output_error:
        if args.estimator not in ("auto", "oe"):
            raise CliError(f"--output-error: conflicts with --estimator {args.estimator}")
        return "oe"
    return args.estimator


def _test(args, mapping: dict, inputs: list, sel) -> dict:
    """Simulate the declared and final models on the --test record from its first --n-init
    outputs; write the simulated outputs with --simulated."""
    import numpy as np
    from cdam_core.record.dataset import read_dataset
    from cdam_core.residual.benchmark import protocol_scores
    ts = read_dataset(args.test, inputs=inputs or None)
    cols = dict(mapping)
    cols.update({c: c for c in inputs if c not in mapping.values()})
    for name, col in cols.items():
        if col not in ts.columns:
            raise ValueError(f"--test: column {col!r} (for {name}) not in {args.test}")
    from cdam_core.models.greybox.registry import get_model
    get_model(args.model).check_units({n: (c, ts.units.get(c)) for n, c in mapping.items()},
                                      f"--test: {args.test}")
    test = {name: ts.column(col) for name, col in cols.items()}
    test["t"] = ts.t
    scores = protocol_scores(sel, test, args.n_init)
    m = sel.final.model
    out = {"path": str(args.test), "n_init": args.n_init,
           "outputs": [mapping[p] for p in m.positions],
           "scores": {k: v.to_json() for k, v in scores.items()}}
    if args.simulated:
        from cdam_core.record.dataset import Dataset, write_dataset
        names, cols_out = [], []
        for j, p in enumerate(m.positions):
            names.append(mapping[p])
            cols_out.append(test[p])
            for label, sc in scores.items():
                if sc.status == "ok":
                    names.append(f"{mapping[p]}_{label}")
                    cols_out.append(sc.prediction[:, j])
        write_dataset(args.simulated, Dataset(t=ts.t, columns=names,
                                              data=np.column_stack(cols_out)), sidecar=False)
        out["simulated"] = str(args.simulated)
    return out


def _save(path, sel, mapping: dict, ds, args) -> dict:
    """Write the final (augmented) model as a ``greybox`` model file; returns its summary."""
    import numpy as np
    from cdam_core.models.file import save_model
    from cdam_core.residual.benchmark import greybox_of
    final = sel.final
    m = final.model
    g = greybox_of(final, float(np.mean(np.diff(ds.t))))
    extra = list(g.extra_columns)
    inputs = [mapping[i] for i in m.inputs] + extra
    outputs = [mapping[p] for p in m.positions]
    out = {}
    if args.firmware:
        g, out = _firmware_refit(sel, g, ds, inputs, outputs)
    digest = save_model(path, g, inputs=inputs, outputs=outputs,
                        meta={"source": Path(args.data).name, "command": "cdam residual",
                              "effects": [e.key for e in final.effects],
                              **({"firmware": True} if args.firmware else {})})
    return {"path": str(path), "kind": "greybox", "sha256": digest, **out}


def _firmware_refit(sel, g, ds, inputs, outputs):
    """``--firmware``: effects whose columns need rows after t (arm_coupling's zero-phase
    columns) are replaced by their causal form and the model is refitted on the record by the
    residual loop's own estimator (:func:`cdam_core.residual.selection.refit`: the same
    prepared record, trim, IDIM-WLS weights and two stages, bounds and chosen estimator): the
    board computes those columns row by row, so its parameters must be fitted on them. Returns
    the model and a summary (the one-step RMS error per output on the record: the residual
    loop's model, the same effects refitted with zero-phase columns (the loop's model again)
    and with causal ones, like with like)."""
    import dataclasses
    import numpy as np
    from cdam_core.residual.benchmark import greybox_of
    from cdam_core.residual.selection import refit
    causal = [dataclasses.replace(e, causal=True) if e.name == "arm_coupling" else e
              for e in g.effects]
    if causal == list(g.effects):
        return g, {"firmware_refit": False}
    U = np.column_stack([ds.column(c) for c in inputs])
    Y = np.column_stack([ds.column(c) for c in outputs])

    def rms(model):
        P = model.predict(U, Y, mode="one_step")
        return np.sqrt(np.mean((P[2:] - Y[2:]) ** 2, axis=0)).tolist()

    h = greybox_of(refit(sel, causal), g.dt)
    return h, {"firmware_refit": True,
               "estimator": (sel.settings.get("estimator") or {}).get("chosen", "IDIM-LS"),
               "one_step_rms_residual_model": rms(g),
               "one_step_rms_zero_phase": rms(greybox_of(refit(sel, list(g.effects)), g.dt)),
               "one_step_rms_causal": rms(h)}


def _rel(s, v) -> str:
    """A relative sigma for the summary ("-" where there is none)."""
    return (f"{100 * abs(s / v):.2g} %" if s is not None and v not in (0, None) and
            math.isfinite(s) else "-")


def _summary(js: dict) -> list[str]:
    """What a person reads on stdout (the whole result goes to --json FILE): the choices made,
    the final parameters with their sigma, the findings, the unexplained lines, the test."""
    st = js.get("settings", {})
    out = [f"model {js['model']}"]
    wc = (st.get("timing") or {}).get("windows_check") or {}
    if wc.get("equations_chose") and wc.get("chosen") != wc["equations_chose"]:
        eq = wc["equations_chose"]
        p_eq = st["timing"].get("p_value" if eq == "held" else "p_value_sampled")
        out.append(f"input timing: {wc['chosen']} (output error's windows, p "
                   f"{wc['p_value_' + wc['chosen']]:.2g}; the equations chose {eq}"
                   + (f", p {p_eq:.2g})" if p_eq is not None else ")"))
    elif (tm := st.get("timing")) and "chosen" in tm:
        p = tm.get("p_value" if tm["chosen"] == "held" else "p_value_sampled",
                   tm.get("p_value"))
        out.append(f"input timing: {tm['chosen']}" + (
            "" if p is None else f" (p {p:.2g})" if tm.get("decided", True)
            else f" (undecided, p {p:.2g}: the zero-order hold kept)"))
        if tm.get("warning"):
            out.append(f"  warning: {tm['warning']}")
    cut = (st.get("filter_choice") or {}).get("chosen_hz")
    if isinstance(cut, dict):
        out.append("derivative cut-offs: " + ", ".join(f"{k} {v:.3g} Hz" for k, v in cut.items()))
    elif cut is not None:
        out.append(f"derivative cut-off: {cut:.3g} Hz")
    if (est := st.get("estimator")) and "chosen" in est:
        out.append(f"estimator: {est['chosen']}")
    if (ss := st.get("stick_slip")) and ss.get("sticky_positions"):
        p = (ss.get("validation") or {}).get("p_value")
        out.append(f"validation windows' dry friction: {ss['chosen']}"
                   + (f" (stick-slip p {p:.2g})" if p is not None else f" ({ss['rule']})"))
    std = js.get("final_std") or {}
    out.append("final parameters (value, relative sigma):")
    dropped = {d.get("term") for d in st.get("declared_terms_dropped") or ()}
    ruled = {d.get("term") for d in st.get("declared_terms_ruled_out") or ()}
    for k, v in (js.get("final_parameters") or {}).items():
        if k in dropped:
            out.append(f"  {k} 0 (dropped: no held-out gain)")
            continue
        if k in ruled:
            out.append(f"  {k} 0 (ruled out by the units)")
            continue
        out.append(f"  {k} {v:.5g} ({_rel(std.get(k), v)})")
    unc = ((st.get("estimator") or {}).get("refinement") or {}).get("unconstrained")
    if unc:
        out.append(f"  at a bound: {', '.join(unc['lifted'])}; the same estimate without "
                   f"{'that bound' if len(unc['lifted']) == 1 else 'those bounds'}: " + (
                       ", ".join(f"{k} {v:.5g} ({_rel(unc['std'].get(k), v)})"
                                 for k, v in unc["theta"].items())
                       if "theta" in unc else f"unavailable ({unc.get('reason')})"))
    for k, v in (js.get("derived_parameters") or {}).items():
        out.append(f"  derived: {k} {v:.5g}")
    for d in st.get("declared_terms_dropped") or ():
        for e in d.get("exchangeable_with") or ():
            out.append(f"  not separable on this record: {d['term']} and {e['term']} "
                       f"(p {e['p_value']:.2g}): what is derived from either is undetermined")
    for f in js["findings"]:
        out.append(f"found {f['effect']} on {f['channel']}: {f['parameters']}")
    val = st.get("validation") or {}
    if not js["findings"] and val.get("status") == "unavailable":
        out.append(f"no effect claimed: too short to decide ({val.get('reason', '')})")
    elif not js["findings"] and val.get("status") == "off":
        out.append("no effect claimed: held-out validation off")
    elif not js["findings"]:
        out.append("no effect found")
    for u in js["unexplained"]:
        what = ("a periodic component the model's terms cannot produce"
                if u["kind"] == "periodic_line" else "unexplained structure")
        out.append(f"{what} on {u['channel']} at {u['frequency_hz']:.2f} Hz"
                   + (f", amplitude {u['amplitude']:.3g}" if "amplitude" in u else ""))
    for label, sc in (js.get("test") or {}).get("scores", {}).items():
        out.append(f"test simulation ({label} model): " + (
            ", ".join(f"{o} rmse {v:.4g}" for o, v in zip(js["test"]["outputs"], sc["rmse"]))
            if sc["status"] == "ok" else f"{sc['status']}: {sc['reason']}"))
    return out


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "residual", help="residual analysis: find the effect a declared model lacks",
        description="Fit a declared grey-box model by inverse-dynamics least squares, test "
                    "library effects on its residual, add the significant ones, report the "
                    "error before and after.")
    p.add_argument("data", help="dataset CSV (t first; optional JSON sidecar)")
    p.add_argument("--model", required=True,
                   choices=["rigid_axis", "flexible_joint", "quadrotor", "aerial_manipulator"])
    p.add_argument("--inputs", help="comma-separated input columns; those not mapped to the "
                                    "model are candidates for external_force")
    p.add_argument("--outputs", help="comma-separated output columns")
    p.add_argument("--map", help="model signal names to columns, e.g. tau=force,q=qm, or a JSON "
                                 "file of them (the syntax of every --map)")
    p.add_argument("--json", metavar="FILE",
                   help="also write the whole result as JSON to FILE (stdout has a summary)")
    p.add_argument("--test", help="test record (dataset CSV, same columns): the declared and "
                                  "the final model simulated open loop from its first --n-init "
                                  "outputs (nonlinearbenchmark.org's protocol), RMSE reported")
    p.add_argument("--n-init", type=int, default=20,
                   help="output samples of the test record the simulation starts from "
                        "(default 20: the EMPS benchmark's initialisation window)")
    p.add_argument("--simulated", help="write the test record's simulated outputs (CSV)")
    p.add_argument("--save", help="write the final model (declared model + the effects found) "
                                  "as a greybox model file here (docs/MODEL_FILE.md)")
    p.add_argument("--firmware", action="store_true",
                   help="with --save: refit the saved model for the board (cdam "
                        "export-firmware): arm_coupling's columns in their causal form, "
                        "computable row by row, and the model refitted on them")
    p.add_argument("--report", help="write a Markdown report with PNG figures into this folder")
    p.add_argument("--estimator", choices=("auto", "idim-ls", "idim-iv", "oe", "sim"),
                   default="auto",
                   help="how the final model's parameters are estimated (rigid_axis, "
                        "flexible_joint): auto tries IDIM-IV and output error (multiple "
                        "shooting from the IDIM-LS estimates) and keeps one only if it predicts "
                        "held-out windows better than IDIM-LS (the choice and its p-values are "
                        "reported; the flight models try IDIM-IV only); idim-ls skips them "
                        "(faster); idim-iv, oe or sim (simulation error over whole runs of the "
                        "record) forces one "
                        "(default: %(default)s)")
    p.add_argument("--stick-slip", choices=("auto", "on", "off"), default="auto",
                   help="the chosen model's Runge-Kutta validation windows (rigid_axis, "
                        "flexible_joint): a dry friction stops the motion at zero speed and "
                        "holds it while the rest of the force is inside its level (on), or its "
                        "sign is held over each step (off); auto keeps stick-slip only if it "
                        "predicts held-out windows better (the comparison and its p-value are "
                        "reported; default: %(default)s)")
    p.add_argument("--output-error", action="store_true",
                   help="force the output-error refinement: the same as --estimator oe")
    p.add_argument("--cutoff", type=float, default=None,
                   help="derivative filter cutoff in Hz (default: rigid_axis and "
                        "flexible_joint choose one per position from the record, where its "
                        "spectrum meets the encoder noise; the flight models use 2 Hz for the "
                        "body channels and 20 Hz for the joints)")
    p.add_argument("--timing", choices=("auto", "sampled", "held"), default="auto",
                   help="where the equations put the state against input sample k: at t_k "
                        "(sampled: a measured current), half a sample later (held: a DAC's "
                        "zero-order hold), or auto: chosen by held-out equation error "
                        "(rigid_axis, flexible_joint; the flight models keep sampled)")
    p.add_argument("--fixed", help="known parameters, e.g. m=1.82 (the weighed mass, which "
                                   "payload_mass needs)")
    p.add_argument("--alpha", type=float, default=0.01, help="significance level (default 0.01)")
    p.add_argument("--no-free-run", action="store_true", help="skip the free-run simulation")
    add_outputs(p, json=False, report=False)
    p.set_defaults(func=run)
