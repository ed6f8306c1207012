"""The residual loop on records it was not written against ([greybox] item 7).

Records from ``joint_generator`` (plain numpy, its own RK4, not ``cdam_core.sim``): joints in a
horizontal and a vertical plane, open-loop torque and PD loops closed on the measured motor or
link angle, coarse and noisy encoders, 250 Hz to 1 kHz. Truths are the generator's parameters;
the 5 % bound on the well-excited parameters is the issue's. Figures measured when written
(relative errors): A Im +0.4 %, Dm -0.5 %, Ks 0.0 %, I 0.0 %, Dl 0.0 %; B (vertical, motor PD,
500 Hz, 4096-count link encoder) Im -2.1 %, Dm -3.3 %, Ks -0.4 %, I +4.3 %, Dl -0.5 %, G +9 %;
C (link PD, 250 Hz, dry friction) Im +2.3 %, Ks -0.2 %, I +1.4 %, Dl -0.2 %, Dm +7.5 %, Fc -15 %.
With parallel filtering (the torque and the friction's sign column low-passed like the
differentiated positions): B Im -1.8 %, Dm -3.9 %, I +2.9 %, G +6.1 %; C Dm -4.5 %, Fc -0.2 %.
"""
import re
from functools import lru_cache

import numpy as np
import pytest

from cdam_core.residual.analyse import analyse
from cdam_core.residual.cutoff import noise_cutoff
from cdam_core.residual.validation import motion_horizon

from joint_generator import TRUTH, Joint, rigid_axis

CONDITIONS = {
    "horizontal_open_1k": Joint(),
    "vertical_motor_pd_500_coarse_link": Joint(fs=500, plane="vertical", control="motor",
                                               link_counts=4096, link_noise=2e-4,
                                               motor_counts=16384),
    "horizontal_link_pd_250_dry_friction": Joint(fs=250, control="link", Fc=0.05,
                                                 motor_counts=16384, link_counts=16384),
    "horizontal_open_1k_hardening": Joint(K3=400.0),
    # 2.35 Hz: more than the Hann main lobe (2 bins of 0.2 Hz) from every excitation line
    "vertical_open_1k_periodic": Joint(plane="vertical", periodic=(0.05, 2.35)),
    # the torque a continuous signal sampled at each instant (a measured current), no hold
    "horizontal_open_1k_continuous": Joint(hold=False),
    # a hardening cable under motor PD, seen through a 4096-count noisy link encoder
    "horizontal_motor_pd_500_coarse_link_hardening": Joint(K3=400.0, fs=500, control="motor",
                                                           link_counts=4096, link_noise=2e-4,
                                                           motor_counts=16384),
    # the link under PD at 250 Hz with a disturbance at 3.7 Hz (0.6 Hz from the nearest
    # excitation line): the link's derivative cut-off gives 1.4 Hz Welch bins to the peak search
    "vertical_link_pd_250_periodic": Joint(fs=250, control="link", plane="vertical",
                                           periodic=(0.05, 3.7), motor_counts=16384,
                                           link_counts=16384),
    # parameters of their own (the cable resonance near 22.7 Hz), a PD loop on the motor at
    # 250 Hz tracking a logarithmic chirp to 6.5 Hz: held-out equation errors that cannot tell
    # the zero-order hold from a sampled input (one-sided p 0.037 / 0.96, measured)
    "horizontal_motor_pd_250_chirp": Joint(
        fs=250, control="motor", excitation=("chirp", 6.5), gains=(5.3, 0.83), Fc=0.15,
        params=dict(Im=0.009, Dm=0.029, Ks=158.0, Kd=0.125, I=0.056, Dl=0.052),
        motor_counts=16384, link_counts=262144),
    # a joint far stiffer than the encoders resolve, the link encoder latched 2 ms early
    "rigid_joint_with_skew": Joint(params={**TRUTH, "Ks": 1e5}, skew=0.002, motor_counts=16384,
                                   link_counts=16384),
}
# the vertical joint read from zeros that are not the model's (the generator's zero,
# motor_zero, tau_bias): under motor PD at 500 Hz, and in open loop at 1 kHz
_ZEROS = dict(fs=500, plane="vertical", control="motor", link_counts=16384, motor_counts=16384)
CONDITIONS.update({
    "zero_0.3_off_hanging": Joint(zero=0.3, **_ZEROS),
    "zero_at_the_horizontal": Joint(zero=np.pi / 2, **_ZEROS),
    "torque_offset_0.05": Joint(tau_bias=0.05, **_ZEROS),
    "motor_zero_0.01_off_the_links": Joint(motor_zero=0.01, **_ZEROS),
    "open_loop_zero_0.5_off_hanging": Joint(**{**_ZEROS, "control": "open", "fs": 1000},
                                            zero=0.5),
    "coarse_link_motor_zero_0.01": Joint(motor_zero=0.01, **{**_ZEROS, "link_counts": 4096},
                                         link_noise=2e-4),
})
WELL_EXCITED = ("Im", "Ks", "I", "Dl")


@lru_cache(maxsize=None)
def _record(name):
    return CONDITIONS[name].record()


@lru_cache(maxsize=None)
def _run(name, estimator="idim-ls"):
    """The loop on a condition; IDIM-LS pinned (the structure, timing and IDIM tests; the
    estimator choice has its own test: output error costs 2-14 s of CPU per record)."""
    r = _record(name)
    sel = analyse("flexible_joint", r["t"], {k: r[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False, estimator=estimator)
    return r, sel


def _found(sel):
    return {(s.candidate.effect.name, s.candidate.effect.channel) for s in sel.steps}


@pytest.mark.parametrize("name", ["horizontal_open_1k", "vertical_motor_pd_500_coarse_link",
                                  "horizontal_link_pd_250_dry_friction",
                                  "horizontal_open_1k_continuous"])
def test_well_excited_parameters_within_5_percent(name):
    r, sel = _run(name)
    for p in WELL_EXCITED + (("Dm",) if "friction" not in name else ()):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.05), p


def test_dry_friction_under_link_control_within_5_percent():
    r, sel = _run("horizontal_link_pd_250_dry_friction")
    eff = next(s.candidate.effect for s in sel.steps if s.candidate.effect.name == "coulomb_friction")
    assert eff.parameters(sel.final.theta, sel.final.model)["Fc"] == pytest.approx(0.05, rel=0.05)
    assert sel.final.theta["Dm"] == pytest.approx(r["truth"]["Dm"], rel=0.05)


def test_input_timing_chosen_from_the_record():
    """The generator holds the torque over each sample (a DAC) except in the continuous
    condition: held-out equation error must tell them apart, and the half-sample correction
    must remove the motor damping's timing bias (-3.9 % under sampled timing on the motor-PD
    record at 500 Hz, measured; +0.7 % with the hold)."""
    for name in ("horizontal_open_1k", "vertical_motor_pd_500_coarse_link",
                 "horizontal_link_pd_250_dry_friction"):
        tm = _run(name)[1].settings["timing"]
        assert tm["chosen"] == "held" and tm["p_value"] < 0.01, (name, tm)
    tm = _run("horizontal_open_1k_continuous")[1].settings["timing"]
    assert tm["chosen"] == "sampled" and tm["p_value"] > 0.01, tm
    assert tm["decided"] and tm["p_value_sampled"] < 0.005, tm   # measured 1.8e-12
    r, sel = _run("vertical_motor_pd_500_coarse_link")
    assert sel.final.theta["Dm"] == pytest.approx(r["truth"]["Dm"], rel=0.02)


def test_timing_the_record_cannot_tell_stays_the_documented_hold():
    """Where the held-out equations do not decide (each one-sided p above alpha / 2), the
    zero-order hold the issue documents stays. The rule before (undecided: "sampled") gave on
    this record Kd +141 %, Dl -21 %, Dm -18 %, Im +5.6 % (measured); with the hold every
    parameter within 3.1 %."""
    r, sel = _run("horizontal_motor_pd_250_chirp")
    tm = sel.settings["timing"]
    assert tm["chosen"] == "held" and not tm["decided"], tm
    assert min(tm["p_value"], tm["p_value_sampled"]) >= 0.005, tm
    for p in WELL_EXCITED + ("Dm", "Kd"):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.05), p


@pytest.mark.parametrize("name", ["horizontal_open_1k", "vertical_motor_pd_500_coarse_link"])
def test_no_finding_without_an_effect(name):
    assert _found(_run(name)[1]) == set()


def test_gravity_enters_only_in_a_vertical_plane():
    dropped = {n: [d["term"] for d in _run(n)[1].settings["declared_terms_dropped"]]
               for n in ("horizontal_open_1k", "vertical_motor_pd_500_coarse_link")}
    assert "G" in dropped["horizontal_open_1k"]
    assert "G" not in dropped["vertical_motor_pd_500_coarse_link"]
    r, sel = _run("vertical_motor_pd_500_coarse_link")
    assert sel.final.theta["G"] == pytest.approx(r["truth"]["G"], rel=0.15)
    assert _run("horizontal_open_1k")[1].final.theta["G"] == 0.0


def test_hidden_effects_named_on_the_right_equation():
    assert ("coulomb_friction", "tau_m") in _found(_run("horizontal_link_pd_250_dry_friction")[1])
    sel = _run("horizontal_open_1k_hardening")[1]
    assert _found(sel) == {("hardening_stiffness", "tau_l")}
    eff = sel.steps[0].candidate.effect
    assert eff.parameters(sel.final.theta, sel.final.model)["K3"] == pytest.approx(400.0, rel=0.05)


def test_periodic_disturbance_reported_with_its_frequency():
    r, sel = _run("vertical_open_1k_periodic")
    assert _found(sel) == set()
    lines = [u for u in sel.unexplained if u["kind"] == "periodic_line" and u["channel"] == "tau_l"]
    assert lines and abs(lines[0]["frequency_hz"] - 2.35) <= 0.2, sel.unexplained
    assert lines[0]["amplitude"] == pytest.approx(0.05, rel=0.2)
    # the model's terms driven by the torque alone hold nearly nothing at 2.35 Hz: almost all
    # of the line is left unexplained (measured: 0.047 N m of 0.05)
    assert lines[0]["attribution"]["unexplained_amplitude"] == pytest.approx(0.05, rel=0.2)
    # and it is the only finding: the residual's lines at the excitation frequencies are the
    # model's (measured: 7 of them, each within what the input-driven terms produce)
    assert len(sel.unexplained) == 1, sel.unexplained
    assert sel.settings["residual_structure_explained_by_the_model"]["explained"]


def test_hardening_cable_screened_on_the_clean_equation():
    """Under motor PD the cable deflects 20 mrad RMS, so its cubic term is 1 % of the cable
    torque; the link equation is mostly the 4096-count encoder's differentiated noise. The
    screen's F-test pooled both equations (p 0.053: never tried on held-out windows, seeds 0-2,
    Ks +1 % absorbing it); per equation the motor's says p 4e-22 and the held-out windows then
    keep it (p < 1e-5). K3 itself (not among the issue's well-excited parameters) comes out
    -18 % by IDIM-LS, pinned here, on this seed; by the default estimator (output error)
    +2.9 / +1.6 / -0.2 % on seeds 0-2."""
    r, sel = _run("horizontal_motor_pd_500_coarse_link_hardening")
    assert _found(sel) == {("hardening_stiffness", "tau_l")}
    for p in WELL_EXCITED + ("Dm",):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.05), p


def test_a_disturbance_is_one_finding_not_a_line_and_a_peak():
    """Under link PD at 250 Hz the peak search's segments (0.7 s: 1.4 Hz bins) show the 3.7 Hz
    line as a spectral peak at 4.39 Hz, which was reported as a second unexplained finding
    (seeds 0-2, before). With the line's sinusoid taken out the peak is gone: it is reported on
    the line, and the disturbance is one finding at its frequency (measured 3.701 Hz)."""
    r, sel = _run("vertical_link_pd_250_periodic")
    assert len(sel.unexplained) == 1, sel.unexplained
    line = sel.unexplained[0]
    assert line["kind"] == "periodic_line" and line["channel"] == "tau_l"
    assert abs(line["frequency_hz"] - 3.7) <= 0.2
    assert line["amplitude"] == pytest.approx(0.05, rel=0.2)
    assert [abs(f - 3.7) < 1.5 for f in line["seen_as_spectral_peak_hz"]] == [True]
    assert _found(sel) == set()


@pytest.mark.parametrize("name", ["horizontal_open_1k", "vertical_motor_pd_500_coarse_link",
                                  "horizontal_link_pd_250_dry_friction",
                                  "horizontal_open_1k_hardening",
                                  "horizontal_open_1k_continuous"])
def test_no_unexplained_structure_without_a_disturbance(name):
    """Records without a disturbance: the residual's lines and peaks sit at the excitation
    frequencies (0.2..8 Hz) or, with the hardening cable, at their odd harmonics and
    intermodulation products; the fitted model driven by the torque alone produces each of them
    with coefficients within their own size. Before (the near-an-input-line rule, session 6):
    an 8 Hz peak on A, hardening and continuous, 0.22 Hz on B, 30 lines on H."""
    sel = _run(name)[1]
    assert sel.unexplained == [], sel.unexplained


def test_no_unexplained_line_from_a_noisy_link_encoder():
    """A noisy link encoder (1 mrad white noise, 1 kHz, open loop, no disturbance): below the
    link's derivative cut-off (8.8 Hz chosen here) the link equation's residual is mostly
    the twice-differentiated noise, rising as f^4. Against the plain lower quartile of the
    neighbouring bins that slope passed as a line at 4.62 Hz (seed 0; 4.83 Hz on seed 2, 6.02
    on seed 3 of the four tried), reported as an unexplained periodic disturbance; against the
    background detrended by its local power law, none (seed 3's 6.02 Hz line stays). The
    estimator by default, as users run it (about 15 s)."""
    r = Joint(fs=1000, motor_noise=5e-5, link_noise=1e-3, seed=0).record()
    sel = analyse("flexible_joint", r["t"], {k: r[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False)
    assert sel.unexplained == [], sel.unexplained
    assert _found(sel) == set()


# (condition, the generator's G sin(q + zero) as G sin q + Gc cos q, offset_m, offset_l): closed
# forms of the generator's settings (G 0.6 N m, Ks 40 N m/rad)
_ZERO_TRUTH = {
    "zero_0.3_off_hanging": (0.6 * np.cos(0.3), 0.6 * np.sin(0.3), 0.0, 0.0),
    "zero_at_the_horizontal": (0.0, 0.6, 0.0, 0.0),
    "torque_offset_0.05": (0.6, 0.0, 0.05, 0.0),
    "motor_zero_0.01_off_the_links": (0.6, 0.0, 40.0 * 0.01, -40.0 * 0.01),
    "open_loop_zero_0.5_off_hanging": (0.6 * np.cos(0.5), 0.6 * np.sin(0.5), 0.0, 0.0),
}


@pytest.mark.parametrize("name", list(_ZERO_TRUTH))
def test_encoder_zeros_and_torque_offset(name):
    """A measured joint's zeros are not the model's: the encoders' zero off the hanging
    position (0.3 rad; at the horizontal, as a simulator that measures from there; 0.5 rad in
    open loop), the motor encoder's zero 0.01 rad off the link's (a cable preload of
    Ks x 0.01 = 0.4 N m) and a torque sensor's offset of 0.05 N m; 16384-count encoders.
    Without the declared terms Gc cos q, offset_m and offset_l the parameters came out biased
    and nothing was reported (measured, defaults): Dm +6.3 %, Ks -2.8 %, I -3.2 % at 0.3 rad;
    I +65 %, Kd +96 %, Dl +40 % at the horizontal; Dm -4.1 %, Kd +6.3 % with the torque
    offset; Dm -24 %, Kd +28 %, Dl +10 % with the preload; Im -14 %, Dm +41 %, I -24 % in open
    loop. Each term the record holds is kept within 3 % of the generator's value (measured
    within 0.3 %), a term of 0 is dropped (no held-out gain), its physical reading derived
    (``derived``: the zero's angle, the encoders' offset, the torque offset) and the
    well-excited parameters are within 1 % (measured within 0.5 %, IDIM-LS). Expected values:
    closed forms of the generator's settings."""
    r, sel = _run(name)
    th, der = sel.final.theta, sel.model.derived(sel.final.theta)
    dropped = {d["term"] for d in sel.settings["declared_terms_dropped"]}
    for term, want in zip(("G", "Gc", "offset_m", "offset_l"), _ZERO_TRUTH[name]):
        if want == 0.0:
            assert term in dropped, (term, th.get(term))
        else:
            assert term not in dropped and th[term] == pytest.approx(want, rel=0.03), term
    for p in WELL_EXCITED:
        assert th[p] == pytest.approx(r["truth"][p], rel=0.01), p
    zero = CONDITIONS[name].zero
    if zero:
        assert der["gravity_zero_rad"] == pytest.approx(zero, abs=0.01)
        assert der["gravity_amplitude"] == pytest.approx(0.6, rel=0.02)
    if CONDITIONS[name].motor_zero:
        assert der["encoder_zero_offset_rad"] == pytest.approx(0.01, rel=0.03)
        assert abs(der["torque_offset"]) < 0.01
    if CONDITIONS[name].tau_bias:
        assert der["torque_offset"] == pytest.approx(0.05, rel=0.03)


def test_encoders_zeros_off_each_other_under_a_coarse_link_encoder():
    """The preload case through a 4096-count noisy link encoder, everything by default (the
    estimator chosen on held-out windows): without the terms Dm -4.8 %, Kd +34 %, G -5.0 %
    (measured); with them, the encoders' offset within 3 % (measured 0.0100 rad for 0.01) and
    the well-excited parameters within 1 % (measured within 0.3 %, output error chosen).
    Expected values: the generator's settings."""
    r, sel = _run("coarse_link_motor_zero_0.01", "auto")
    der = sel.model.derived(sel.final.theta)
    assert der["encoder_zero_offset_rad"] == pytest.approx(0.01, rel=0.03)
    assert abs(der["torque_offset"]) < 0.01
    for p in WELL_EXCITED + ("G",):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.01), p


def test_report_reads_the_zero_of_a_joint_measured_off_hanging(tmp_path):
    """``cdam residual`` on the joint whose encoders' zero is 0.3 rad off the hanging position,
    with a sidecar giving the units: the JSON's ``derived_parameters`` and the report's page
    give the zero's angle in rad and the gravity's amplitude in N m. Expected values: the
    generator's settings (0.3 rad, 0.6 N m)."""
    import json
    from cdam_core.cli.main import main
    r = _record("zero_0.3_off_hanging")
    np.savetxt(tmp_path / "j.csv", np.column_stack([r["t"], r["tau_m"], r["theta_m"], r["q"]]),
               delimiter=",", header="t,tau_m1,theta_m1,q1", comments="", fmt="%.10g")
    (tmp_path / "j.json").write_text(json.dumps(
        {"inputs": ["tau_m1"], "outputs": ["theta_m1", "q1"],
         "units": {"tau_m1": "N m", "theta_m1": "rad", "q1": "rad"}}))
    assert main(["residual", str(tmp_path / "j.csv"), "--model", "flexible_joint",
                 "--estimator", "idim-ls", "--no-free-run", "--quiet", "--json",
                 str(tmp_path / "r.json"), "--report", str(tmp_path / "rep")]) == 0
    der = json.loads((tmp_path / "r.json").read_text())["derived_parameters"]
    assert der["gravity_zero_rad"] == pytest.approx(0.3, abs=0.01)
    assert der["gravity_amplitude"] == pytest.approx(0.6, rel=0.02)
    md = (tmp_path / "rep" / "index.md").read_text()
    zero = re.search(r"gravity_zero_rad = ([-0-9.e]+) rad", md)
    amp = re.search(r"gravity_amplitude = ([-0-9.e]+) N m", md)
    assert zero and float(zero.group(1)) == pytest.approx(0.3, abs=0.01)
    assert amp and float(amp.group(1)) == pytest.approx(0.6, rel=0.02)


def test_coarse_encoder_gets_a_lower_cutoff():
    cut = _run("vertical_motor_pd_500_coarse_link")[1].settings["filter_choice"]["chosen_hz"]
    fine = _run("horizontal_open_1k")[1].settings["filter_choice"]["chosen_hz"]
    assert cut["q"] < cut["theta_m"] < 0.1 * fine["theta_m"]


def test_creep_error_against_the_true_quantisation_error():
    """An angle creeping through an encoder's counts (a slow sine, 20 to 40 samples per count):
    the grid is read from the record (16384 counts per revolution), and the quantisation error
    estimated from the record alone (cutoff.creep_error) follows the true one, the quantised
    minus the noise-free angle, to under 5 % of a count (RMS; the true error's RMS is 29 % of a
    count, a sawtooth). White noise added after the quantisation takes the record off its
    grid."""
    from cdam_core.residual.cutoff import creep_error, encoder_step
    t = np.arange(20000) / 1000.0
    res = 2 * np.pi / 16384
    x = 0.05 * np.sin(2 * np.pi * 0.03 * t) + 1.5e-4 * t
    xq = np.round(x / res) * res
    assert encoder_step(xq) == pytest.approx(res, rel=1e-9)
    assert encoder_step(xq + np.random.default_rng(0).normal(0, 1e-5, xq.size)) is None
    e = creep_error(xq, encoder_step(xq))
    true = xq - x
    inner = slice(2000, 18000)
    assert np.sqrt(np.mean(true[inner] ** 2)) > 0.25 * res
    assert np.sqrt(np.mean((e - true)[inner] ** 2)) < 0.05 * res


@pytest.mark.parametrize("ratio", [12.0, 7.0])
def test_noisy_grid_found_under_noise_smaller_than_the_step(ratio):
    """Counts read with white noise added after the quantisation (sigma a 12th and a 7th of the
    step; a slow sine creeping through 16384 counts per revolution): the grid is found under
    the noise, its step to 1e-4 and its offset (0 here) to 2 % of the step. Expected values:
    the grid the record was made on."""
    from cdam_core.residual.cutoff import noisy_grid
    t = np.arange(20000) / 1000.0
    res = 2 * np.pi / 16384
    x = 0.05 * np.sin(2 * np.pi * 0.03 * t) + 1.5e-4 * t
    xq = np.round(x / res) * res + np.random.default_rng(int(ratio)).normal(0, res / ratio, t.size)
    g = noisy_grid(xq)
    assert g is not None
    assert g["step"] == pytest.approx(res, rel=1e-4)
    assert abs(g["offset"]) < 0.02 * res
    assert g["noise_sigma"] == pytest.approx(res / ratio, rel=0.1)


@pytest.mark.parametrize("noise", [1e-5, 1e-4])
def test_no_noisy_grid_where_there_is_none(noise):
    """No grid is claimed on angles that were never quantised: a smooth creeping angle, an angle
    held at two positions for most of the record (their phases line up at some period), a
    staircase of 40 random rests; nor where the noise (half a step) dithers the counts."""
    from cdam_core.residual.cutoff import noisy_grid
    rng = np.random.default_rng(3)
    t = np.arange(20000) / 1000.0
    smooth = 0.05 * np.sin(2 * np.pi * 0.03 * t) + 1.5e-4 * t
    held = np.clip(0.3 * np.sin(2 * np.pi * 0.5 * t), -0.2, 0.2)
    stairs = np.convolve(np.repeat(np.cumsum(rng.uniform(-0.02, 0.02, 40)), 500),
                         np.ones(50) / 50, mode="same")
    for x in (smooth, held, stairs):
        assert noisy_grid(x + rng.normal(0, noise, t.size)) is None
    res = 2 * np.pi / 16384
    assert noisy_grid(np.round(smooth / res) * res + rng.normal(0, res / 2, t.size)) is None


def test_heavy_axis_read_with_noise_after_its_counts():
    """The heavy axis below with white noise (3e-5 rad, an eighth of a count) added after the
    quantisation. Off its grid the white rule alone chose 157 Hz (the creep's lines above the
    white level), M came out +90 %, Fv +870 % and the dry friction was not found. With the grid
    found under the noise (cutoff.noisy_grid), the cut-off is the one of the same record's
    noise-free counts (21 Hz) and, measured, M -1.0 %, Fc +0.6 %. Expected values: the
    generator's truth."""
    r = rigid_axis(M=2.0, Fv=1.0, Fc=2.0, counts=16384, noise=3e-5, seed=1)
    sel = analyse("rigid_axis", r["t"], {"tau": r["tau"], "q": r["q"]}, free_run=False)
    ev = sel.settings["filter_choice"]["signals"]["q"]
    assert ev["noisy_grid"]["step"] == pytest.approx(2 * np.pi / 16384, rel=1e-3)
    assert sel.settings["filter_choice"]["chosen_hz"]["q"] < 25.0
    assert ("coulomb_friction", "tau") in _found(sel)
    assert sel.final.theta["M"] == pytest.approx(2.0, rel=0.05)
    assert sel.final.theta["coulomb_friction@tau.Fc"] == pytest.approx(2.0, rel=0.05)


@lru_cache(maxsize=None)
def _heavy_axis(seed):
    """A heavy axis with large dry friction, 16384 counts at 1 kHz (independent generator)."""
    return rigid_axis(M=2.0, Fv=1.0, Fc=2.0, counts=16384, seed=seed)


@pytest.mark.parametrize("seed", [0, 2])
def test_heavy_axis_with_dry_friction_cutoff_from_its_counts(seed):
    """A heavy axis with large dry friction (M 2, Fv 1, Fc 2: a third of the record stuck),
    16384 counts at 1 kHz, everything by default. While it creeps, the encoder's quantisation is
    a sawtooth whose lines stood above the white level: cut-off 95 Hz on seed 0 (212 Hz on seed
    1), M at 5 % of the truth, no friction found, Fv +700 %. With the quantisation error
    estimated from the record's own counts (cutoff.creep_error) as the level: 7.3 / 21 / 7.8 Hz
    on seeds 0-2, and the Coulomb term found. Seed 2 found it only once the structures are
    compared by IDIM-LS fold fits as well (IDIM-IV's, chosen for the declared model, put the
    Coulomb structure's windows behind the viscous one's: selection.compare_structures).
    Measured: M +0.3 / +3.5 %, Fc -1.6 / -1.5 % (seeds 0 / 2); Fv +11 / +13 %, not asserted:
    the axis moves slowly (viscous force a tenth of the dry one) and Fv is weakly excited.
    Expected values: the generator's truth."""
    r = _heavy_axis(seed)
    sel = analyse("rigid_axis", r["t"], {"tau": r["tau"], "q": r["q"]}, free_run=False)
    assert sel.settings["filter_choice"]["chosen_hz"]["q"] < 25.0
    assert ("coulomb_friction", "tau") in _found(sel)
    assert sel.final.theta["M"] == pytest.approx(2.0, rel=0.05)
    assert sel.final.theta["coulomb_friction@tau.Fc"] == pytest.approx(2.0, rel=0.05)


def test_noise_cutoff_against_a_known_spectrum():
    """Sines up to 20 Hz under white noise: the cut-off keeps the 20 Hz line and stops within
    the Hann window's leakage of it (a few 0.49 Hz bins for a line 10^5 above the noise)."""
    fs, n = 1000.0, 20000
    t = np.arange(n) / fs
    x = sum(np.sin(2 * np.pi * f * t) / f ** 2 for f in (1.0, 4.0, 9.0, 20.0))
    x = x + np.random.default_rng(0).normal(0, 1e-4, n)
    fc, ev = noise_cutoff(x, fs)
    assert 20.0 <= fc <= 21.5
    # the noise level is the white noise's one-sided density 2 sigma^2 / fs
    assert ev["noise_level"] == pytest.approx(2 * 1e-8 / fs, rel=0.2)


def test_motion_horizon_of_a_sine():
    """The autocorrelation of a sine's velocity is cos(2 pi f tau): it falls below 1/e at
    tau = arccos(1/e) / (2 pi f)."""
    fs, f = 1000.0, 1.3
    t = np.arange(200000) / fs
    v = np.cos(2 * np.pi * f * t)
    h = motion_horizon({"x_d": v}, ["x"])
    assert h / fs == pytest.approx(np.arccos(1 / np.e) / (2 * np.pi * f), rel=0.01)


def test_rigid_axis_with_a_coarse_encoder():
    r = rigid_axis(fs=500.0, counts=8192, noise=1e-4, Fc=1.0)
    sel = analyse("rigid_axis", r["t"], {"tau": r["tau"], "q": r["q"]}, free_run=False)
    assert ("coulomb_friction", "tau") in _found(sel)
    for p in ("M", "Fv"):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.05), p
    fc = sel.final.theta["coulomb_friction@tau.Fc"]
    assert fc == pytest.approx(1.0, rel=0.05)


def test_skewed_encoders_on_a_rigid_joint_fall_back_to_the_motor_axis():
    """The motor-minus-link angle of a rigid joint with a 2 ms encoder skew is velocity times
    the skew, not a deflection: the flexible model is declared not identifiable and the motor
    side is identified as a rigid axis (inertia Im + I: the link rides on the motor)."""
    r, sel = _run("rigid_joint_with_skew")
    idf = sel.settings["identifiability"]
    assert idf["identifiable"] is False and idf["fallback"].startswith("rigid_axis")
    assert idf["velocity_coefficient_s"] == pytest.approx(0.002, rel=0.1)
    assert sel.model.name == "rigid_axis"
    assert sel.final.theta["M"] == pytest.approx(TRUTH["Im"] + TRUTH["I"], rel=0.05)
    for name in ("horizontal_open_1k", "vertical_motor_pd_500_coarse_link"):
        assert _run(name)[1].settings["identifiability"]["identifiable"] is True


def test_a_term_the_sidecar_declares_is_kept(tmp_path):
    """Gravity on a horizontal joint is dropped by the data, but kept (estimated near 0) when
    the record's sidecar declares it; the sidecar's `model.terms` reaches `cdam residual`."""
    import json

    from cdam_core.cli.main import main
    r = _record("horizontal_open_1k")
    path = tmp_path / "joint.csv"
    np.savetxt(path, np.column_stack([r["t"], r["tau_m"], r["theta_m"], r["q"]]), delimiter=",",
               header="t,tau_m1,theta_m1,q1", comments="", fmt="%.12g")
    (tmp_path / "joint.json").write_text(json.dumps({"model": {"terms": ["G"]}}))
    out = tmp_path / "r.json"
    assert main(["residual", str(path), "--model", "flexible_joint", "--no-free-run",
                 "--estimator", "idim-ls", "--json", str(out), "--quiet"]) == 0
    js = json.loads(out.read_text())
    assert "G" not in [d["term"] for d in js["settings"]["declared_terms_dropped"]]
    assert abs(js["final_parameters"]["G"]) < 0.01   # N m; the vertical joints' G is 0.6
    assert "G" in [d["term"] for d in _run("horizontal_open_1k")[1].settings["declared_terms_dropped"]]


def test_iv_corrects_least_squares_under_a_too_high_cutoff():
    """[greybox] item 2: with the derivative cut-off forced far above the noise floor (60 Hz at
    250 Hz sampling, a quantised link under PD control), IDIM-LS is biased by the noise in its
    regressors (measured: I -43 %, Ks -24 %); IDIM-IV, with instruments from the simulated
    auxiliary model, predicts the held-out windows better, is chosen, and lands within 5 %
    (measured: Im +3.7 %, Ks -0.1 %, I +0.1 %, Dl +2.4 %; with RK4 windows Im +1.6 %, Ks -0.1 %,
    I -0.1 %, Dl +2.8 %; with IDIM-IV's own windows by RK4 too, session 8: Im +2.1 %,
    Ks -0.2 %, I +0.2 %, Dl +2.7 %). Output error predicts them better than IDIM-LS too, but
    not better than IDIM-IV (measured p 0.11; p 0.052 with output error on every window
    sample), so IDIM-IV is kept. The structure is the declared one (``max_steps=0``): the
    estimators are compared on the same model (the search finds the motor's dry friction since
    the screen tests each equation apart: the next test)."""
    r = _record("horizontal_link_pd_250_dry_friction")
    sel = analyse("flexible_joint", r["t"], {k: r[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False, cutoff_hz=60.0, max_steps=0)
    est = sel.settings["estimator"]
    assert est["chosen"] == "IDIM-IV", est
    assert est["validation"]["IDIM-IV"]["better"]
    assert not est["oe_against_iv"]["better"]
    ls = est["idim"]
    assert abs(ls["I"] / r["truth"]["I"] - 1) > 0.15     # the bias IV removes
    for p in ("Im", "Ks", "I", "Dl"):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.05), p
    assert est["iv"]["converged"]


def test_dry_friction_found_under_a_too_high_cutoff():
    """The same record and cut-off with the effect search: the motor's dry friction (0.05 N m)
    was not found (the screen's F-test pooled the motor equation with the link's, noise at a
    60 Hz cut-off: nothing tried on held-out windows; Dm +90 % took the friction); tested per
    equation it is screened, kept on held-out windows, and every parameter lands within 5 %
    (measured: Fc -0.14 %, Dm +0.2 %, the others within 0.03 %, output error chosen)."""
    r = _record("horizontal_link_pd_250_dry_friction")
    sel = analyse("flexible_joint", r["t"], {k: r[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False, cutoff_hz=60.0)
    assert _found(sel) == {("coulomb_friction", "tau_m")}
    assert sel.final.theta["coulomb_friction@tau_m.Fc"] == pytest.approx(0.05, rel=0.05)
    for p in WELL_EXCITED + ("Dm",):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.05), p


def test_output_error_chosen_where_least_squares_is_biased():
    """[greybox] item 2, the estimator chosen by default: a motor-PD record at 500 Hz with a
    2048-count noisy link encoder. IDIM-LS is biased by the noise of the twice-differentiated
    link angle (measured: Im -3.4 %, I +1.8 %); the output-error refinement (multiple shooting
    from the measured state, RK4 windows) predicts held-out windows better (measured p 2.6e-12
    at level 0.005), IDIM-IV does not (p 1.0), and output error is chosen: Im -0.02 %,
    Ks -0.05 %, I +0.01 %, Dm -0.4 %, Dl +0.25 %, Kd +0.5 % (IDIM-LS's +4.6 %; session 7's
    output error, one residual per window, stopped at Kd +4.3 %, Dm +0.6 %)."""
    r = Joint(fs=500, control="motor", link_counts=2048, link_noise=2e-4,
              motor_counts=16384).record()
    sel = analyse("flexible_joint", r["t"], {k: r[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False)
    est = sel.settings["estimator"]
    assert est["chosen"] == "output error (multiple shooting)", est
    oe = est["validation"]["output error (multiple shooting)"]
    assert oe["better"] and oe["p_value"] < oe["level"] and oe["structures_tried"] == 2
    assert not est["validation"]["IDIM-IV"]["better"]
    assert abs(est["idim"]["Im"] / r["truth"]["Im"] - 1) > 0.02   # the bias it removes
    for p in ("Im", "Ks", "I", "Dm", "Dl"):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.01), p


@pytest.mark.parametrize("Fc, seed", [(2.0, 0), (2.0, 2), (3.0, 2), (3.0, 3)])
def test_rigid_axis_with_long_stops(Fc, seed):
    """Coulomb friction Fc 2 and 3 against a multisine torque whose swings stay below it much
    of the time: the axis sticks for long stretches (checked on the generator's noise-free
    angle). Seed 0 lost Coulomb in the in-sample screen (every row compared, the rows at rest
    too), seed 2 in the cut-off (one chance spectral bin at 168 Hz); with the rows beside a stop
    in the fit, Fv came out 10-18 % high. At Fc 3 (more than half the record stuck) the sign of
    the velocity noise at rest, low-passed into the rows kept beside the stops, gave Fv +7.6 %
    (seed 2; seed 3 +3.1 %); with the sign 0 at rest (effects.CoulombFriction.regressors) -0.9 %
    and +2.9 %. Expected values: the generator's truth."""
    r = rigid_axis(fs=500.0, counts=8192, noise=1e-4, Fc=Fc, seed=seed)
    clean = rigid_axis(fs=500.0, Fc=Fc, seed=seed)["q"]
    stuck = np.abs(np.diff(clean)) * 500.0 < 1e-3       # below the tanh's 1 mrad/s
    edge = np.diff(np.r_[0, stuck.astype(int), 0])
    longest = np.max(np.flatnonzero(edge == -1) - np.flatnonzero(edge == 1)) / 500.0
    assert stuck.mean() > 0.2 and longest > 0.4         # stops of 0.4-0.55 s, a fifth or more
    sel = analyse("rigid_axis", r["t"], {"tau": r["tau"], "q": r["q"]}, free_run=False)
    assert ("coulomb_friction", "tau") in _found(sel)
    for p in ("M", "Fv"):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.05), p
    assert sel.final.theta["coulomb_friction@tau.Fc"] == pytest.approx(Fc, rel=0.05)


def test_rows_at_rest_left_out_under_a_given_cutoff():
    """A heavy axis with large dry friction (M 2, Fv 1, Fc 2 against the multisine torque: a
    third of the record stuck), the cut-off given (10 Hz, where the noise-free motion's
    spectrum meets the encoder's white level). The rows at rest were left out of the dry
    friction's fit only with a cut-off chosen from the record: given one, they stayed in, and
    the stops' rows (where the friction balances the torque, anywhere in [-Fc, Fc]) took Fv to
    +239 % and Fc to -28 % (session 14, measured; earlier IDIM-IV failed on a fold there and the
    Coulomb term was lost, Fv +744 %). The encoder's noise is read from the record with a
    given cut-off as well (cutoff.given_cutoff), the rows at rest left out, and, measured,
    M +0.8 %, Fv +1.3 %, Fc -0.1 % (seeds 1, 2: M -0.1 / +0.8 %, Fv -1.2 / +8.4 %, Fc +0.2 /
    -0.8 %). Expected values: the generator's truth."""
    r = _heavy_axis(0)
    sel = analyse("rigid_axis", r["t"], {"tau": r["tau"], "q": r["q"]}, free_run=False,
                  cutoff_hz=10.0)
    fc = sel.settings["filter_choice"]
    assert fc["rule"] == "given" and fc["chosen_hz"] == {"q": 10.0}
    assert fc["signals"]["q"]["noise_level"] > 0
    assert ("coulomb_friction", "tau") in _found(sel)
    assert sel.final.theta["M"] == pytest.approx(2.0, rel=0.05)
    assert sel.final.theta["Fv"] == pytest.approx(1.0, rel=0.05)
    assert sel.final.theta["coulomb_friction@tau.Fc"] == pytest.approx(2.0, rel=0.05)


@lru_cache(maxsize=None)
def _readme_joint(seed):
    """The README's joint (vertical plane, motor PD at 500 Hz, 4096-count noisy link encoder,
    motor dry friction 0.03 N m) and the loop on it, the estimator and rollout by default."""
    r = Joint(fs=500, plane="vertical", control="motor", link_counts=4096, link_noise=2e-4,
              motor_counts=16384, Fc=0.03, seed=seed).record()
    sel = analyse("flexible_joint", r["t"], {k: r[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False)
    return r, sel


@pytest.mark.parametrize("seed", [0, 2])
def test_dry_and_viscous_friction_of_the_readme_joint_within_2_percent(seed):
    """The README's joint (vertical plane, motor PD at 500 Hz, 4096-count noisy link encoder,
    motor dry friction 0.03 N m), the estimator and rollout chosen by default. With each
    window's state fitted by one linearised step inside the output-error cost, dry friction
    came out traded for viscous (measured: Fc -17 % / -12.9 %, Dm +5.2 % / +3.7 % on seeds
    0 / 2): the switching sign's linearisation error is larger for the truth. The final
    estimate now fits the windows' states beside the parameters (output_error.joint_refine):
    measured every parameter within 0.4 % on seed 0 and 0.45 % on seed 2. Expected values:
    the generator's truth. (About 42 s of CPU each with one BLAS thread;
    42-67 s in CI on two busy workers, session 17.)"""
    r, sel = _readme_joint(seed)
    assert sel.settings["estimator"]["chosen"] == "output error (multiple shooting)"
    assert "joint" not in sel.settings["estimator"]["refinement"]     # it ran
    for p in ("Im", "Dm", "Ks", "Kd", "I", "Dl", "G"):
        assert sel.final.theta[p] == pytest.approx(r["truth"][p], rel=0.02), p
    assert sel.final.theta["coulomb_friction@tau_m.Fc"] == pytest.approx(0.03, rel=0.02)


def test_readme_joint_dry_friction_decided_on_the_chosen_estimators_fold_fits():
    """Seed 6 of the README's joint: with the structures compared on IDIM-LS fold fits the
    motor's dry friction predicted the held-out windows better at p 0.027 only (the windows'
    error is mostly IDIM-LS's errors-in-variables bias), above the level 0.01: no friction
    found, Dm +27 % (the viscous term took it). Compared on the fold fits of the estimator the
    windows choose for the declared model (output error there) it is found at p 3e-9.
    Expected values: the generator's truth, friction on the motor equation and Fc, Dm within
    5 % (the issue's bound). (About 40-50 s in CI, session 17.)"""
    r, sel = _readme_joint(6)
    assert sel.settings["structures_compared_by"]["chosen"] == "output error (multiple shooting)"
    assert ("coulomb_friction", "tau_m") in _found(sel)
    assert sel.final.theta["coulomb_friction@tau_m.Fc"] == pytest.approx(0.03, rel=0.05)
    assert sel.final.theta["Dm"] == pytest.approx(r["truth"]["Dm"], rel=0.05)


@pytest.mark.parametrize("seed", [0, 2])
def test_sigmas_of_the_readme_joint_match_the_spread_over_seeds(seed):
    """The output-error estimate's relative sigmas (the joint problem's sandwich, each window's
    state projected out: output_error.joint_covariance) against the spread of the estimate
    over records. Measured (session 12) on this record, seeds 0-19 less 6, 7 and 15 (6 and 15
    found no dry friction before the structures were compared on the chosen estimator's fold
    fits; with them and the Coulomb sign 0 at rest, 19 seeds less 7: Fc 0.87 %, Dm 0.33 %;
    seed 7's windows are fitted 10 % better at its estimate, Fc -9.8 %, than at the
    truth), the errors' standard deviation over the 17 seeds: Fc 0.81 %, Dm
    0.30 % (uncertain by about 18 %); the mean sigmas Fc 0.76 %, Dm 0.31 %.
    A sigma within a factor 3 of that spread either way; session 11's sigmas (the nested
    state fit's sensitivities) were Fc 6.0 %, Dm 1.9 % on seed 0. The analysis is shared with
    the test above (no extra run)."""
    _, sel = _readme_joint(seed)
    for p, spread in (("coulomb_friction@tau_m.Fc", 0.81), ("Dm", 0.30)):
        rel = 100 * sel.final.std[p] / sel.final.theta[p]
        assert spread / 3 < rel < 3 * spread, (p, rel)
