"""EMPS real data (Janot, Gautier, Brunot 2019): published IDIM-LS numbers in
../shared/docs/ALGORITHMS.md, section EMPS."""
import numpy as np
import pytest

from cdam_core.record.realdata.emps import EMPS_UNITS, load_emps


@pytest.fixture(autouse=True, scope="module")
def _records_present(bundled_record):
    """The EMPS records ship in data/emps: missing is a failure, not a skip."""
    bundled_record("emps/DATA_EMPS.mat")
    bundled_record("emps/DATA_EMPS_PULSES.mat")

PUBLISHED = {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648}
PUBLISHED_ASYM = {"Fv_pos": 166.71, "Fc_pos": 20.144, "Fv_neg": 240.42, "Fc_neg": 20.628}


def test_load_emps_shapes_and_force():
    d = load_emps("DATA_EMPS")
    assert d["t"].shape == d["qm"].shape == d["force"].shape == (24841,)
    assert d["gtau"] == pytest.approx(35.15, abs=0.01)
    np.testing.assert_allclose(d["force"], d["gtau"] * d["vir"], rtol=1e-12)
    assert "pulses" in load_emps("DATA_EMPS_PULSES") and "pulses" not in d


def test_load_emps_rejects_bad_name_and_corrupt_file(tmp_path):
    with pytest.raises(ValueError, match="name"):
        load_emps("NOPE")
    bad = tmp_path / "x.mat"
    bad.write_bytes(b"not a mat file at all")
    with pytest.raises(ValueError, match="path"):
        load_emps(path=bad)


@pytest.fixture(scope="module")
def emps_selection():
    from cdam_core.residual import analyse
    d, p = load_emps("DATA_EMPS"), load_emps("DATA_EMPS_PULSES")
    return analyse("rigid_axis", d["t"], {"tau": d["force"], "q": d["qm"]},
                   validation=(p["t"], {"tau": p["force"], "q": p["qm"]}), units=EMPS_UNITS)


def test_emps_published_values_under_their_timing():
    """The published IDIM-LS values compare the force sample with the state at the same
    instant: under that timing M, Fv, Fc and the offset come within 1 %."""
    from cdam_core.residual import analyse
    d = load_emps("DATA_EMPS")
    sel = analyse("rigid_axis", d["t"], {"tau": d["force"], "q": d["qm"]}, free_run=False,
                  timing="sampled", max_steps=1, estimator="idim-ls",
                  units=EMPS_UNITS)
    th = sel.steps[0].candidate.fit.theta
    est = {"M": th["M"], "Fv": th["Fv"], "Fc": th["coulomb_friction@tau.Fc"],
           "offset": th["offset"]}
    for k, v in PUBLISHED.items():
        assert est[k] == pytest.approx(v, rel=0.01), k


def test_emps_data_choose_the_zero_order_hold(emps_selection):
    # vir leaves the controller through a DAC: the held-out equations prefer the state half
    # a sample after each force sample (measured p 1e-18), which moves Fv +2.5 % and Fc -2 %
    tm = emps_selection.settings["timing"]
    assert tm["chosen"] == "held" and tm["p_value"] < 1e-6, tm


def test_emps_finds_coulomb_then_asymmetric(emps_selection):
    sel = emps_selection
    assert [s.candidate.effect.name for s in sel.steps] == ["coulomb_friction",
                                                            "asymmetric_friction"]
    th = sel.steps[0].candidate.fit.theta
    est = {"M": th["M"], "Fv": th["Fv"], "Fc": th["coulomb_friction@tau.Fc"],
           "offset": th["offset"]}
    for k, v in PUBLISHED.items():
        assert est[k] == pytest.approx(v, rel=0.05), k
    asym = sel.steps[1].candidate.effect.parameters(sel.steps[1].candidate.fit.theta, sel.model)
    for k, v in PUBLISHED_ASYM.items():
        assert asym[k] == pytest.approx(v, rel=0.05), k


def test_emps_force_error_before_and_after(emps_selection):
    sel = emps_selection
    e0 = sel.declared_error["tau"]["nrmse"]
    e1 = sel.steps[0].error_after["tau"]["nrmse"]
    e2 = sel.steps[1].error_after["tau"]["nrmse"]
    assert 0.15 < e0 < 0.19            # our check without Coulomb: about 17 %
    assert 0.035 < e1 < 0.05           # published 4.08 % (their decimated data)
    assert 0.028 < e2 < e1             # published 3.11 %


def test_emps_pulses_free_run_error(emps_selection):
    # open loop on DATA_EMPS_PULSES from its vir with the DATA_EMPS estimates
    sel = emps_selection
    before = sel.declared_error["q"]["rmse"]
    after_coulomb = sel.steps[0].error_after["q"]["rmse"]
    assert 0.012 < before < 0.030       # issue's check: ~21 mm
    assert 0.006 < after_coulomb < 0.011  # issue's check: ~8.8 mm


def test_emps_pulses_resonance_is_unexplained(emps_selection):
    """PULSES's 17-23 Hz structure: under the published timing (force sample against the state
    at the same instant) a broad spectral peak near 24 Hz, more than a decade above its base;
    the model's terms driven by the force alone account for under a fifth of the band's power
    (measured 0.185), so it stays reported as unexplained. Under the zero-order hold the
    held-out data choose, the residual RMS falls 26 % (5.93 -> 4.40 N, measured) and the hump
    with it (0.06 decades): most of it was the half-sample timing error acting on the pulses'
    edges. The narrow 20.4 Hz line that stays (0.33 N) is within what the model's own terms
    produce there (its line is 0.69 of the largest input-driven term: the Coulomb terms' sign
    columns are broadband), so it is listed as the model's, with its attribution; the mains
    lines near 100 Hz are not (3.9-5.4 times the largest term) and stay unexplained."""
    from cdam_core.residual import analyse
    p = load_emps("DATA_EMPS_PULSES")
    sig = {"tau": p["force"], "q": p["qm"]}
    # the two timings compared under one estimator, IDIM-LS (on PULSES output error is chosen
    # under the hold: p 0.001 at level 0.005 on RK4 windows, the sign held over each step)
    sampled = analyse("rigid_axis", p["t"], sig, free_run=False, timing="sampled",
                      estimator="idim-ls", units=EMPS_UNITS)
    names = [s.candidate.effect.name for s in sampled.steps]
    assert names[0] == "coulomb_friction"
    assert set(names) <= {"coulomb_friction", "asymmetric_friction"}
    peaks = [u["frequency_hz"] for u in sampled.unexplained if u["kind"] == "spectral_peak"]
    assert any(15.0 <= f <= 27.0 for f in peaks), sampled.unexplained
    held = analyse("rigid_axis", p["t"], sig, free_run=False, estimator="idim-ls",
                   units=EMPS_UNITS)
    assert held.settings["timing"]["chosen"] == "held"
    lines = [u["frequency_hz"] for u in held.unexplained if u["kind"] == "periodic_line"]
    assert any(abs(f - 100.0) < 0.5 for f in lines), held.unexplained
    assert not any(15.0 <= f <= 27.0 for f in lines), held.unexplained
    model = held.settings["residual_structure_explained_by_the_model"]["explained"]
    at20 = [u for u in model if abs(u["frequency_hz"] - 20.4) < 0.3]
    assert at20 and at20[0]["attribution"]["relative_to_terms"] < 1.0
    assert np.std(held.final.residuals["tau"]) < 0.85 * np.std(sampled.final.residuals["tau"])
    # the broad 17-23 Hz resonance is a PULSES phenomenon; DATA_EMPS's residual holds narrow
    # periodic lines only, the mains' near 50 and 100 Hz unexplained.
    # DATA_EMPS's analysis is the module's (the free runs on PULSES do not enter its residual)
    un = emps_selection.unexplained
    assert any(abs(u["frequency_hz"] - 50.0) < 0.7 for u in un), un
    assert not any(15.0 <= u["frequency_hz"] <= 27.0 for u in un if u["kind"] == "spectral_peak")


def test_benchmark_protocol_reproduces_the_published_model():
    """nonlinearbenchmark.org's EMPS protocol (all of vir, the first 20 samples of qm, open-loop
    simulation, RMSE of qm in mm over the rest) on the published IDIM-LS parameters: 8.4 mm as
    measured for issue [greybox] with an independent simulation."""
    from cdam_core.evaluate.simulation import EMPS_PROTOCOL, simulation_score
    from cdam_core.models.greybox.augmented import GreyBox
    from cdam_core.models.greybox.effects import CoulombFriction
    p = load_emps("DATA_EMPS_PULSES")
    g = GreyBox("rigid_axis", 0.001, [CoulombFriction("tau")], fixed={"G": 0.0, "Gc": 0.0})
    g._set(g._structure(), {"M": PUBLISHED["M"], "Fv": PUBLISHED["Fv"], "G": 0.0, "Gc": 0.0,
                            "offset": PUBLISHED["offset"],
                            "coulomb_friction@tau.Fc": PUBLISHED["Fc"]}, {}, [], 1, 1)
    sc = simulation_score(g, p["force"], p["qm"], EMPS_PROTOCOL["n_init"], EMPS_PROTOCOL["scale"])
    assert sc.status == "ok"
    assert sc.rmse[0] == pytest.approx(8.4, abs=0.1)


def _idim_plain(r):
    """The published structure plus asymmetric viscous friction by plain least squares (zero-phase
    30 Hz Butterworth on position and force, central differences, moving samples only):
    [M, Fv-, Fc, offset, Fv+ - Fv-]."""
    from scipy.signal import butter, filtfilt
    b, a = butter(4, 30.0 / 500.0)
    q = filtfilt(b, a, r["qm"])
    v = np.gradient(q, 1e-3)
    X = np.column_stack([np.gradient(v, 1e-3), v, np.sign(v), np.ones_like(v), v * (v > 0)])
    m = np.abs(v) > 0.005
    m[:200] = m[-200:] = False
    th, *_ = np.linalg.lstsq(X[m], filtfilt(b, a, r["force"])[m], rcond=None)
    return th


def _protocol_plain(th, r, n0=20):
    """The benchmark protocol with a plain simulator (semi-implicit Euler at the 1 kHz sampling,
    force held over the sample, sign(0) = 0): RMSE of qm in mm after the first n0 samples."""
    M, fv, fc, off, dfv = (float(x) for x in th)
    F, Q = r["force"], r["qm"]
    x, v = Q[n0 - 1], (Q[n0 - 1] - Q[n0 - 2]) / 1e-3
    out = np.empty(Q.size)
    out[:n0] = Q[:n0]
    for k in range(n0 - 1, Q.size - 1):
        s = 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)
        v += 1e-3 * (F[k] - fv * v - fc * s - off - (dfv * v if v > 0 else 0.0)) / M
        x += 1e-3 * v
        out[k + 1] = x
    return 1000.0 * float(np.sqrt(np.mean((out[n0:] - Q[n0:]) ** 2)))


def test_pulses_friction_level_is_not_data_emps():
    """Why the protocol target is open (plain numpy, independent of the package): the two records
    share the trajectory, but PULSES's friction is about 1 N higher in both directions (moving
    samples away from the pulse edges; measured +0.91 / -1.11 N), so the same structure fitted on
    either record simulates that record to <= 3.5 mm under the protocol (measured 2.8 and 2.3 mm)
    while DATA_EMPS's parameters score 11.8 mm on PULSES: the open-loop score of an integrating
    axis is set by the friction level, which DATA_EMPS cannot tell for the other record. The
    halves of DATA_EMPS differ the same way (its viscous friction drifts by 3 % over 25 s)."""
    d, p = load_emps("DATA_EMPS"), load_emps("DATA_EMPS_PULSES")
    assert np.max(np.abs(p["qm"] - d["qm"])) < 5e-4              # the same motion (0.17 mm)
    v = np.gradient(d["qm"], 1e-3)
    df = p["force"] - d["force"]
    quiet = np.ones(df.size, dtype=bool)
    for k in np.flatnonzero(np.abs(np.diff(p["pulses"])) > 1) + 1:
        quiet[max(k - 5, 0):k + 150] = False                      # the edges and the loop's reply
    assert np.mean(df[quiet & (v > 0.01)]) > 0.5                  # more force to move forward
    assert np.mean(df[quiet & (v < -0.01)]) < -0.5                # and backward
    te, tp = _idim_plain(d), _idim_plain(p)
    assert abs(tp[0] / te[0] - 1) < 0.02                          # M: -1.2 %
    assert tp[1] / te[1] - 1 > 0.02 and tp[2] / te[2] - 1 > 0.01  # Fv- +3.5 %, Fc +1.9 %
    assert _protocol_plain(te, d) < 3.5 and _protocol_plain(tp, p) < 3.5
    assert _protocol_plain(te, p) > 8.0
    # the same within DATA_EMPS: each half's fit simulates its own half to 1.1 / 1.7 mm and the
    # other half to 7.2 / 6.1 mm (measured), above the 6 mm target on a record it never saw
    n = d["qm"].size // 2
    halves = [{k: d[k][sl] for k in ("qm", "force")} for sl in (slice(0, n), slice(n, None))]
    for i, h in enumerate(halves):
        th = _idim_plain(h)
        assert _protocol_plain(th, h) < 2.5 and _protocol_plain(th, halves[1 - i]) > 5.0


def test_asymmetric_friction_holds_over_long_held_out_windows(emps_selection):
    """The step that raises the PULSES score is no artefact of short validation windows: fitted
    (IDIM-LS, bounded) on four fifths of DATA_EMPS, the model with asymmetric friction simulates
    every 2.4 s window of the held-out fifth from 20 measured samples better than the one with
    symmetric friction (measured RMS 1.4 against 3.6 mm; 4.8 s windows 2.1 against 3.9 mm)."""
    from cdam_core.models.greybox.effects import AsymmetricFriction, CoulombFriction
    from cdam_core.models.greybox.estimation import fit
    sel = emps_selection
    m, sig = sel.declared.model, sel.declared.signals
    d = load_emps("DATA_EMPS")
    n, H = d["qm"].size, 2400
    edges = np.linspace(0, n, 6).astype(int)
    err = {"sym": [], "asym": []}
    for a, b in zip(edges[:-1], edges[1:]):
        rows = np.ones(n, dtype=bool)
        rows[max(a - 50, 0):b + 50] = False
        for name, eff in (("sym", (CoulombFriction("tau"),)),
                          ("asym", (CoulombFriction("tau"), AsymmetricFriction("tau")))):
            th = fit(m, sig, eff, 50, rows=rows, bounded=True).theta
            vec = [th["M"], th["Fv"], th["coulomb_friction@tau.Fc"], th.get("offset", 0.0),
                   th.get("asymmetric_friction@tau.dFv", 0.0)]
            for s0 in range(max(a, 60), b - H, H):
                w = {k: d[k][s0 - 20:s0 + H] for k in ("qm", "force")}
                err[name].append(_protocol_plain(vec, w))
    e0, e1 = np.array(err["sym"]), np.array(err["asym"])
    assert e0.size == 10 and np.all(e1 < e0), (e0, e1)


@pytest.mark.xfail(strict=True, reason="issue [greybox]: target <= 6 mm on the protocol; the "
                                        "final model (12.3 mm) is not there: PULSES's friction "
                                        "is ~1 N above DATA_EMPS's (test_pulses_friction_level_"
                                        "is_not_data_emps), which DATA_EMPS cannot tell")
def test_residual_final_model_meets_the_benchmark_target(emps_selection):
    """The residual loop's final model (DATA_EMPS), simulated on DATA_EMPS_PULSES under the
    protocol, at or below the issue's 6 mm target (published IDIM-LS: 8.4 mm)."""
    from cdam_core.evaluate.simulation import EMPS_PROTOCOL
    from cdam_core.residual.benchmark import protocol_scores
    p = load_emps("DATA_EMPS_PULSES")
    sc = protocol_scores(emps_selection, {"t": p["t"], "tau": p["force"], "q": p["qm"]},
                         EMPS_PROTOCOL["n_init"], EMPS_PROTOCOL["scale"])
    print({k: v.rmse for k, v in sc.items()})
    assert sc["declared"].status == "ok" and sc["final"].status == "ok"
    assert sc["final"].rmse[0] <= 6.0
