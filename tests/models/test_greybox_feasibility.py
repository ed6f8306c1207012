"""Physical feasibility of the grey-box estimates: an estimate outside the model's bounds
(negative inertia, stiffness, damping, dry friction) is refitted by bounded least squares and
both are reported. The bounded solution is checked against scipy.optimize.lsq_linear on the
same regressors."""
import numpy as np
import pytest
from scipy.optimize import lsq_linear
from scipy.signal import butter, sosfiltfilt

from cdam_core.models.greybox.effects import CoulombFriction
from cdam_core.models.greybox.estimation import fit
from cdam_core.models.greybox.registry import get_model

DT = 1e-3


def _record(fv, fc=0.0, n=4000, seed=0):
    t = np.arange(n) * DT
    q = 0.3 * np.sin(2 * np.pi * 0.8 * t) + 0.1 * np.sin(2 * np.pi * 2.9 * t)
    qd = np.gradient(q, DT)
    qdd = np.gradient(qd, DT)
    tau = 2.0 * qdd + fv * qd + fc * np.sign(qd) + 0.2
    return t, q, tau + 0.01 * np.random.default_rng(seed).standard_normal(n)


def test_negative_damping_is_refitted_with_bounds():
    t, q, tau = _record(fv=-0.5)                 # an "active" axis: no passive model fits it
    m = get_model("rigid_axis", {"G": 0.0, "Gc": 0.0})   # a linear axis
    sig = m.prepare(t, {"tau": tau, "q": q})
    free = fit(m, sig)                           # structure searches: unconstrained, flagged
    assert free.violations == ["Fv"] and free.theta["Fv"] == free.unconstrained["Fv"]
    f = fit(m, sig, bounded=True)
    assert f.violations == ["Fv"]
    assert f.unconstrained["Fv"] == pytest.approx(-0.5, abs=0.02)
    assert f.theta["Fv"] == 0.0 and np.isnan(f.std["Fv"])
    k = slice(50, len(t) - 50)
    # parallel filtering: both sides low-passed by the derivative filter's Butterworth (order
    # 4, 100 Hz, zero phase), here with scipy directly
    sos = butter(4, 100.0, fs=1.0 / DT, output="sos")
    X = sosfiltfilt(sos, np.column_stack([sig["q_dd"], sig["q_d"], np.ones(len(t))]), axis=0)
    y = sosfiltfilt(sos, tau)
    ref = lsq_linear(X[k], y[k], bounds=([0, 0, -np.inf], [np.inf, np.inf, np.inf])).x
    np.testing.assert_allclose([f.theta["M"], f.theta["Fv"], f.theta["offset"]], ref,
                               rtol=1e-6, atol=1e-9)


def test_feasible_estimates_are_left_alone():
    t, q, tau = _record(fv=0.5, fc=0.3)
    m = get_model("rigid_axis")
    f = fit(m, m.prepare(t, {"tau": tau, "q": q}), (CoulombFriction("tau"),))
    assert f.violations == [] and f.unconstrained == {}
    assert f.theta["Fv"] == pytest.approx(0.5, rel=0.05)
    assert f.theta["coulomb_friction@tau.Fc"] == pytest.approx(0.3, rel=0.1)


def test_negative_dry_friction_is_refused():
    t, q, tau = _record(fv=0.5, fc=-0.3)
    m = get_model("rigid_axis")
    f = fit(m, m.prepare(t, {"tau": tau, "q": q}), (CoulombFriction("tau"),), bounded=True)
    assert f.violations == ["coulomb_friction@tau.Fc"]
    assert f.theta["coulomb_friction@tau.Fc"] == 0.0
