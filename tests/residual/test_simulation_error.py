"""The simulation-error refinement over whole runs and the free-run check ([greybox] 19,
items 2 and 8), on a rigid axis written here in plain numpy (not cdam_core.sim, not the
model's integrators): M q'' + Fv q' + Fc sign(q') + offset = tau, the force held over each
sample, semi-implicit Euler on a grid 20 times finer than the sampling, the sign as
tanh(q' / 0.1 mm/s) (a stiff but continuous dry friction)."""
from functools import lru_cache

import numpy as np
import pytest

from cdam_core.models.greybox.declared import DerivativeFilter
from cdam_core.models.greybox.effects import CoulombFriction
from cdam_core.models.greybox.estimation import fit
from cdam_core.models.greybox.registry import get_model
from cdam_core.residual.benchmark import greybox_of
from cdam_core.residual.output_error import runs, simulation_refine
from cdam_core.residual.selection import free_run_check, select
from cdam_core.residual.validation import MIN_WINDOWS, BlockedCV

TRUTH = {"M": 0.5, "Fv": 2.0, "coulomb_friction@tau.Fc": 1.0, "offset": 0.3}


@lru_cache(maxsize=None)
def _axis(fs=1000.0, duration=12.0, noise=1e-5, seed=0):
    rng = np.random.default_rng(seed)
    dt = 1.0 / fs
    n = int(round(duration * fs))
    t = np.arange(n) * dt
    freqs = np.array([0.2, 0.5, 1.1, 2.3, 4.7])
    ph = rng.uniform(0.0, 2 * np.pi, freqs.size)
    u = np.sum(4.0 * np.sin(2 * np.pi * freqs * t[:, None] + ph) / (1 + freqs), axis=1)
    M, Fv, Fc, off = (TRUTH[k] for k in ("M", "Fv", "coulomb_friction@tau.Fc", "offset"))
    sub = 40
    h = dt / sub
    x = v = 0.0
    q = np.empty(n)
    for k in range(n):
        q[k] = x
        for _ in range(sub):
            v += h * (u[k] - Fv * v - Fc * np.tanh(v / 1e-4) - off) / M
            x += h * v
    return t, u, q + noise * rng.standard_normal(n)


def _prepared():
    t, u, q = _axis()
    m = get_model("rigid_axis", {"G": 0.0, "Gc": 0.0})   # a linear axis: no gravity terms
    sig = m.prepare(t, {"tau": u, "q": q}, DerivativeFilter(100.0), timing="held")
    return m, sig


def test_runs_are_the_masks_contiguous_rows_clear_of_the_edges():
    mask = np.ones(100, bool)
    mask[40:60] = False
    assert runs(mask, 5, 10) == [(5, 40), (60, 95)]
    assert runs(mask, 5, 36) == []           # both runs shorter than 36 rows
    assert runs(np.zeros(50, bool), 5, 1) == []


def test_simulation_error_recovers_the_axis_from_a_perturbed_start():
    """Started 20 % away from the truth on every parameter, the whole-run simulation error
    (parameters and the run's initial state) brings M, Fv, Fc and the offset back within 2 %
    (measured: M +0.97 %, Fv +0.14 %, offset -1.0 %, Fc -0.96 %); the run's RMS error falls
    by more than 50x."""
    m, sig = _prepared()
    f = fit(m, sig, (CoulombFriction("tau"),), 50, bounded=True)
    g = greybox_of(f, float(sig["dt"]))
    g.set_parameters({k: 1.2 * v for k, v in TRUTH.items()})
    U = np.asarray(sig["tau"], dtype=float)[:, None]
    Y = np.asarray(sig["q_raw"], dtype=float)[:, None]
    n = Y.shape[0]
    theta, info = simulation_refine(g, U, Y, [(50, n - 50)], {"M": (0, np.inf)},
                                    np.var(Y[300:] - Y[:-300], axis=0), "rk4", 300)
    for k, true in TRUTH.items():
        assert theta[k] == pytest.approx(true, rel=0.02), k
    assert info["rms_after"] < info["rms_before"] / 50
    assert all(np.isfinite(v) and v > 0 for v in info["std"].values())


def test_simulation_error_is_chosen_on_held_out_windows(monkeypatch):
    """``estimator`` auto with the simulation-error refinement among the alternatives (the
    last, the costliest): IDIM-LS is biased here (measured: Fc -7 %, offset -9 %), the
    simulation-error refinement predicts the held-out windows better than it (measured
    p 3e-11 at level alpha / 3) and is kept only if it also beats output error there
    (measured: p 0.57, output error kept); the model kept lands within 1 % of the truth.
    Forced, the simulation-error refinement from IDIM-LS lands within 1 % too."""
    m, sig = _prepared()
    monkeypatch.setattr(type(m), "auto_estimators", ("iv", "oe", "sim"))
    # the windows' rollout pinned (the sign held): this is the estimator's test, the rollout's
    # choice has its own (test_validation)
    sel = select(m, sig, [CoulombFriction("tau")], free_run=False, stick_slip="off")
    est = sel.settings["estimator"]
    assert abs(est["idim"]["coulomb_friction@tau.Fc"] - 1.0) > 0.03    # the bias removed
    sim = est["validation"]["simulation error (whole runs)"]
    assert sim["structures_tried"] == 3 and sim["windows"] >= MIN_WINDOWS
    assert sim["level"] == pytest.approx(0.01 / 3) and sim["better"]
    oe = est["validation"]["output error (multiple shooting)"]
    assert oe["better"]
    assert (est["chosen"] == "simulation error (whole runs)") == est["sim_against_oe"]["better"]
    for k, true in TRUTH.items():
        assert sel.final.theta[k] == pytest.approx(true, rel=0.01), k
    forced = select(m, sig, [CoulombFriction("tau")], free_run=False, estimator="sim",
                    stick_slip="off")
    assert forced.settings["estimator"]["chosen"] == "simulation error (whole runs)"
    for k, true in TRUTH.items():
        assert forced.final.theta[k] == pytest.approx(true, rel=0.01), k


def test_free_run_check_names_an_earlier_step_that_simulates_better():
    """The free-run check on held-out blocks: a final model without the axis' dry friction
    drifts (the friction is a quarter of the force's scale) and an earlier step with it is
    named as simulating better (measured: 0.0035 against 0.23, p 6e-10); the final model with
    it is not beaten by the declared model without it. Reported, not acted on
    (selection.free_run_check says why)."""
    m, sig = _prepared()
    cv = BlockedCV(m, sig, 50)
    c = (CoulombFriction("tau"),)
    rep = free_run_check(cv, [("with dry friction", c, m)], ((), m, "idim"), 0.01)
    assert rep["earlier_better"] == ["with dry friction"]
    assert rep["earlier"][0]["score_rich"] < 0.1 * rep["final_score"]
    rep = free_run_check(cv, [("declared model", (), m)], (c, m, "idim"), 0.01)
    assert rep["earlier_better"] == [] and rep["earlier"][0]["p_value"] > 0.5


def test_a_held_out_block_run_is_a_plain_free_run():
    """A held-out block's run: the state fitted on the block's first window, then the model
    simulated open loop to the block's end. Against plain numpy RK4 written here (the force
    and the friction's sign held over each step) from the same fitted state, with the truth's
    parameters: the same pieces to 1e-6 (relative)."""
    m, sig = _prepared()
    cv = BlockedCV(m, sig, 50)
    f = fit(m, sig, (CoulombFriction("tau"),), 50, bounded=True)
    g = greybox_of(f, cv.dt)
    g.set_parameters(TRUTH)
    U = cv.inputs(f.effects)
    Y = cv.Y[:, 0]
    a, b = int(cv.edges[2]), int(cv.edges[3])
    got = cv._block_run(g, U, a, b, 4)
    M, Fv, Fc, off = (TRUTH[k] for k in ("M", "Fv", "coulomb_friction@tau.Fc", "offset"))
    dt, H = cv.dt, cv.horizon

    def run(x, v, k0, steps):
        out = np.empty(steps)
        for j in range(steps):
            u, sg = U[k0 + j, 0], np.sign(v)

            def acc(vv):
                return (u - Fv * vv - Fc * sg - off) / M
            a1 = acc(v)
            a2 = acc(v + 0.5 * dt * a1)
            a3 = acc(v + 0.5 * dt * a2)
            a4 = acc(v + dt * a3)
            x, v = (x + dt / 6 * (v + 2 * (v + 0.5 * dt * a1) + 2 * (v + 0.5 * dt * a2)
                                  + v + dt * a3),
                    v + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4))
            out[j] = x
        return out
    # the state fit: least squares on the first window, by differences as the code does
    x0, v0 = Y[a], (Y[a] - Y[a - 1]) / dt
    base = run(x0, v0, a, H)
    dx = (run(x0 + 1e-6, v0, a, H) - base) / 1e-6
    dv = (run(x0, v0 + 1e-6, a, H) - base) / 1e-6
    d = np.linalg.lstsq(np.column_stack([dx, dv]), Y[a + 1:a + H + 1] - base, rcond=None)[0]
    e = (run(x0 + d[0], v0 + d[1], a, b - a - 1)[H:] - Y[a + H + 1:b]) ** 2 / cv.norm[0]
    want = np.array([np.mean(c) for c in np.array_split(e, 4)])
    assert got == pytest.approx(want, rel=1e-6)
