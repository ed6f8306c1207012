"""Each library effect hidden in synthetic records (tests/test_residual_synth_data.py):
found on the right channel, parameter within 20 %, >= 80 % of the excess error removed,
at the default noise and at three times that noise; no effect -> no finding; two effects ->
both found; a periodic force outside the library -> unexplained, no effect claimed."""
from functools import lru_cache

import pytest
from test_residual_synth_data import flexible_joint_record, rigid_axis_record

from cdam_core.residual import analyse

RIG = ("tau", "q")
FLX = ("tau_m", "theta_m", "q")


def _run(rec, keys, model, extra=None, estimator="idim-ls"):
    """The loop with IDIM-LS pinned: these tests are about which effects are found. (With the
    default estimator choice, output error is chosen on the Coulomb + delay record, p 9e-14,
    and moves Fc from 1.36 to 1.15 against the generator's 1.5 (measured): the generator
    integrates Fc sign(v) by RK4 at one step per sample with the sign evaluated at every
    stage, whose stages cancel it where |v| < dt Fc / (2 M) (the windows hold it over a step:
    GreyBox._rollout), and adds an unmeasured force noise, so the plain sign that simulates
    its record best on the windows is lower; measured in session 7 on Euler windows, not
    investigated further.)"""
    return analyse(model, rec["t"], {k: rec[k] for k in keys}, extra=extra, free_run=False,
                   estimator=estimator)


@lru_cache(maxsize=None)
def _clean_rmse(model, noise, seed):
    rec = rigid_axis_record(seed=seed, noise=noise) if model == "rigid_axis" else \
        flexible_joint_record(seed=seed, noise=noise)
    keys = RIG if model == "rigid_axis" else FLX
    return _run(rec, keys, model).declared_error


CASES = [  # model, generator kwargs, effect, channel, parameter, truth
    ("rigid_axis", {"Fc": 1.5}, "coulomb_friction", "tau", "Fc", 1.5),
    ("rigid_axis", {"delay": 0.03}, "actuator_delay", "tau", "delay", 0.03),
    ("rigid_axis", {"ext_gain": 1.0}, "external_force", "tau", "gain", 1.0),
    ("flexible_joint", {"K3": 200.0}, "hardening_stiffness", "tau_l", "K3", 200.0),
    ("flexible_joint", {"backlash": 0.02}, "backlash", "tau_l", "width", 0.02),
    ("flexible_joint", {"Fc_link": 0.1}, "coulomb_friction", "tau_l", "Fc", 0.1),
]


# at three times the noise the derivative cut-off chosen from the record (35 Hz) smooths the
# dry friction's sign; with parallel filtering (the torque and the sign column low-passed like
# the differentiated position) Coulomb friction is no longer biased low (it was: 76 % of its
# excess removed, an open case until the axis models filtered both sides alike)


def _single_cases():
    out = []
    for noise in (1.0, 3.0):
        for c in CASES:
            marks = [pytest.mark.slow] if noise == 3.0 else []
            out.append(pytest.param(*c, noise, marks=marks))
    return out


@pytest.mark.parametrize("model,kw,effect,channel,param,truth,noise", _single_cases())
def test_single_effect_found(model, kw, effect, channel, param, truth, noise):
    seed = 2
    gen = rigid_axis_record if model == "rigid_axis" else flexible_joint_record
    rec = gen(seed=seed, noise=noise, **kw)
    keys = RIG if model == "rigid_axis" else FLX
    sel = _run(rec, keys, model, extra={"ext": rec["ext"]} if "ext_gain" in kw else None)
    assert sel.steps, "no finding"
    first = sel.steps[0]
    eff = first.candidate.effect
    assert (eff.name, eff.channel) == (effect, channel)
    est = eff.parameters(first.candidate.fit.theta, sel.model)[param]
    assert est == pytest.approx(truth, rel=0.2)
    clean = _clean_rmse(model, noise, seed)
    for ch in first.error_before:
        excess = first.error_before[ch]["rmse"] - clean[ch]["rmse"]
        if excess > 0.05 * clean[ch]["rmse"]:   # channels the effect visibly disturbs
            removed = first.error_before[ch]["rmse"] - sel.final.equation_error()[ch]["rmse"]
            assert removed >= 0.8 * excess, (ch, removed, excess)
    assert first.evidence["p_value"] < 0.01


@pytest.mark.parametrize("noise", [1.0, 3.0])
@pytest.mark.parametrize("model", ["rigid_axis", "flexible_joint"])
def test_no_effect_no_finding(model, noise):
    rec = rigid_axis_record(seed=5, noise=noise) if model == "rigid_axis" else \
        flexible_joint_record(seed=5, noise=noise)
    sel = _run(rec, RIG if model == "rigid_axis" else FLX, model)
    assert sel.steps == []


def test_two_effects_both_found():
    rec = rigid_axis_record(seed=3, Fc=1.5, dFv_pos=3.0)
    sel = _run(rec, RIG, "rigid_axis")
    names = [s.candidate.effect.name for s in sel.steps]
    assert names[:2] == ["coulomb_friction", "asymmetric_friction"]
    p = sel.steps[1].candidate.effect.parameters(sel.final.theta, sel.model)
    # truth: Fv+ = 5 + 3, Fv- = 5; Coulomb with the 0.5 N offset: Fc+ = 2.0, Fc- = 1.0
    assert p["Fv_pos"] == pytest.approx(8.0, rel=0.2)
    assert p["Fv_neg"] == pytest.approx(5.0, rel=0.2)
    assert p["Fc_pos"] == pytest.approx(2.0, rel=0.2)
    assert p["Fc_neg"] == pytest.approx(1.0, rel=0.2)


@pytest.mark.parametrize("noise", [1.0, pytest.param(3.0, marks=[pytest.mark.slow])])
def test_coulomb_and_delay_both_found(noise):
    # Coulomb 1.5 N + a 30 ms command delay on the rigid axis: exactly those two, each within
    # 20 % of the generator's values
    rec = rigid_axis_record(seed=2, noise=noise, Fc=1.5, delay=0.03)
    sel = _run(rec, RIG, "rigid_axis")
    keys = {s.candidate.effect.key: s.candidate.effect for s in sel.steps}
    assert set(keys) == {"coulomb_friction@tau", "actuator_delay@tau"}, list(keys)
    assert sel.removed == []
    assert keys["actuator_delay@tau"].delay == pytest.approx(0.03, rel=0.2)
    fc = keys["coulomb_friction@tau"].parameters(sel.final.theta, sel.model)["Fc"]
    assert fc == pytest.approx(1.5, rel=0.2)


def test_periodic_disturbance_is_unexplained():
    rec = rigid_axis_record(seed=4, periodic=(1.0, 7.0))
    sel = _run(rec, RIG, "rigid_axis")
    assert sel.steps == []
    assert sel.unexplained
    # Welch with 0.25 s segments: 4 Hz bins, so 7 Hz shows within one bin
    assert abs(sel.unexplained[0]["frequency_hz"] - 7.0) <= 4.0
