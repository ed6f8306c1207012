"""The grey-box rollout: the traced tape against the numpy equations (a tape interpreter written
here), the compiled rollout against the numpy one (semi-implicit Euler and RK4) and against an
RK4 written here on that interpreter (switching terms held over each step's stages), RK4
against the closed-form solution of a linear axis under a held input and of an axis that dry
friction stops, batched parameter groups against separate runs, and the output-error Jacobian
against scipy's finite differences."""
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core.models.greybox import trace as tr
from cdam_core.models.greybox.augmented import GreyBox
from cdam_core.models.greybox.effects import (ActuatorDelay, AsymmetricFriction, Backlash,
                                              CoulombFriction, HardeningStiffness)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "residual"))
from joint_generator import Joint, rigid_axis  # noqa: E402


SWITCHING_OPS = ("sign", "gt", "lt", "ge", "le")


def _interpret(tape, outs, x, v, srow, t, th, hold=None, replay=False):
    """A plain numpy interpreter of the tape (independent of the C++ one). ``hold``: a dict
    that receives the switching nodes' values, or with ``replay`` gives them."""
    op, a, b, c = tape.arrays()
    fns = {"add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.divide,
           "neg": np.negative, "sign": np.sign, "tanh": np.tanh, "sin": np.sin, "cos": np.cos,
           "abs": np.abs, "max": np.maximum, "min": np.minimum, "gt": np.greater,
           "lt": np.less, "ge": np.greater_equal, "le": np.less_equal, "pow": np.power,
           "exp": np.exp, "sqrt": np.sqrt}
    W = x.shape[0]
    reg = []
    for i in range(op.size):
        name = tr.OPS[op[i]]
        j = int(c[i])
        if name == "C":
            val = np.full(W, c[i])
        elif name in ("X", "V", "S", "P"):
            val = {"X": x, "V": v, "S": srow, "P": th}[name][:, j]
        elif name == "T":
            val = t
        elif replay and name in SWITCHING_OPS:
            val = hold[i]
        elif b[i] >= 0:
            val = fns[name](reg[a[i]], reg[b[i]])
        else:
            val = fns[name](reg[a[i]])
        reg.append(np.asarray(val, dtype=float) * np.ones(W))
        if hold is not None and not replay and name in SWITCHING_OPS:
            hold[i] = reg[-1]
    return np.array([reg[o] for o in outs])


@pytest.fixture(scope="module")
def axis():
    r = rigid_axis(fs=500.0, duration=6.0, Fc=0.4, offset=0.1, seed=3)
    g = GreyBox("rigid_axis", 0.002, [CoulombFriction("tau"), AsymmetricFriction("tau")],
                cutoff_hz=40.0)
    g.fit(r["tau"][:, None], r["q"][:, None])
    return g, r["tau"][:, None], r["q"][:, None]


@pytest.fixture(scope="module")
def joint():
    r = Joint(fs=500.0, duration=6.0, plane="vertical", Fc=0.02, seed=1).record()
    g = GreyBox("flexible_joint", 0.002,
                [CoulombFriction("tau_m"), Backlash("tau_l", width=0.002),
                 HardeningStiffness("tau_l"), ActuatorDelay("tau_m", delay=0.003)],
                cutoff_hz=40.0)
    U, Y = r["tau_m"][:, None], np.column_stack([r["theta_m"], r["q"]])
    g.fit(U, Y)
    return g, U, Y


@pytest.mark.parametrize("case", ["axis", "joint"])
def test_tape_equals_the_numpy_equations(case, request):
    g, U, Y = request.getfixturevalue(case)
    rng = np.random.default_rng(0)
    u_all, ex_all = g._inputs(U)
    tape, outs = g._trace(u_all, ex_all, {})
    W, m = 50, Y.shape[1]
    x = Y[rng.integers(2, Y.shape[0], W)] + 0.01 * rng.standard_normal((W, m))
    v = rng.standard_normal((W, m))
    v[:5] = 0.0                                   # the sign terms at rest
    k = rng.integers(0, Y.shape[0], W)
    series = np.column_stack(list(u_all.values()))
    th = np.tile([g.theta_[p] for p in g.theta_], (W, 1)) * (1 + 0.1 * rng.random((W, 1)))
    theta = {p: th[:, i] for i, p in enumerate(g.theta_)}
    want = g._errors(g._state(x, v, np.zeros_like(x), {g._m.inputs[0]: series[k, 0]}, {}, k,
                              k * g.dt), {}, theta=theta)
    got = _interpret(tape, outs, x, v, series[k], k * g.dt, th)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.max(np.abs(want)))


def test_untraceable_code_is_refused():
    tape = tr.Tape()
    x = tape.leaf("X", 0)
    with pytest.raises(tr.TraceError):
        if x > 0:      # Python control flow on a simulated value
            pass
    with pytest.raises(tr.TraceError):
        np.asarray(x, dtype=float)
    with pytest.raises(tr.TraceError):
        np.interp(x, [0.0, 1.0], [0.0, 1.0])


def _numpy_only(g):
    """The same model with the compiled path switched off."""
    h = GreyBox.from_dict(g.to_dict())
    h.compiled = False
    return h


@pytest.mark.parametrize("case", ["axis", "joint"])
@pytest.mark.parametrize("integrator", ["euler", "rk4"])
def test_compiled_rollout_equals_numpy(case, integrator, request):
    from cdam_core import _core
    assert hasattr(_core, "greybox_rollout"), "the extension lacks greybox_rollout: rebuild it"
    g, U, Y = request.getfixturevalue(case)
    starts = np.arange(10, Y.shape[0] - 60, 97)
    fast = g.windows(U, Y, starts, 50, integrator=integrator)
    assert g._tapes and all(f is not None and f[3]["ok"] for f in g._tapes.values())
    slow = _numpy_only(g).windows(U, Y, starts, 50, integrator=integrator)
    np.testing.assert_allclose(fast, slow, rtol=1e-10, atol=1e-12)
    # the model kind's free run (semi-implicit Euler), long
    np.testing.assert_allclose(g.predict(U, Y, mode="free_run"),
                               _numpy_only(g).predict(U, Y, mode="free_run"), rtol=1e-9,
                               atol=1e-11)


def test_rk4_windows_against_the_closed_form():
    """M q'' + Fv q' = u with u held over each sample: exact per-sample solution (closed form);
    RK4 (4 ms steps, |dt lambda| = 0.016) matches it to 1e-8 of the motion over 100 samples,
    semi-implicit Euler is off by more than 1e-3 (its half-substep timing error)."""
    M, Fv, dt = 0.5, 2.0, 0.004
    rng = np.random.default_rng(2)
    n = 400
    u = np.repeat(rng.normal(0, 3.0, n // 20), 20)
    a = Fv / M
    x, v = np.zeros(n), np.zeros(n)
    for k in range(n - 1):        # exact solution over one sample of constant input
        vinf = u[k] / Fv
        x[k + 1] = x[k] + vinf * dt + (v[k] - vinf) * (1 - np.exp(-a * dt)) / a
        v[k + 1] = vinf + (v[k] - vinf) * np.exp(-a * dt)
    g = GreyBox("rigid_axis", dt, fixed={"offset": 0.0})
    g._set(g._structure(), {"M": M, "Fv": Fv, "offset": 0.0}, {}, ["M", "Fv"], 1, 1)
    starts = np.arange(5, n - 120, 50)
    x0, v0 = x[starts][:, None], v[starts][:, None]
    Y = x[:, None]
    exact = x[starts[None, :] + np.arange(1, 101)[:, None]]
    rk4 = g.windows(u[:, None], Y, starts, 100, x0, v0, integrator="rk4")[:, :, 0]
    eul = g.windows(u[:, None], Y, starts, 100, x0, v0, integrator="euler")[:, :, 0]
    span = np.max(np.abs(exact - x[starts][None, :]))
    assert np.max(np.abs(rk4 - exact)) < 1e-8 * span
    assert np.max(np.abs(eul - exact)) > 1e-3 * span


def test_parameter_groups_equal_separate_runs(axis):
    g, U, Y = axis
    names = list(g.theta_)
    base = np.array([g.theta_[p] for p in names])
    TH = np.vstack([base, base * 1.05, base * 0.9])
    starts = np.arange(10, Y.shape[0] - 60, 211)
    batched = g.windows(U, Y, np.tile(starts, 3), 40, thetas=TH).reshape(40, 3, -1, 1)
    for j, row in enumerate(TH):
        h = GreyBox.from_dict(g.to_dict()).set_parameters(dict(zip(names, row)))
        np.testing.assert_allclose(batched[:, j], h.windows(U, Y, starts, 40), rtol=1e-12,
                                   atol=1e-14)
    with pytest.raises(ValueError, match="thetas"):
        g.windows(U, Y, starts, 40, thetas=TH[:2, :3])


def test_output_error_jacobian_equals_scipy_differences(axis):
    """The batched forward differences equal scipy's '2-point' Jacobian of the same residual."""
    from scipy.optimize._numdiff import approx_derivative
    from cdam_core.residual import output_error as oe
    g, U, Y = axis
    g = GreyBox.from_dict(g.to_dict())
    starts = np.arange(20, Y.shape[0] - 80, 60)

    def shooting(g, U, Y, starts, thetas=None, samples=False):
        P = g.windows(U, Y, np.tile(starts, 1 if thetas is None else len(thetas)), 50,
                      thetas=thetas).reshape(50, -1, starts.size)
        r = P - Y[starts[None, :] + np.arange(1, 51)[:, None], 0][:, None]
        if samples:
            return np.transpose(r, (1, 2, 0))
        e = np.mean(r ** 2, axis=0)
        return e if thetas is not None else e[0]
    seen = {}

    def spy(fun, x0, jac, bounds, max_nfev, **options):
        # away from the scaled start (where every |x| = 1), M and Fv at |x| < 1
        x = x0 * (0.8 + 0.1 * np.arange(x0.size))
        seen["J"] = jac(x)
        seen["ref"] = approx_derivative(fun, x, method="2-point", rel_step=oe.DIFF_STEP,
                                        bounds=bounds)
        return real(fun, x0, jac=jac, bounds=bounds, max_nfev=1)
    real = oe.least_squares
    try:
        oe.least_squares = spy
        oe.refine(g, U, Y, starts, shooting, {"M": (0, np.inf), "Fv": (0, np.inf)})
    finally:
        oe.least_squares = real
    assert np.all(np.any(seen["ref"] != 0, axis=0))     # every parameter moves the windows
    np.testing.assert_allclose(seen["J"], seen["ref"], rtol=1e-9,
                               atol=1e-12 * np.max(np.abs(seen["ref"])))


def test_validation_windows_by_rk4_score_the_true_structure_lower():
    """Held-out windows of the generator's own structure (rigid axis, no dry friction): the
    RK4 windows' error is below the semi-implicit Euler windows' (whose timing error adds to
    it; measured 8.2e-8 against 1.01e-7, the rest is the IDIM estimates' own error); a bad
    integrator name is refused."""
    from cdam_core.models.greybox.registry import get_model
    from cdam_core.models.greybox.declared import DerivativeFilter
    from cdam_core.models.greybox.estimation import fit
    from cdam_core.residual.validation import BlockedCV
    r = rigid_axis(fs=500.0, duration=20.0, Fc=0.0, offset=0.0, seed=4)
    m = get_model("rigid_axis")
    sig = m.prepare(r["t"], {"tau": r["tau"], "q": r["q"]}, DerivativeFilter(40.0))
    f = fit(m, sig, (), 50)
    scores = {i: float(np.mean(BlockedCV(m, sig, 50, declared=f, integrator=i).scores(())[0]))
              for i in ("euler", "rk4")}
    assert scores["rk4"] < 0.9 * scores["euler"], scores
    with pytest.raises(ValueError, match="integrator"):
        BlockedCV(m, sig, 50, integrator="rk45")


def _rk4_held_here(g, U, Y, starts, steps):
    """RK4 windows on this file's tape interpreter: the inputs held over the sample, the
    switching nodes evaluated at each step's start state and held over its four stages."""
    u_all, ex_all = g._inputs(U)
    tape, outs = g._trace(u_all, ex_all, {})
    series = np.column_stack(list(u_all.values()) + list(ex_all.values()))
    th = np.tile([g.theta_[p] for p in g.theta_], (starts.size, 1))
    inv = g.inertia
    dt = float(g.dt)
    h = dt / g.substeps_
    x, v = Y[starts].astype(float), (Y[starts] - Y[starts - 1]) / dt
    out = np.empty((steps,) + x.shape)
    for j in range(steps):
        k = starts + j
        for _ in range(g.substeps_):
            hold = {}

            def acc(x, v, replay):
                return (inv @ _interpret(tape, outs, x, v, series[k], k * dt, th, hold,
                                         replay)).T
            a1 = acc(x, v, False)
            x2, v2 = x + 0.5 * h * v, v + 0.5 * h * a1
            a2 = acc(x2, v2, True)
            x3, v3 = x + 0.5 * h * v2, v + 0.5 * h * a2
            a3 = acc(x3, v3, True)
            x4, v4 = x + h * v3, v + h * a3
            a4 = acc(x4, v4, True)
            x = x + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
            v = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        out[j] = x
    return out


@pytest.mark.parametrize("case", ["axis", "joint"])
def test_rk4_switching_terms_held_as_written_here(case, request):
    """The compiled RK4 windows (and the package's numpy path) against an RK4 written here on
    the test's own tape interpreter, the switching nodes held from each step's first stage.
    Both fixtures hold a plain sign (Coulomb friction) and the axis a direction test
    (asymmetric friction, v > 0)."""
    g, U, Y = request.getfixturevalue(case)
    assert any(tr.OPS[o] in SWITCHING_OPS for o in g._trace(*g._inputs(U), {})[0].arrays()[0])
    starts = np.arange(10, Y.shape[0] - 60, 211)
    want = _rk4_held_here(g, U, Y, starts, 40)
    got = g.windows(U, Y, starts, 40, integrator="rk4")
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_rk4_dry_friction_held_over_the_step_closed_form():
    """M v' = u_k - Fv v - Fc s_k over each sample, u_k held and s_k = sign(v_k) taken at the
    sample's start (the zero-order hold of the switching term): exact per-sample solution
    (closed form). The input (1.5 sin 2 pi t against Fc 1) lets the axis move and stick in
    turn. RK4 windows (one substep) follow it to 1e-9 of the motion; with the sign evaluated at
    every stage they would not: where the axis sticks the stages see -Fc, +Fc, -Fc, +Fc and
    cancel (a plain RK4 written here, the sign at every stage, is off by more than 1e-3)."""
    M, Fv, Fc, dt, n = 0.5, 0.1, 1.0, 0.002, 1500
    g = GreyBox("rigid_axis", dt, [CoulombFriction("tau")], fixed={"offset": 0.0})
    g._set(g._structure(), {"M": M, "Fv": Fv, "offset": 0.0, "coulomb_friction@tau.Fc": Fc},
           {}, ["M", "Fv", "coulomb_friction@tau.Fc"], 1, 1, substeps=1)
    u = 1.5 * np.sin(2 * np.pi * np.arange(n) * dt)
    a = Fv / M

    def exact():
        x, v = np.zeros(n), np.zeros(n)
        for k in range(n - 1):
            vinf = (u[k] - Fc * np.sign(v[k])) / Fv
            x[k + 1] = x[k] + vinf * dt + (v[k] - vinf) * (1 - np.exp(-a * dt)) / a
            v[k + 1] = vinf + (v[k] - vinf) * np.exp(-a * dt)
        return x, v

    def stagewise():          # plain RK4, the sign evaluated at every stage
        f = lambda k, v: (u[k] - Fv * v - Fc * np.sign(v)) / M   # noqa: E731
        x, v = np.zeros(n), np.zeros(n)
        for k in range(n - 1):
            a1 = f(k, v[k])
            a2 = f(k, v[k] + 0.5 * dt * a1)
            a3 = f(k, v[k] + 0.5 * dt * a2)
            a4 = f(k, v[k] + dt * a3)
            x[k + 1] = x[k] + dt / 6 * (v[k] + 2 * (v[k] + 0.5 * dt * a1)
                                        + 2 * (v[k] + 0.5 * dt * a2) + v[k] + dt * a3)
            v[k + 1] = v[k] + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        return x

    x, v = exact()
    starts = np.array([1, 400, 700])
    want = x[starts[None, :] + np.arange(1, 701)[:, None]]
    span = np.max(np.abs(x))
    for compiled in (True, False):
        h = g if compiled else _numpy_only(g)
        got = h.windows(u[:, None], x[:, None], starts, 700, x[starts][:, None],
                        v[starts][:, None], integrator="rk4")[:, :, 0]
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * span, err_msg=str(compiled))
    assert np.max(np.abs(stagewise() - x)) > 1e-3 * span    # the stage-wise sign's error
