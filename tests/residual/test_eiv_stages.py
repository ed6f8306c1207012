"""Errors-in-variables equations: two-stage estimation and held-out decisions ([greybox] items
1, 3, 6).

The flight model's link equations are errors-in-variables (EIV) equations: parameters they
share with the clean motor equations come from the motor equations (first stage), the EIV
equations estimate only the rest with those held (second stage), and an effect on them is
claimed on held-out time blocks, with no fixed gain gate. Here the same declaration on a
flexible joint with a coarse, noisy link encoder (its twice-differentiated link angle is the
EIV regressor), records from ``joint_generator`` (plain numpy, its own RK4), and a synthetic
linear record for the covariance. Expected values are plain numpy least squares written here,
a Monte Carlo over noise draws, or the generator's own settings.
"""
from functools import lru_cache

import numpy as np
import pytest

from cdam_core.models.greybox.declared import DerivativeFilter, FlexibleJoint, Signals
from cdam_core.models.greybox.effects import CoulombFriction, ExternalForce
from cdam_core.models.greybox.estimation import design, fit
from cdam_core.residual.selection import select
from cdam_core.residual.validation import BlockedCV

from joint_generator import Joint

FS, DURATION, CUTOFF, TRIM = 500.0, 10.0, 30.0, 50
MOTOR = ("Im", "Dm", "Ks", "Kd")
LINK = ("I", "Dl", "G")


class EIVJoint(FlexibleJoint):
    """The flexible joint with its link equation declared errors-in-variables."""

    eiv_equations = ("tau_l",)


def _joint(**kw) -> Joint:
    return Joint(fs=FS, duration=DURATION, link_counts=4096, link_noise=2e-4, seed=3, **kw)


def _slow(seed: int, n: int) -> np.ndarray:
    """A Brownian bridge over the record, unit standard deviation (slowly varying)."""
    w = np.cumsum(np.random.default_rng(seed).normal(size=n))
    w -= np.linspace(w[0], w[-1], n)
    return w / np.std(w)


N = int(round(FS * DURATION))
# an unmeasured slow link torque (0.3 N m std) and a measured column unrelated to it: seed 4
# gives them a sample correlation of -0.65 over the record (a spurious regression)
LINK_TORQUE = 0.3 * _slow(4, N)


def _unrelated() -> np.ndarray:
    """The next Brownian bridge from the same generator as LINK_TORQUE."""
    rng = np.random.default_rng(4)
    rng.normal(size=N)            # the draw LINK_TORQUE used
    w = np.cumsum(rng.normal(size=N))
    w -= np.linspace(w[0], w[-1], N)
    return w / np.std(w)


@lru_cache(maxsize=None)
def _prepared(kind: str):
    m = EIVJoint()
    extra = None
    if kind == "plain":
        r = _joint().record()
    elif kind == "link_friction":
        r = _joint(Fc_link=0.125).record()
    else:   # "spurious"
        r = _joint(link_torque=tuple(LINK_TORQUE)).record()
        extra = {"z": _unrelated()}
    sig = m.prepare(r["t"], {k: r[k] for k in ("tau_m", "theta_m", "q")},
                    DerivativeFilter(CUTOFF), extra)
    return m, sig


def _columns(m, sig, effects=()):
    """Each equation's (y, X, names) over the fitted rows, from the model's columns."""
    _, eqs = design(m, sig, effects)
    n = sig["t"].size
    out = {}
    for eq, (y, cols) in eqs.items():
        names = [p for p in cols if p not in m.fixed]
        X = np.column_stack([np.broadcast_to(np.asarray(cols[p], float), (n,)) for p in names])
        out[eq] = (np.broadcast_to(np.asarray(y, float), (n,))[TRIM:n - TRIM],
                   X[TRIM:n - TRIM], names)
    return out


def _numpy_two_stage(m, sig, effects=()):
    """Plain numpy: the motor equation alone for its parameters, then the link equation for
    the rest with those held."""
    c = _columns(m, sig, effects)
    y1, X1, n1 = c["tau_m"]
    th1 = dict(zip(n1, np.linalg.lstsq(X1, y1, rcond=None)[0]))
    y2, X2, n2 = c["tau_l"]
    held = [j for j, p in enumerate(n2) if p in th1]
    free = [j for j, p in enumerate(n2) if p not in th1]
    rhs = y2 - X2[:, held] @ np.array([th1[n2[j]] for j in held])
    th2 = dict(zip([n2[j] for j in free], np.linalg.lstsq(X2[:, free], rhs, rcond=None)[0]))
    return {**th1, **th2}, rhs, X2[:, free]


def _numpy_weighted(m, sig, w):
    """Plain numpy: both equations stacked, the link rows weighted by ``w``."""
    c = _columns(m, sig)
    names = list(dict.fromkeys(c["tau_m"][2] + c["tau_l"][2]))
    rows, rhs = [], []
    for eq, f in (("tau_m", 1.0), ("tau_l", w)):
        y, X, nm = c[eq]
        A = np.zeros((y.size, len(names)))
        for j, p in enumerate(nm):
            A[:, names.index(p)] = X[:, j]
        rows.append(f * A)
        rhs.append(f * y)
    return dict(zip(names, np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]))


def test_two_stage_is_the_vanishing_weight_limit():
    m, sig = _prepared("plain")
    got = fit(m, sig, (), TRIM).theta
    ref, _, _ = _numpy_two_stage(m, sig)
    for p in MOTOR + LINK:
        assert got[p] == pytest.approx(ref[p], rel=1e-8, abs=1e-12), p
    # the weighted stack tends to it as the link weight vanishes (the session-7 weight 1e-3
    # stood for this limit): the gap shrinks with the weight and is gone at 1e-4
    gaps = []
    for w in (1e-1, 1e-2, 1e-4):
        wt = _numpy_weighted(m, sig, w)
        gaps.append(max(abs(wt[p] / ref[p] - 1) for p in MOTOR + ("I", "Dl")))
    assert gaps[0] > gaps[1] > gaps[2] and gaps[2] < 1e-6, gaps
    # and the equal-weight stack is what the two stages avoid: the link rows drag Ks
    assert abs(_numpy_weighted(m, sig, 1.0)["Ks"] / ref["Ks"] - 1) > 10 * gaps[2]


class _MCJoint(EIVJoint):
    """The EIV joint on synthetic prepared signals: the link equation's left side is a given
    noise column (so both equations have plain additive errors)."""

    def equations(self, s):
        eqs = super().equations(s)
        eqs["tau_l"] = (s["e_l"], eqs["tau_l"][1])
        return eqs


def test_second_stage_sigma_carries_the_first_stage():
    """Monte Carlo over noise draws on fixed regressors: each stage's standard deviation
    matches the spread of its estimates; the second stage's own least-squares term alone
    would be too small (its parameters lean on the held Ks and Kd)."""
    rng = np.random.default_rng(7)
    n, reps = 2000, 300
    t = np.arange(n) * 1e-3
    base = {"t": t, "dt": 1e-3}
    for k in ("theta_m_dd", "theta_m_d", "defl", "defl_d", "q_d", "q"):
        base[k] = np.convolve(rng.normal(size=n + 50), np.ones(50) / 50, "valid")[:n]
    # the link acceleration mostly follows the cable deflection (as a stiff cable makes it)
    base["q_dd"] = 2.0 * base["defl"] + 0.3 * rng.normal(size=n)
    truth = {"Im": 0.02, "Dm": 0.05, "Ks": 40.0, "Kd": 0.05, "I": 0.1, "Dl": 0.1, "G": 0.5}
    motor = (truth["Im"] * base["theta_m_dd"] + truth["Dm"] * base["theta_m_d"]
             + truth["Ks"] * base["defl"] + truth["Kd"] * base["defl_d"])
    link = (truth["I"] * base["q_dd"] + truth["Dl"] * base["q_d"] + truth["G"] * np.sin(base["q"])
            - truth["Ks"] * base["defl"] - truth["Kd"] * base["defl_d"])
    m = _MCJoint()
    est, sd = [], []
    for _ in range(reps):
        s = Signals(base)
        s["tau_m"] = motor + 0.05 * rng.normal(size=n)
        s["e_l"] = link + 0.02 * rng.normal(size=n)
        f = fit(m, s, (), TRIM)
        est.append([f.theta[p] for p in MOTOR + LINK])
        sd.append([f.std[p] for p in MOTOR + LINK])
    spread = np.std(est, axis=0, ddof=1)
    formula = np.mean(sd, axis=0)
    # 300 draws: the sample standard deviation is within 4 % (one sigma) of the truth
    assert np.allclose(formula, spread, rtol=0.15), dict(zip(MOTOR + LINK, formula / spread))
    # the second stage's own term (plain numpy, the last draw's residual variance)
    X2 = np.column_stack([base["q_dd"], base["q_d"], np.sin(base["q"])])[TRIM:n - TRIM]
    r2 = f.residuals["tau_l"]
    own = np.sqrt(np.diag(np.linalg.inv(X2.T @ X2)) * (r2 @ r2) / (r2.size - 3))
    assert own[0] < 0.7 * spread[4], (own, spread[4:])


def _gain(m, sig, eff):
    """Plain numpy: the share of the link equation's second-stage residual sum of squares the
    effect's column removes (first stage held at the declared values)."""
    theta, rhs, X = _numpy_two_stage(m, sig)
    r0 = rhs - X @ np.linalg.lstsq(X, rhs, rcond=None)[0]
    c = _columns(m, sig, (eff,))
    y, Xe, names = c["tau_l"]
    held = [j for j, p in enumerate(names) if p in ("Ks", "Kd")]
    free = [j for j, p in enumerate(names) if p not in ("Ks", "Kd")]
    rhs1 = y - Xe[:, held] @ np.array([theta[names[j]] for j in held])
    r1 = rhs1 - Xe[:, free] @ np.linalg.lstsq(Xe[:, free], rhs1, rcond=None)[0]
    return 1.0 - (r1 @ r1) / (r0 @ r0)


def test_link_only_effect_below_twenty_percent_is_claimed_on_held_out_blocks():
    """Link-side dry friction 0.125 N m removes about 15 % of the link equation's residual
    in-sample (the rest is the encoder's twice-differentiated noise): below the 20 % gate the
    flight model used to apply, yet held-out equation error on blocks the fit did not see
    confirms it (one-sided Wilcoxon at 1 %)."""
    m, sig = _prepared("link_friction")
    eff = CoulombFriction("tau_l")
    gain = _gain(m, sig, eff)
    assert 0.10 < gain < 0.20, gain
    dec = fit(m, sig, (), TRIM)
    cv = BlockedCV(m, sig, TRIM, declared=dec, criterion="equation")
    v = cv.compare(((), None), ((eff,), None), 1, 0.01)
    assert v.better and v.score_rich < v.score_simple, v.to_json()


def test_spurious_large_in_sample_gain_on_a_link_equation_is_not_claimed():
    """A measured column unrelated to the slow torque acting on the link removes about 25 % of
    the link residual in-sample, above the 20 % gate the flight model used to apply (a
    spurious regression of two slowly varying signals; 24.6 % once the declared link equation
    has its Gc cos q and constant terms); it does not predict held-out blocks, and the
    selection does not claim it."""
    m, sig = _prepared("spurious")
    assert abs(np.corrcoef(LINK_TORQUE, sig["extra"]["z"])[0, 1]) > 0.5
    eff = ExternalForce(channel="tau_l", column="z")
    assert _gain(m, sig, eff) > 0.20
    dec = fit(m, sig, (), TRIM)
    v = BlockedCV(m, sig, TRIM, declared=dec, criterion="equation").compare(
        ((), None), ((eff,), None), 1, 0.01)
    assert not v.better, v.to_json()
    sel = select(m, sig, [eff], free_run=False, estimator="idim-ls")
    assert sel.steps == [] and sel.settings["validation"]["status"] == "ok"


def test_without_held_out_blocks_a_link_only_effect_is_not_claimed():
    """Without held-out data nothing is claimed (the in-sample statistics cannot decide, on an
    EIV equation least of all: its mismatch correlates with any velocity-shaped column): the
    friction the held-out blocks confirm above is then not claimed, and the settings say
    why."""
    m, sig = _prepared("link_friction")
    sel = select(m, sig, [CoulombFriction("tau_l")], free_run=False, estimator="idim-ls",
                 held_out=False)
    assert sel.steps == [] and sel.settings["validation"]["status"] == "off"


class _BoundedJoint(EIVJoint):
    """A lower bound on the link inertia above its unconstrained estimate (0.089)."""

    bounds = {**EIVJoint.bounds, "I": (0.095, float("inf"))}


def test_bounded_refit_keeps_the_stages():
    """A second-stage bound is active: the first stage is untouched, the second refitted with
    I at its bound (plain numpy: the link equation with I held too)."""
    m0, sig = _prepared("plain")
    m = _BoundedJoint()
    f = fit(m, sig, (), TRIM, bounded=True)
    assert f.violations == ["I"] and f.theta["I"] == pytest.approx(0.095)
    ref, _, _ = _numpy_two_stage(m0, sig)
    for p in MOTOR:
        assert f.theta[p] == pytest.approx(ref[p], rel=1e-6), p
    y, X, names = _columns(m0, sig)["tau_l"]
    fixed = {p: ref[p] for p in ("Ks", "Kd")} | {"I": 0.095}
    held = [j for j, p in enumerate(names) if p in fixed]
    free = [j for j, p in enumerate(names) if p not in fixed]
    rhs = y - X[:, held] @ np.array([fixed[names[j]] for j in held])
    sol = dict(zip([names[j] for j in free], np.linalg.lstsq(X[:, free], rhs, rcond=None)[0]))
    for p in ("Dl", "G"):
        assert f.theta[p] == pytest.approx(sol[p], rel=1e-5), p
