"""The residual analysis as JSON and as a report (Markdown and HTML) with PNG figures
(matplotlib, Agg): units on every axis and in the parameter tables (``report.units``), a caption
under every figure, the residual spectrum one panel per channel."""
from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from cdam_core.base.jsonio import atomic_target, plain, write_text_atomic
from cdam_core.report.page import figure, write_page
from cdam_core.report.units import channel_unit, derived_unit, parameter_unit

from cdam_core.residual import diagnostics as dg
from cdam_core.residual.selection import ESTIMATORS, SINGLE_ROUTE, Selection


def held_out_line(v: dict) -> str:
    """A finding's held-out decision (``Comparison.to_json``) as one sentence."""
    how = ", ".join(x for x in (f"{v['route']} fold fits" if v.get("route") else "",
                                f"{v['rollout']} windows" if v.get("rollout") else "") if x)
    other = v.get("other_rollout") or v.get("other_route")
    return (f"Held out: mean window error {v['score_rich']:.3g} with it against "
            f"{v['score_simple']:.3g} without, one-sided Wilcoxon p {v['p_value']:.2g} at level "
            f"{v['level']:.2g}" + (f" ({how})" if how else "")
            + (f"; the other {'rollout' if v.get('other_rollout') else 'route'}: p "
               f"{other['p_value']:.2g}" if other else "") + ".")


def to_json(sel: Selection) -> dict:
    """The issue's JSON: model, declared_error, findings, residual_white_after, unexplained.

    Error dictionaries are keyed by channel: equation channels (``tau``, ``tau_m``, ``tau_l``)
    hold the equation error (nrmse = ||e|| / ||measured torque||), output channels (``q``,
    ``theta_m``) the free-run error (nrmse = rmse / std(measured)). Extra keys:
    ``declared_parameters``, ``final_parameters``, ``derived_parameters`` (physical quantities
    that follow from them: the declared model's ``derived``), ``error_final`` (the final model's errors),
    ``removed_in_backward_pass`` (claims withdrawn when re-tested with all others) and
    ``settings``.
    """
    model = sel.model
    findings = []
    for st in sel.steps:
        eff = st.candidate.effect
        findings.append({"effect": eff.name, "channel": eff.channel,
                         "parameters": eff.parameters(st.candidate.fit.theta, model),
                         "error_before": st.error_before, "error_after": st.error_after,
                         "evidence": st.evidence})
    filt = sel.declared.signals.get("filter")
    settings = dict(sel.settings)
    settings["derivative_filter"] = filt.describe() if filt is not None else None
    return plain({
        "model": model.name,
        "declared_error": sel.declared_error,
        "findings": findings,
        "residual_white_after": sel.white_after,
        "unexplained": sel.unexplained,
        "error_final": sel.final_error,
        "removed_in_backward_pass": sel.removed,
        "declared_parameters": sel.declared.theta,
        "final_parameters": sel.final.theta,
        "derived_parameters": model.derived(sel.final.theta),
        "declared_std": sel.declared.std,
        "final_std": sel.final.std,
        "feasibility": {k: {"feasible": not f.violations, "violations": f.violations,
                            "unconstrained": f.unconstrained,
                            "bounds": {p: list(b) for p, b in _bounds(f).items()}}
                        for k, f in (("declared", sel.declared), ("final", sel.final))},
        "complete": _complete(sel),
        "settings": settings,
    })


def _bounds(f) -> dict:
    out = dict(getattr(f.model, "bounds", {}) or {})
    for e in f.effects:
        out.update(e.bounds())
    return {p: b for p, b in out.items() if p in f.theta}


def _complete(sel: Selection) -> bool:
    """False when a part of the analysis (a free run) could not be computed."""
    errs = [sel.declared_error, sel.final_error] + [s.error_before for s in sel.steps] + \
        [s.error_after for s in sel.steps]
    return not any(isinstance(v, dict) and v.get("status") == "unavailable"
                   for e in errs for v in (e or {}).values())


def _fmt_err(err: dict) -> str:
    return "; ".join(f"{k}: free run unavailable ({v['reason']})" if v.get("status") else
                     f"{k}: RMSE {v['rmse']:.4g}, NRMSE {100 * v['nrmse']:.2f} %"
                     for k, v in err.items())


def _bracket(unit: str) -> str:
    return f"[{unit}]" if unit else "[equation units]"


def _figure_finding(path: Path, sel: Selection, i: int, units: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    st = sel.steps[i]
    eff, model = st.candidate.effect, sel.model
    ch = eff.display_equation(st.before.residuals)
    r0, r1 = st.before.residuals[ch], st.candidate.fit.residuals[ch]
    t = st.before.signals["t"][st.before.keep]
    u = st.before.signals[model.inputs[0]][st.before.keep]
    reg = eff.regressor_signal(st.candidate.fit.signals, model)[st.before.keep]
    fig, ax = plt.subplots(2, 2, figsize=(11, 7))
    ax[0, 0].plot(t, r0, lw=0.6, label="before")
    ax[0, 0].plot(t, r1, lw=0.6, label="after")
    ru = _bracket(channel_unit(model.name, ch, units))
    ax[0, 0].set(title=f"residual ({ch})", xlabel="t [s]", ylabel=f"residual {ru}")
    ax[0, 0].legend()
    for r, lab in ((r0, "before"), (r1, "after")):
        ac = dg.autocorrelation(r, 25)
        ax[0, 1].plot(ac["lags"], ac["acf"], "o-", ms=3, label=lab)
    ax[0, 1].axhspan(-ac["band"], ac["band"], color="grey", alpha=0.3, label="99 % band")
    ax[0, 1].set(title="residual autocorrelation", xlabel="lag [samples]",
                 ylabel="autocorrelation [-]")
    ax[0, 1].legend()
    for r, lab in ((r0, "before"), (r1, "after")):
        cc = dg.cross_correlation(r, u, 25)
        ax[1, 0].plot(cc["lags"], cc["ccf"], "o-", ms=3, label=lab)
    ax[1, 0].axhspan(-cc["band"], cc["band"], color="grey", alpha=0.3)
    ax[1, 0].set(title=f"residual / input ({model.inputs[0]}) cross-correlation",
                 xlabel="lag [samples]", ylabel="cross-correlation [-]")
    ax[1, 0].legend()
    step = max(1, r0.size // 4000)
    ax[1, 1].plot(reg[::step], r0[::step], ".", ms=2)
    ax[1, 1].set(title=f"{eff.key} regressor against residual before",
                 xlabel="regressor [per unit of the parameter]", ylabel=f"residual {ru}")
    fig.tight_layout()
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)


def _figure_spectrum(path: Path, sel: Selection, units: dict) -> None:
    """The residual's Welch spectrum, one panel per channel (declared and final model), the
    unexplained lines marked on their channel's panel."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fs = 1.0 / sel.declared.signals["dt"]
    chans = list(dict.fromkeys(list(sel.declared.residuals) + list(sel.final.residuals)))
    fig, axes = plt.subplots(len(chans), 1, figsize=(8, 2.6 * len(chans) + 0.4), squeeze=False,
                             sharex=True)
    for ax, ch in zip(axes[:, 0], chans):
        for lab, f_ in (("declared", sel.declared), ("final", sel.final)):
            if ch in f_.residuals:
                f, p = dg.spectrum(f_.residuals[ch], fs, 0.25)
                ax.semilogy(f, p, lw=0.8, label=f"{lab} model")
        for u in sel.unexplained:
            if u["channel"] == ch:
                ax.axvline(u["frequency_hz"], color="r", ls="--", lw=0.8)
        unit = channel_unit(sel.model.name, ch, units)
        ax.set(ylabel=f"PSD [{unit}²/Hz]" if unit else "PSD [(equation units)²/Hz]",
               title=f"residual spectrum (Welch), channel {ch}")
        ax.grid(True, alpha=0.3, which="both")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("frequency [Hz]")
    fig.tight_layout()
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)


def _bounded_rms(sel) -> float:
    """The final output-error estimate's window RMS (NaN when not reported)."""
    ref = (sel.settings.get("estimator") or {}).get("refinement") or {}
    return float(ref.get("window_rms_after", float("nan")))


def _param_rows(sel, fit, units: dict) -> list[str]:
    """Table rows: parameter, value, standard deviation, relative sigma, unit."""
    rows = []
    for k, v in fit.theta.items():
        sd = fit.std.get(k)
        unit = parameter_unit(sel.model.name, k, units)
        if k not in fit.estimated:
            rows.append(f"| {k} | {v:.6g} | fixed | | {unit} |")
        elif sd is None or not np.isfinite(sd):
            rows.append(f"| {k} | {v:.6g} | n/a (at a bound or not identifiable) | | {unit} |")
        else:
            rel = f"{100 * sd / abs(v):.3g}" if v != 0 else ""
            rows.append(f"| {k} | {v:.6g} | {sd:.3g} | {rel} | {unit} |")
    return rows


_PARAM_HEAD = ["| parameter | value | standard deviation | relative sigma [%] | unit |",
               "|---|---|---|---|---|"]


def write_report(sel: Selection, out_dir, title: str | None = None, source: str = "",
                 units: dict | None = None) -> Path:
    """Write ``index.md``, ``index.html``, ``residual.json`` and the PNG figures into
    ``out_dir``. ``units``: the record's unit per model signal (``{"tau": "N", "q": "m"}``),
    for the axes and the parameter tables (blank where not given)."""
    units = dict(units or {})
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"out_dir: {out} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    js = to_json(sel)
    write_text_atomic(out / "residual.json", json.dumps(js, indent=2))
    lines = [f"# Residual analysis: {title or sel.model.name}", ""]
    if source:
        lines += [f"Data: {source}", ""]
    lines += [f"Declared model `{sel.model.name}`; derivatives: "
              f"{js['settings'].get('derivative_filter')}.", ""]
    if getattr(sel.model, "parallel_filter", False):
        lines += ["Both sides of every equation are low-passed alike (parallel filtering).", ""]
    tm = sel.settings.get("timing") or {}
    if tm:
        why = (f"held-out equation error {tm['held_out_error']['sampled']:.4g} (sampled) against "
               f"{tm['held_out_error']['held']:.4g} (held) over {tm['windows']} windows, "
               f"Wilcoxon p {tm['p_value']:.2g} (held better), "
               f"{tm.get('p_value_sampled', float('nan')):.2g} (sampled better)"
               + ("" if tm.get("decided", True) else
                  ": neither at the level, the documented zero-order hold kept")
               if tm.get("status") == "ok"
               else tm.get("reason") or tm.get("rule", ""))
        lines += [f"Input timing: **{tm['chosen']}** "
                  + ("(the state half a sample after each input sample: a zero-order hold)"
                     if tm["chosen"] == "held" else "(the state at the input's sample instant)")
                  + f"; {why}.", ""]
        if tm.get("warning"):
            lines += [f"**Warning:** {tm['warning']}.", ""]
    lines += ["## Declared model", ""] + _PARAM_HEAD + _param_rows(sel, sel.declared, units)
    lines += ["", "| channel | RMSE | NRMSE |", "|---|---|---|"]
    lines += [f"| {k} | {v['rmse']:.4g} {channel_unit(sel.model.name, k, units)} | "
              f"{100 * v['nrmse']:.2f} % |" for k, v in sel.declared_error.items()]
    lines += ["", "## Findings", ""]
    if not sel.steps:
        val = sel.settings.get("validation") or {}
        lines += [f"No effect claimed: {val['decision']} ({val.get('reason', '')})."
                  if val.get("status") in ("unavailable", "off") and "decision" in val
                  else "No candidate effect predicts held-out data better.", ""]
    for i, (st, fjs) in enumerate(zip(sel.steps, js["findings"])):
        png = f"finding_{i + 1}_{fjs['effect']}.png"
        _figure_finding(out / png, sel, i, units)
        ev = fjs["evidence"]
        lines += [f"### {i + 1}. `{fjs['effect']}` on `{fjs['channel']}`", "",
                  "Parameters: " + ", ".join(
                      f"{k} = {v:.6g}" + (f" {u}" if (u := parameter_unit(
                          sel.model.name, f"{st.candidate.effect.key}.{k}", units)) else "")
                      if isinstance(v, float) else f"{k} = {v}"
                      for k, v in fjs["parameters"].items()),
                  "", "| channel | before RMSE | before NRMSE | after RMSE | after NRMSE |",
                  "|---|---|---|---|---|"]
        for k, b in fjs["error_before"].items():
            a = fjs["error_after"][k]
            u = channel_unit(sel.model.name, k, units)
            lines.append(f"| {k} | {b['rmse']:.4g} {u} | {100 * b['nrmse']:.2f} % | "
                         f"{a['rmse']:.4g} {u} | {100 * a['nrmse']:.2f} % |")
        lines += ["", f"Evidence: ERR {ev['err']:.3g}, F = {ev['f_statistic']:.4g} on "
                  f"({ev['added_parameters']}, N_eff = {ev['n_eff']:.0f}) -> p = {ev['p_value']:.3g}, "
                  f"delta BIC {ev['delta_bic']:.4g}; Ljung-Box p before "
                  f"{ev['ljung_box_before']['pvalue']:.3g}, after {ev['ljung_box_after']['pvalue']:.3g}.",
                  ""] + ([held_out_line(ev["validation"]), ""] if ev.get("validation") else []) \
            + figure(png, f"finding {i + 1}",
                               f"Figure {i + 1}: residual of the {st.candidate.effect.display_equation(st.before.residuals)} "
                               f"equation before and after adding `{fjs['effect']}` against "
                               "time (top left), its autocorrelation with the 99 % band of a "
                               "white residual (top right), its cross-correlation with the "
                               f"input `{sel.model.inputs[0]}` (bottom left), and the effect's "
                               "regressor against the residual before (bottom right).")
    lines += ["## After", "", f"Residual white (Ljung-Box, 25 lags, 1 %): "
              f"{'yes' if sel.white_after else 'no'}.", ""]
    lines += _PARAM_HEAD + _param_rows(sel, sel.final, units)
    lines += ["", "Standard deviations are the chosen estimator's (IDIM-LS and IDIM-IV: from "
              "the equations; output error: from the windows' Jacobian), errors taken as white: "
              "optimistic when they are not."]
    unc = ((sel.settings.get("estimator") or {}).get("refinement") or {}).get("unconstrained")
    if unc:
        lines += ["", f"At a bound: {', '.join(unc['lifted'])} (no standard deviation there; "
                  "the others' are conditional on it). The same output-error estimate without "
                  "that bound, reported beside it (window RMS "
                  + (f"{unc['window_rms_after']:.4g} against {_bounded_rms(sel):.4g} "
                     "bounded):" if "theta" in unc else
                     f"-): unavailable, {unc.get('reason')}.")]
        if "theta" in unc:
            fit = SimpleNamespace(theta=unc["theta"], std=unc["std"], estimated=unc["theta"])
            lines += [""] + _PARAM_HEAD + _param_rows(sel, fit, units)
    dropped = sel.settings.get("declared_terms_dropped") or []
    if dropped:
        lines += ["", "Declared terms the held-out data do not support (fixed at 0): "
                  + ", ".join(f"{d['term']} (p {d['p_value']:.2g})" for d in dropped) + "."]
    pairs = [(d["term"], e["term"], e["p_value"]) for d in dropped
             for e in d.get("exchangeable_with") or ()]
    if pairs:
        lines += ["", "Not separable on this record (the held-out windows do not prefer one of "
                  "the two): " + ", ".join(f"{a} and {b} (p {p:.2g})" for a, b, p in pairs)
                  + "; the one kept holds both, and a quantity derived from either is "
                  "undetermined here."]
    ruled = sel.settings.get("declared_terms_ruled_out") or []
    if ruled:
        lines += ["", "Declared terms the units rule out (fixed at 0): "
                  + ", ".join(d["term"] for d in ruled) + f" ({ruled[0]['reason']})."]
    derived = js.get("derived_parameters") or {}
    if derived:
        lines += ["", "Derived from the final parameters (the model's `derived`): " + ", ".join(
            f"{k} = {v:.6g}" + (f" {u}" if (u := derived_unit(sel.model.name, k, units)) else "")
            for k, v in derived.items()) + "."]
    cmp = sel.settings.get("structures_compared_by") or {}
    if cmp.get("validation"):
        single = {"IDIM-LS"} | {ESTIMATORS[c] for c in SINGLE_ROUTE}
        both = "" if cmp["chosen"] in single else (
            " and by their IDIM-LS fold fits (two routes, each at half the level: a structure "
            "is better if either says so)")
        lines += ["", f"Structures (effects added, the backward pass) compared on held-out "
                      f"windows by their {cmp['chosen']} fold fits, the estimator the windows "
                      f"choose for the declared model{both}; those holding a dry friction on "
                      "two rollouts of the windows, its sign held over each step and its "
                      "stick-slip, each at half the level."]
    est = sel.settings.get("estimator") or {}
    if est.get("validation"):
        alts = "; ".join(f"{name}: mean error {v['score_rich']:.3g} against IDIM-LS's "
                         f"{v['score_simple']:.3g}, one-sided Wilcoxon p {v['p_value']:.2g} at "
                         f"level {v['level']:.2g}" for name, v in est["validation"].items())
        how = f" by {est['windows_integrator']}" if est.get("windows_integrator") else ""
        lines += ["", f"Estimator: {est['chosen']} (alternatives on held-out windows{how}: "
                      f"{alts})."]
    elif str(est.get("rule", "")).startswith("given"):
        lines += ["", f"Estimator: {est['chosen']} ({est['rule']})."]
    stick = sel.settings.get("stick_slip") or {}
    if stick.get("sticky_positions"):
        v = stick.get("validation")
        lines += ["", f"Validation windows' dry friction (on {', '.join(stick['sticky_positions'])}): "
                      f"{stick['chosen']} ({stick['rule']}"
                  + (f"; mean held-out error with stick-slip {v['score_rich']:.3g} against "
                     f"{v['score_simple']:.3g} held, p {v['p_value']:.2g} at level "
                     f"{v['level']:.2g}" if v else "") + ")."]
    frc = est.get("free_run_check") or {}
    if frc.get("earlier"):
        lines += ["", "Free runs of held-out blocks (each fold's model, its state fitted on the "
                      "block's first window, the rest simulated open loop; mean normalised "
                      f"squared error): final model {frc['final_score']:.3g}; "
                  + "; ".join(f"{r['step']} {r['score_rich']:.3g} (p {r['p_value']:.2g})"
                              for r in frc["earlier"])
                  + (". Earlier steps simulating them better than the final model: "
                     + ", ".join(frc["earlier_better"]) if frc["earlier_better"] else
                     ". No earlier step simulates them better than the final model")
                  + " (reported, not acted on)."]
    stab = sel.settings.get("stability") or {}
    if "stable" in stab:
        lines += ["", "Linearised at rest (effects left out): " + (
            "stable" if stab["stable"] else "**unstable**: the model falls over or diverges "
            "in a free run") + f" (largest real part of the eigenvalues {stab['max_real_part']:.3g}"
            " 1/s)."]
    elif stab:
        lines += ["", f"Stability not computed: {stab.get('reason')}."]
    idf = sel.settings.get("identifiability")
    if idf and not idf.get("identifiable", True):
        lines += ["", f"Not identifiable as {idf.get('declared')}: {idf.get('fallback')}."]
    lines += ["", "## Unexplained structure", ""]
    if sel.unexplained:
        lines += ["| channel | kind | frequency [Hz] | strength |", "|---|---|---|---|"]
        lines += [f"| {u['channel']} | {u['kind']} | {u['frequency_hz']:.2f} | "
                  + (f"{u['prominence_decades']:.2f} decades above its base"
                     if "prominence_decades" in u else
                     f"amplitude {u['amplitude']:.3g}"
                     f"{(' ' + channel_unit(sel.model.name, u['channel'], units)).rstrip()} "
                     f"(x{u['ratio_to_background']:.3g} "
                     f"the background, p {u['p_value']:.2g}"
                     + (f"; {u['attribution']['unexplained_amplitude']:.3g} beyond what the "
                        "model's terms driven by the inputs produce" if "attribution" in u
                        else "") + ")") + " |"
                  for u in sel.unexplained]
        lines += ["", "No library effect explains these; they are reported, not fitted."]
    else:
        lines += ["None found (no spectral peak of 1 decade or more and no periodic line "
                  "beyond what the model's terms, driven by the measured inputs, produce)."]
    _figure_spectrum(out / "spectrum.png", sel, units)
    lines += [""] + figure("spectrum.png", "spectrum",
                           f"Figure {len(sel.steps) + 1}: power spectral density (Welch) of the "
                           "residual of the declared and the final model, one panel per channel; "
                           "dashed red lines: structure no library effect explains (table above).")
    return write_page(out / "index.md", lines, f"Residual analysis: {title or sel.model.name}")
