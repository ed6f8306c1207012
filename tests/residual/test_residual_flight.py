"""Effects nobody declared, hidden in flights simulated by cdam_core.sim (issue 5).

Each flight: experiment "both", 10 s, the sidecar declares only arm_coupling (always present in
the simulator); the declared model is aerial_manipulator with the weighed mass m fixed. The
truth is the simulator's effect parameters; the excess error of an effect is the declared
model's equation error on the record minus its error on the same record simulated with the
same seed and no effect.
"""
from functools import lru_cache

import numpy as np
import pytest

from cdam_core.residual import analyse
from cdam_core.models.greybox.registry import get_model
from cdam_core.sim import simulate_flight
from cdam_core.sim.parameters import plant_vector, plant_dict, total_mass

MASS = total_mass(plant_dict(plant_vector()), with_payload=False)   # weighed, without payload
SIGNALS = get_model("aerial_manipulator").signals


def _record(effects, seed, noise, periodic=None):
    ds = simulate_flight("both", duration=10.0, seed=seed, effects=list(effects),
                         noise_scale=noise, declare=("arm_coupling",))
    sig = {k: ds.column(k).copy() for k in SIGNALS}
    if periodic is not None:   # a force outside the library, added to the logged thrust
        amp, f = periodic
        sig["T"] = sig["T"] + amp * np.sin(2 * np.pi * f * ds.t)
    return ds.t, sig


@lru_cache(maxsize=None)
def _analyse(effects: tuple, seed: int = 1, noise: float = 1.0, periodic=None):
    t, sig = _record(effects, seed, noise, periodic)
    return analyse("aerial_manipulator", t, sig, fixed={"m": MASS}, free_run=False,
                   declared=("arm_coupling",))


# effect spec, [(effect, channel, parameter, truth)]: truths are the simulator's defaults
CASES = {
    "thrust_loss": [("thrust_loss", "Z", "c", 0.003)],
    "ground_effect": [("ground_effect", "Z", "k", 1.0)],
    "payload_mass": [("payload_mass", "Z", "mass", 0.10)],
    "backlash": [("backlash", "tau_l1", "width", 0.02), ("backlash", "tau_l2", "width", 0.02)],
    "coulomb_friction": [("coulomb_friction", "tau_m1", "Fc", 0.03),
                         ("coulomb_friction", "tau_m2", "Fc", 0.02)],
    "hardening_stiffness": [("hardening_stiffness", "tau_l1", "K3", 5000.0),
                            ("hardening_stiffness", "tau_l2", "K3", 5000.0)],
    # both joints' commands late by 20 ms: the delay is found on each motor equation
    "actuator_delay:joint=0.02": [("actuator_delay", "tau_m1", "delay", 0.02),
                                  ("actuator_delay", "tau_m2", "delay", 0.02)],
}


def _check_found(spec, noise, seed=1):
    sel = _analyse((spec,), seed, noise)
    clean = _analyse((), seed, noise).declared_error
    found = {(s.candidate.effect.name, s.candidate.effect.channel): s for s in sel.steps}
    expected = CASES[spec]
    assert set(found) == {(e, c) for e, c, _, _ in expected}, list(found)
    final = sel.final.equation_error()
    for eff, ch, par, truth in expected:
        st = found[(eff, ch)]
        est = st.candidate.effect.parameters(sel.final.theta, sel.model)[par]
        assert est == pytest.approx(truth, rel=0.2), (eff, ch, est)
        assert st.evidence["p_value"] < 0.01
        before = sel.declared_error[ch]["rmse"]
        excess = before - clean[ch]["rmse"]
        if excess > 0.05 * clean[ch]["rmse"]:   # where noise dominates, the test decides
            assert before - final[ch]["rmse"] >= 0.8 * excess, (ch, before, final[ch], excess)


def test_thrust_loss_found():
    _check_found("thrust_loss", 1.0)


def test_no_effect_no_finding():
    sel = _analyse(())
    assert sel.steps == [] and sel.removed == []


@pytest.mark.slow
@pytest.mark.parametrize("spec", ["ground_effect", "payload_mass", "backlash",
                                  "coulomb_friction"])
def test_single_effect_found(spec):
    _check_found(spec, 1.0)


# open: with decisions on held-out equation error, at three times the noise the ground effect
# is not kept and the hardening cable is kept on joint 1 only (its held-out gain on joint 2 is
# not significant after Bonferroni)
HELD_OUT_AT_3X = pytest.mark.xfail(strict=True, reason="[greybox] held-out decision at 3x noise "
                                   "on the flight model: open")


@pytest.mark.slow
@pytest.mark.parametrize("spec", ["thrust_loss",
                                  pytest.param("ground_effect", marks=HELD_OUT_AT_3X),
                                  "payload_mass",
                                  pytest.param("hardening_stiffness", marks=HELD_OUT_AT_3X),
                                  "actuator_delay:joint=0.02", "coulomb_friction"])
def test_single_effect_found_at_three_times_the_noise(spec):
    _check_found(spec, 3.0)


def test_hardening_stiffness_found():
    # the cable parameters come from the motor equations (the link equations are
    # errors-in-variables equations): K3 within 20 % on both joints, Ks unbiased
    _check_found("hardening_stiffness", 1.0)
    theta = _analyse(("hardening_stiffness",), 1, 1.0).final.theta
    assert theta["Ks1"] == pytest.approx(20.0, rel=0.03)   # simulator defaults (parameters.py)
    assert theta["Ks2"] == pytest.approx(15.0, rel=0.03)


@pytest.mark.slow
def test_declared_cable_stiffness_unbiased_without_noise():
    # zero noise, no effect: the motor equations give the simulator's Ks, Im (parameters.py)
    sel = _analyse((), 1, 0.0)
    th = sel.declared.theta
    # on this record the held-out windows simulate: --estimator auto tries IDIM-IV only on a
    # flight model (output error over every body and arm parameter took 15 min here)
    assert list(sel.settings["estimator"].get("validation", {})) in ([], ["IDIM-IV"])
    assert th["Ks1"] == pytest.approx(20.0, rel=0.01)
    assert th["Ks2"] == pytest.approx(15.0, rel=0.01)
    assert th["Im1"] == pytest.approx(1e-3, rel=0.05)


ROTOR = {"T", "tau_phi", "tau_theta", "tau_psi"}


@pytest.mark.slow
@pytest.mark.parametrize("noise", [1.0, 3.0])
def test_rotor_delay_found_on_the_moment_equations(noise):
    # A 20 ms delay of all four rotor commands: one shared delay (channel "rotors"), searched
    # jointly on T's equations and the three moments, is the only claim, within 20 %, and it
    # removes >= 80 % of the excess error over the rotor equations (excess per equation
    # relative to its clean error, summed), and >= 80 % on each equation with a real excess
    # (> 5 % of its clean error) except yaw. Yaw keeps part of its excess at the true delay
    # (measured 61 % / 53 % removed at 1x / 3x): on the clean record the yaw equation alone
    # already prefers a ~20 ms shift (an unmodelled rotor lag the 0.5 Hz yaw loop cannot
    # separate from Jz and Kpsi), which is why yaw alone used to claim ~43 ms; it must still
    # improve.
    spec = "actuator_delay:joint=0,rotor=0.02"
    sel = _analyse((spec,), 1, noise)
    clean = _analyse((), 1, noise).declared_error
    final = sel.final.equation_error()
    found = [(s.candidate.effect.name, s.candidate.effect.channel) for s in sel.steps]
    assert found == [("actuator_delay", "rotors")] and sel.removed == [], found
    eff = sel.steps[0].candidate.effect
    assert set(eff.commands) == ROTOR
    assert eff.parameters(sel.final.theta, sel.model)["delay"] == pytest.approx(0.02, rel=0.2)
    assert sel.steps[0].evidence["p_value"] < 0.01
    excess_sum = removed_sum = 0.0
    for ch in ("X", "Y", "Z", "tau_phi", "tau_theta", "tau_psi"):   # T enters X, Y, Z
        before, after, ref = (sel.declared_error[ch]["rmse"], final[ch]["rmse"],
                              clean[ch]["rmse"])
        excess = before - ref
        if excess <= 0.05 * ref:   # noise dominates: the significance test decided
            continue
        excess_sum += excess / ref
        removed_sum += (before - after) / ref
        if ch == "tau_psi":
            assert after < before, (ch, before, after)
        else:
            assert before - after >= 0.8 * excess, (ch, before, after, excess)
    assert removed_sum >= 0.8 * excess_sum, (removed_sum, excess_sum)


@pytest.mark.slow
def test_no_effect_no_finding_at_three_times_the_noise():
    assert _analyse((), 1, 3.0).steps == []


@pytest.mark.slow
def test_two_effects_both_found():
    sel = _analyse(("thrust_loss", "backlash:width1=0.03,width2=0"), 2)
    keys = {(s.candidate.effect.name, s.candidate.effect.channel) for s in sel.steps}
    assert keys == {("thrust_loss", "Z"), ("backlash", "tau_l1")}


@pytest.mark.slow
def test_periodic_force_is_unexplained():
    # 0.4 N at 0.7 Hz on the thrust: no library effect makes a sinusoid
    sel = _analyse((), 1, 1.0, (0.4, 0.7))
    assert sel.steps == []
    z = [u for u in sel.unexplained if u["channel"] == "Z"]
    assert z and abs(z[0]["frequency_hz"] - 0.7) <= 0.3, sel.unexplained
    # the same flight without the force shows no such structure on Z
    assert not [u for u in _analyse(()).unexplained if u["channel"] == "Z"]


def test_network_path_names_the_effect_held_out_and_the_error_drops():
    """The network path decides on held-out blocks (residual/network.py): the 10 s flight
    holds 8 units of windows spanning the motion's correlation time (731 samples), too short
    to decide; on a 30 s flight the thrust loss is found (measured p 3.1e-4 on 15 units, level
    0.01 / 3; equation RMSE 1.51 -> 0.047), and without the effect nothing is claimed."""
    from cdam_core.models.greybox.effects import candidates
    from cdam_core.residual.network import network_residual
    m = get_model("aerial_manipulator", fixed={"m": MASS})
    cands = candidates(m)
    for effects in (["thrust_loss:c=0.01"], []):
        ds = simulate_flight("both", duration=30.0, seed=4, effects=effects, noise_scale=1.0,
                             declare=("arm_coupling",))
        s = m.prepare(ds.t, {k: ds.column(k).copy() for k in SIGNALS})
        out = network_residual(m, s, "Z",
                               declared_effects=[e for e in cands if e.key == "arm_coupling@Z"],
                               candidates=[e for e in cands if e.channel in ("Z", "T")])
        if not effects:
            assert out["winner"] is None
            continue
        assert out["winner"] == "thrust_loss"
        v = out["evidence"]["validation"]
        assert v["better"] and v["p_value"] < 0.01 / 3 and v["structures_tried"] == 3
        assert out["error_after"]["rmse"] < 0.5 * out["error_before"]["rmse"]
