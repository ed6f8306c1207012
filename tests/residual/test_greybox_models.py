"""Declared models: IDIM-LS recovers known parameters, free run reproduces the generator."""
import numpy as np
import pytest
from test_residual_synth_data import FLEX, RIGID, flexible_joint_record, rigid_axis_record

from cdam_core.residual import fit, get_model, simulate
from cdam_core.models.greybox.effects import CoulombFriction, candidates
from cdam_core.models.greybox.freerun import free_run_error


def test_rigid_axis_exact_on_analytic_signals():
    # q = sin(2 pi 1.5 t): derivatives in closed form, tau from the model -> exact estimates
    t = np.arange(0, 5, 1e-3)
    w = 2 * np.pi * 1.5
    q = 0.1 * np.sin(w * t)
    tau = 2.0 * (-0.1 * w ** 2 * np.sin(w * t)) + 5.0 * (0.1 * w * np.cos(w * t)) + 0.5
    m = get_model("rigid_axis")
    f = fit(m, m.prepare(t, {"tau": tau, "q": q}))
    assert f.theta["M"] == pytest.approx(2.0, rel=1e-3)
    assert f.theta["Fv"] == pytest.approx(5.0, rel=1e-3)
    assert f.theta["offset"] == pytest.approx(0.5, rel=1e-3)


def test_flexible_joint_recovers_parameters():
    rec = flexible_joint_record(seed=1)
    m = get_model("flexible_joint")
    f = fit(m, m.prepare(rec["t"], {k: rec[k] for k in ("tau_m", "theta_m", "q")}))
    for k, v in FLEX.items():
        assert f.theta[k] == pytest.approx(v, rel=0.1), k


def test_free_run_reproduces_the_record():
    rec = rigid_axis_record(seed=1, duration=4.0, Fc=1.5, noise=0.0)
    m = get_model("rigid_axis", {"G": 0.0, "Gc": 0.0})   # the generator's linear axis
    sig = m.prepare(rec["t"], {"tau": rec["tau"], "q": rec["q"]})
    f = fit(m, sig, (CoulombFriction("tau"),))
    # with the true parameters, semi-implicit Euler must reproduce the RK4 record
    f.theta.update(RIGID)
    f.theta["coulomb_friction@tau.Fc"] = 1.5
    err, sim = free_run_error(f, sig)
    # (semi-implicit Euler vs RK4, filtered initial velocity, open-loop drift: 2 %)
    assert err["q"]["rmse"] < 0.02 * np.std(rec["q"])


def test_flexible_free_run_tracks_generator():
    rec = flexible_joint_record(seed=1, duration=3.0, noise=0.0)
    m = get_model("flexible_joint", fixed=None)
    sig = m.prepare(rec["t"], {k: rec[k] for k in ("tau_m", "theta_m", "q")})
    f = fit(m, sig)
    sim = simulate(f, rec["t"], {"tau_m": rec["tau_m"]}, x0=[0.0, 0.0], v0=[0.0, 0.0])
    assert np.sqrt(np.mean((sim["q"] - rec["q"]) ** 2)) < 0.05 * np.std(rec["q"])


def test_quadrotor_exact_on_analytic_signals():
    # level flight with closed-form Z, X, psi: T and the moments built from PAPER.md (1)
    t = np.arange(0, 8, 1e-3)
    w = 2 * np.pi * 0.4
    Z, Zd, Zdd = 1 + 0.2 * np.sin(w * t), 0.2 * w * np.cos(w * t), -0.2 * w ** 2 * np.sin(w * t)
    psi, psid, psidd = 0.3 * np.sin(w * t), 0.3 * w * np.cos(w * t), -0.3 * w ** 2 * np.sin(w * t)
    m, Kz, Jz, Kpsi = 1.8, 0.3, 0.024, 0.005
    zero = np.zeros_like(t)
    sig = {"T": m * (Zdd + 9.81) + Kz * Zd, "tau_phi": zero, "tau_theta": zero,
           "tau_psi": Jz * psidd + Kpsi * psid, "phi": zero, "theta": zero, "psi": psi,
           "X": zero, "Y": zero, "Z": Z}
    q = get_model("quadrotor")
    f = fit(q, q.prepare(t, sig), (), trim=1000)
    for k, v in {"m": m, "Kz": Kz, "Jz": Jz, "Kpsi": Kpsi}.items():
        assert f.theta[k] == pytest.approx(v, rel=2e-3), k


def test_models_unknown():
    with pytest.raises(ValueError, match="unknown model"):
        get_model("nope")
    with pytest.raises(ValueError, match="fixed"):
        get_model("rigid_axis", fixed={"X": 1.0})


def test_prepare_rejects_bad_signals():
    m = get_model("rigid_axis")
    t = np.arange(1000) * 1e-3
    with pytest.raises(ValueError, match="needs signal"):
        m.prepare(t, {"tau": np.zeros(1000)})
    with pytest.raises(ValueError, match="q: contains NaN"):
        m.prepare(t, {"tau": np.zeros(1000), "q": np.r_[np.nan, np.zeros(999)]})
    with pytest.raises(ValueError, match="t: not strictly increasing"):
        m.prepare(t[::-1], {"tau": np.zeros(1000), "q": np.zeros(1000)})
    with pytest.raises(ValueError, match="tau: has 999"):
        m.prepare(t, {"tau": np.zeros(999), "q": np.zeros(1000)})


def test_candidates_apply_per_model():
    rig = {e.key for e in candidates(get_model("rigid_axis"))}
    assert rig == {"coulomb_friction@tau", "asymmetric_friction@tau", "actuator_delay@tau"}
    flx = {e.name for e in candidates(get_model("flexible_joint"))}
    assert {"backlash", "hardening_stiffness", "coulomb_friction"} <= flx
    assert "payload_mass" not in flx and "ground_effect" not in flx
    fixed = get_model("flexible_joint", fixed={"I": 0.05, "G": 0.8})
    assert "payload_mass" in {e.name for e in candidates(fixed)}


@pytest.mark.parametrize("name", ["quadrotor", "aerial_manipulator"])
def test_rotor_commands_share_one_delay_candidate(name):
    # the four rotor commands get one joint delay (channel "rotors"), the joints their own
    m = get_model(name)
    delays = [e for e in candidates(m) if e.name == "actuator_delay"]
    rotors = [e for e in delays if e.channel == "rotors"]
    assert len(rotors) == 1 and set(rotors[0].commands) == {"T", "tau_phi", "tau_theta", "tau_psi"}
    per = {e.channel for e in delays if e.channel != "rotors"}
    assert per == ({"tau_m1", "tau_m2"} if name == "aerial_manipulator" else set())
    # every command shifted by the same delay: sin(w (t - d)) in closed form
    t = np.arange(0, 2, 0.01)
    w, d = 2 * np.pi * 0.7, 0.02
    s = {"t": t, **{c: (k + 1) * np.sin(w * t) for k, c in enumerate(rotors[0].commands)}}
    out = rotors[0].with_value(d).transform_inputs(s, m)
    inner = t >= d
    for k, c in enumerate(rotors[0].commands):
        assert np.allclose(out[c][inner], (k + 1) * np.sin(w * (t[inner] - d)), atol=2e-3)
    assert rotors[0].with_value(d).parameters({}, m)["delay"] == d
