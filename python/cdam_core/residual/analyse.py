"""The residual loop on arrays: fit the declared model, select the missing effects."""
from __future__ import annotations

from cdam_core.models.greybox.declared import DerivativeFilter
from cdam_core.residual.cutoff import at_rest, choose_cutoff, given_cutoff
from cdam_core.residual.identifiability import deflection_check
from cdam_core.models.greybox.registry import get_model
from cdam_core.models.greybox.effects import LIBRARY, candidates as library_candidates
from cdam_core.residual.selection import (ESTIMATOR_CHOICES, ESTIMATORS, STICK_SLIP_CHOICES,
                                          Selection, select)
from cdam_core.residual.timing import choose_timing, windows_timing

__all__ = ["analyse"]


def analyse(model: str, t, signals: dict, extra: dict | None = None, fixed: dict | None = None,
            cutoff_hz: float | None = None, alpha: float = 0.01, free_run: bool = True,
            validation: tuple | None = None, options: dict | None = None,
            max_steps: int | None = None, declared=(), keep_terms=(),
            estimator: str = "auto", timing: str = "auto",
            stick_slip: str = "auto", units: dict | None = None) -> Selection:
    """Fit ``model`` to the signals, select missing effects, return the :class:`Selection`.

    ``signals`` maps the model's signal names (``tau``, ``q`` / ``tau_m``, ``theta_m``, ``q`` /
    the dataset's channel names for the flight models) to arrays; ``extra`` holds measured
    channels left out of the model (``external_force`` candidates); ``validation`` = (t, signals)
    of another record for the free-run errors; ``fixed``: known parameters (e.g. the weighed
    mass ``m``, which ``payload_mass`` needs); ``declared``: library effect names the declared
    model already holds (on every channel they apply to), e.g. the sidecar's model effects;
    ``estimator``: "auto" (IDIM-LS, IDIM-IV or the output-error refinement, chosen on held-out
    windows), "idim-ls" (the others not tried: cheaper), "idim-iv", "oe" or "sim" (forced);
    the choice and its evidence are in ``settings["estimator"]``; ``stick_slip``: "auto"
    (the chosen model's RK4 windows simulate the dry friction's stick-slip only where that
    predicts held-out windows better than its sign held over each step), "on" or "off"
    (given); the choice and its evidence are in ``settings["stick_slip"]``;
    ``keep_terms``: optional declared terms (``offset``, ``G``, ``Kd``) kept even when the
    held-out data do not support them (a sidecar that declares them);
    ``timing``: "auto" (chosen from the record on held-out blocks,
    :func:`cdam_core.residual.timing.choose_timing`; the flight models keep "sampled" at their
    documented bands), "sampled" or "held" (see ``GreyBoxModel.prepare``); the choice and its
    evidence are in ``settings["timing"]`` (a given "sampled" is checked against the record:
    ``record`` and, when the record prefers the hold, ``warning``);
    ``units``: the declared units of the signals (``{"tau": "N", "q": "m"}``, the known
    ones): declared terms they rule out are fixed at 0 (a linear axis has no gravity terms,
    ``GreyBoxModel.ruled_out``; listed in ``settings["declared_terms_ruled_out"]``), unless
    ``fixed`` gives them;
    ``cutoff_hz``: derivative filter cutoff (default: chosen from the record by held-out
    simulation, :func:`cdam_core.residual.cutoff.choose_cutoff`; the choice and the candidates'
    scores are in ``settings["filter_choice"]``).
    """
    if timing not in ("auto", "sampled", "held"):
        raise ValueError(f"timing: expected auto, sampled or held, got {timing!r}")
    if estimator not in ESTIMATOR_CHOICES:
        raise ValueError(f"estimator: expected one of {', '.join(ESTIMATOR_CHOICES)}, "
                         f"got {estimator!r}")
    if stick_slip not in STICK_SLIP_CHOICES:
        raise ValueError(f"stick_slip: expected one of {', '.join(STICK_SLIP_CHOICES)}, "
                         f"got {stick_slip!r}")
    if units is not None and not (isinstance(units, dict) and all(
            isinstance(k, str) and isinstance(v, str) for k, v in units.items())):
        raise ValueError("units: expected a dict {signal: unit text}")
    ruled = get_model(model).ruled_out(dict(units or {}))
    ruled = {p: why for p, why in ruled.items() if p not in (fixed or {})}
    if ruled:
        fixed = {**(fixed or {}), **{p: 0.0 for p in ruled}}
    m = get_model(model, fixed)
    keep_terms = [keep_terms] if isinstance(keep_terms, str) else list(keep_terms)
    unknown = [p for p in keep_terms if p not in m.parameter_names]
    if unknown:
        raise ValueError(f"keep_terms: {', '.join(map(str, unknown))} not parameters of {m.name}")
    clash = [p for p in keep_terms if p in ruled]
    if clash:
        raise ValueError(f"keep_terms: {', '.join(clash)} declared, but the units rule "
                         f"{'them' if len(clash) > 1 else 'it'} out ({ruled[clash[0]]})")
    if isinstance(declared, str):
        declared = [declared]
    for name in declared:
        if name not in LIBRARY:
            raise ValueError(f"declared: unknown effect {name!r} (known: {', '.join(LIBRARY)})")
    cands = library_candidates(m, list((extra or {}).keys()), options)
    dec = [c for c in cands if c.name in set(declared)]
    choice = {"rule": "given" if cutoff_hz is not None else "the model's default",
              "chosen_hz": cutoff_hz if cutoff_hz is not None else m.default_cutoff_hz}
    trim = None
    if getattr(m, "fixed_bands", False):    # the flight models keep their documented bands
        filt = DerivativeFilter(cutoff_hz=choice["chosen_hz"])
    else:   # given, or chosen from the record; either way the rows at rest are left out
        if cutoff_hz is not None:
            filt = DerivativeFilter(cutoff_hz=cutoff_hz)
            choice = given_cutoff(m, t, signals, cutoff_hz, filt.order)
        else:
            filt, choice = choose_cutoff(m, t, signals, extra)
            trim = choice["trim_samples"]
        cands = at_rest(m, cands, choice, alpha)
        dec = [c for c in cands if c.name in set(declared)]
    if timing == "auto" and getattr(m, "fixed_bands", False):
        timing_info = {"chosen": "sampled", "rule": "the flight models' documented bands"}
        timing = "sampled"
    elif timing == "auto":
        timing, timing_info = choose_timing(
            m, lambda tm: m.prepare(t, signals, filt, extra, tm), dec,
            50 if trim is None else trim, alpha)
    else:
        timing_info = {"chosen": timing, "rule": "given"}
        if not getattr(m, "fixed_bands", False):
            # a given timing is used, but what the record says is reported beside it: on a
            # zero-order-hold record analysed as "sampled" the half-sample timing error is
            # absorbed by whatever column resembles it (exact-ZOH frictionless axis, 40-60 s:
            # a Coulomb friction Fc 0.003-0.008 claimed held out on 6 of 8 records; with the
            # timing the record chooses, "held" at p ~3e-20, none)
            rec, rec_info = choose_timing(m, lambda tm: m.prepare(t, signals, filt, extra, tm),
                                          dec, 50 if trim is None else trim, alpha)
            timing_info["record"] = {"chosen": rec, "decided": bool(rec_info.get("decided")),
                                     **{k: rec_info[k] for k in ("p_value", "p_value_sampled")
                                        if k in rec_info}}
            if rec != timing and rec_info.get("decided"):
                p_rec = rec_info["p_value" if rec == "held" else "p_value_sampled"]
                timing_info["warning"] = (
                    f"the record's held-out equations prefer the {rec} timing ("
                    + ("a zero-order hold" if rec == "held" else "the input at its sample "
                       "instant") + f", p {p_rec:.2g}): a finding may be the half-sample "
                    "timing error")
    sig = m.prepare(t, signals, filt, extra, timing)
    check = None
    motor_side = len(m.positions) == 2 and "theta_m" in signals and m.cables and \
        not getattr(m, "fixed_bands", False)

    def rigid_fallback(why: dict):
        """The motor side alone: a rigid axis with its friction (item 4 of [greybox])."""
        motor = {"tau": signals[m.inputs[0]], "q": signals["theta_m"]}
        mu = {k: (units or {}).get(s) for k, s in (("tau", m.inputs[0]), ("q", "theta_m"))}
        out = analyse("rigid_axis", t, motor, extra, None, None, alpha, free_run,
                      None, options, max_steps, declared, estimator=estimator,
                      stick_slip=stick_slip, units={k: u for k, u in mu.items() if u},
                      timing=timing_info["chosen"] if timing_info["rule"] == "given"
                      else "auto")
        out.settings["identifiability"] = {**why, "declared": m.name}
        return out
    if m.cables and not getattr(m, "fixed_bands", False):   # a cable between two encoders
        noise = sum(ev.get("noise_level", 0.0) * choice["chosen_hz"][p]
                    for p, ev in choice.get("signals", {}).items())
        check = deflection_check(sig, trim or 50, noise, alpha)
        if not check["identifiable"] and motor_side:
            return rigid_fallback({**check, "fallback": "rigid_axis on the motor side "
                                   "(tau_m, theta_m): the motor-minus-link angle is not a "
                                   "cable's deflection"})
    val = None
    if validation is not None:
        val = m.prepare(validation[0], validation[1], sig["filter"], None, timing)
    sel = select(m, sig, cands, alpha=alpha, free_run=free_run, validation=val,
                 max_steps=max_steps, declared_effects=dec, trim=trim, keep_terms=keep_terms,
                 estimator=estimator, stick_slip=stick_slip)
    if timing_info["rule"] != "given" and not getattr(m, "fixed_bands", False) and \
            sel.settings["estimator"].get("chosen") == ESTIMATORS["oe"]:
        # the timing the equations chose, checked on the chosen estimator's windows
        check_t = windows_timing(sel.final.model, lambda tm: m.prepare(t, signals, filt, extra,
                                                                         tm),
                                 sel.final.effects, timing, sel.settings["trim"], alpha)
        timing_info = {**timing_info, "windows_check": check_t}
        if check_t["chosen"] != timing:
            timing = timing_info["chosen"] = check_t["chosen"]
            timing_info["rule"] = ("the equations' choice, overruled by output error's "
                                   "windows (windows_check)")
            sig = m.prepare(t, signals, filt, extra, timing)
            if validation is not None:
                val = m.prepare(validation[0], validation[1], sig["filter"], None, timing)
            sel = select(m, sig, cands, alpha=alpha, free_run=free_run, validation=val,
                         max_steps=max_steps, declared_effects=dec, trim=trim,
                         keep_terms=keep_terms, estimator=estimator, stick_slip=stick_slip)
    sel.settings["filter_choice"] = choice
    sel.settings["timing"] = timing_info
    if ruled:
        sel.settings["declared_terms_ruled_out"] = [{"term": p, "reason": why}
                                                    for p, why in ruled.items()]
    if check is not None:
        sel.settings["identifiability"] = check
    zero = [k for k in m.collapses_at_zero
            if k not in m.fixed and not sel.final.theta.get(k, 0.0) > 0.0]
    if zero and motor_side:
        # an inertia or the cable's stiffness at its bound 0: the flexible model cannot be
        # simulated and its other estimates absorb the missing term; the record does not
        # separate the link from the motor (a deflection near the encoders' resolution)
        return rigid_fallback({**(check or {}), "fallback": "rigid_axis on the motor side "
                               "(tau_m, theta_m): the flexible fit is degenerate ("
                               + ", ".join(f"{k} = 0" for k in zero) + " at its physical "
                               "bound): the record does not separate the link from the motor",
                               "degenerate": sorted(zero),
                               "flexible_estimates": {k: float(v) for k, v in
                                                      sel.final.theta.items()}})
    return sel
