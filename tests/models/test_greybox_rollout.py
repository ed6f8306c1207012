"""The grey-box rollout: the traced tape against the numpy equations (a tape interpreter written
here), the compiled rollout against the numpy one (semi-implicit Euler and RK4) and against an
RK4 with stick-slip written here on that interpreter (switching terms held over each step's
stages, dry friction stopping and holding the motion), RK4 against the closed-form solution of a
linear axis under a held input and against the exact stick-slip solution of an axis with dry
friction, batched parameter groups against separate runs, and the output-error Jacobian against
scipy's finite differences."""
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

# the closed forms here are of a linear axis: no gravity terms
LINEAR = {"G": 0.0, "Gc": 0.0}


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


@pytest.fixture(scope="module")
def joint_two_frictions():
    """Motor PD on a 16384-count motor encoder: the motor and the link at rest in turn, dry
    friction on both."""
    r = Joint(fs=500.0, duration=6.0, control="motor", Fc=0.05, Fc_link=0.03,
              motor_counts=16384, link_counts=16384).record()
    g = GreyBox("flexible_joint", 0.002, [CoulombFriction("tau_m"), CoulombFriction("tau_l")],
                cutoff_hz=20.0)
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
@pytest.mark.parametrize("integrator", ["euler", "rk4", "rk4-stickslip"])
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
    g = GreyBox("rigid_axis", dt, fixed={"offset": 0.0, **LINEAR})
    g._set(g._structure(), {"M": M, "Fv": Fv, "offset": 0.0, **LINEAR}, {}, ["M", "Fv"], 1, 1)
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


def _sticky_here(tape, n):
    """The coordinates j with a switching node that depends on the velocity leaf V j and on no
    other velocity (from the tape's graph: this file's rule, not the package's probing)."""
    op, a, b, c = tape.arrays()
    deps = []
    for i in range(op.size):
        name = tr.OPS[op[i]]
        if name == "V":
            d = {int(c[i])}
        elif name in ("C", "X", "S", "T", "P"):
            d = set()
        else:
            d = deps[a[i]] | (deps[b[i]] if b[i] >= 0 else set())
        deps.append(d)
    out = np.zeros(n, dtype=bool)
    for i in range(op.size):
        if tr.OPS[op[i]] in SWITCHING_OPS and len(deps[i]) == 1:
            out[next(iter(deps[i]))] = True
    return out


def _rk4_stick_slip_here(g, U, Y, starts, steps):
    """RK4 windows on this file's tape interpreter: the inputs held over the sample, the
    switching nodes evaluated at each step's start state and held over its four stages, and
    stick-slip written here lane by lane: a sticking coordinate at rest (v exactly 0) is
    evaluated at v = +1e-150 and -1e-150 (a+, a-); a+ <= 0 <= a- holds it at rest over the step
    with the switching nodes interpolated between the two sides by Filippov's weight
    a- / (a- - a+) (0.5 when both are 0); otherwise it moves to the side of a+ + a- (ties +),
    the switches taken from that side; a velocity that ends a step against the step's
    direction is set to 0, its position to x0 + h v0^2 / (2 (v0 - v1)), and the rest of the
    step, h v1 / (v1 - v0), is spent at rest or at the broken-away side's acceleration a from
    the stop (x += a left^2 / 2, v = a left), by the same rule as at a step's start; a
    coordinate held over a step that the end state no longer holds broke away where that
    side's acceleration (a0 at the start, a at the end) crossed zero: tau = h a / (a - a0),
    v = a tau / 2, x += a tau^2 / 6."""
    u_all, ex_all = g._inputs(U)
    tape, outs = g._trace(u_all, ex_all, {})
    series = np.column_stack(list(u_all.values()) + list(ex_all.values()))
    th = np.tile([g.theta_[p] for p in g.theta_], (starts.size, 1))
    inv = g.inertia
    dt = float(g.dt)
    h = dt / g.substeps_
    W, n = starts.size, Y.shape[1]
    sticky = _sticky_here(tape, n)
    x, v = Y[starts].astype(float), (Y[starts] - Y[starts - 1]) / dt
    out = np.empty((steps,) + x.shape)
    events = {"stuck": 0, "moved off": 0, "stopped": 0}
    for j in range(steps):
        k = starts + j

        def acc(x, v, hold, replay=False):
            return (inv @ _interpret(tape, outs, x, v, series[k], k * dt, th, hold, replay)).T
        for _ in range(g.substeps_):
            x0, v0 = x.copy(), v.copy()
            direction = np.sign(v)
            stuck = np.zeros((W, n), dtype=bool)
            start_limits = np.zeros((W, n, 2))
            hold = {}
            zero = sticky[None, :] & (v == 0.0)
            if not zero.any():
                a1 = acc(x, v, hold)
            else:
                vp = np.where(zero, 1e-150, v)
                a_p, hold_p = acc(x, vp, hold), dict(hold)
                a1 = a_p.copy()
                for c in range(n):
                    if not zero[:, c].any():
                        continue
                    vm = vp.copy()
                    vm[zero[:, c], c] = -1e-150
                    hold_m = {}
                    a_m = acc(x, vm, hold_m)
                    for lane in np.flatnonzero(zero[:, c]):
                        ap, am = a_p[lane, c], a_m[lane, c]
                        start_limits[lane, c] = ap, am
                        if ap <= 0.0 <= am:
                            lam = am / (am - ap) if am > ap else 0.5
                            w, stuck[lane, c], direction[lane, c] = 1.0 - lam, True, 0.0
                            events["stuck"] += 1
                        elif ap + am >= 0.0:
                            w, direction[lane, c] = 0.0, 1.0
                        else:
                            w, direction[lane, c] = 1.0, -1.0
                        events["moved off"] += not stuck[lane, c]
                        a1[lane] = a1[lane] + w * (a_m[lane] - a_p[lane])
                        for node in hold:
                            hold[node][lane] = hold[node][lane] + w * (hold_m[node][lane]
                                                                      - hold_p[node][lane])
                a1[stuck] = 0.0
            x2, v2 = x + 0.5 * h * v, v + 0.5 * h * a1
            a2 = acc(x2, v2, hold, True)
            a2[stuck] = 0.0
            x3, v3 = x + 0.5 * h * v2, v + 0.5 * h * a2
            a3 = acc(x3, v3, hold, True)
            a3[stuck] = 0.0
            x4, v4 = x + h * v3, v + h * a3
            a4 = acc(x4, v4, hold, True)
            a4[stuck] = 0.0
            x = x + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
            v = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
            crossed = sticky[None, :] & (direction * v < 0.0)
            left = np.zeros((W, n))
            for lane, c in zip(*np.nonzero(crossed)):
                gap = v0[lane, c] - v[lane, c]
                x[lane, c] = x0[lane, c] + 0.5 * h * v0[lane, c] * v0[lane, c] / gap
                left[lane, c] = -h * v[lane, c] / gap
                v[lane, c] = 0.0
                events["stopped"] += 1
            ends = crossed | stuck
            if ends.any():   # the step's end: the rest after a stop, a breakaway within a hold
                vp = np.where(ends, 1e-150, v)
                a_p = acc(x, vp, {})
                a_end = a_p.copy()
                held_end = np.zeros((W, n), dtype=bool)
                plus_end = np.zeros((W, n), dtype=bool)
                for c in range(n):
                    if not ends[:, c].any():
                        continue
                    vm = vp.copy()
                    vm[ends[:, c], c] = -1e-150
                    a_m = acc(x, vm, {})
                    for lane in np.flatnonzero(ends[:, c]):
                        ap, am = a_p[lane, c], a_m[lane, c]
                        if ap <= 0.0 <= am:
                            w = 1.0 - (am / (am - ap) if am > ap else 0.5)
                            held_end[lane, c] = True
                        else:
                            w = 0.0 if ap + am >= 0.0 else 1.0
                            plus_end[lane, c] = w == 0.0
                        a_end[lane] = a_end[lane] + w * (a_m[lane] - a_p[lane])
                for lane, c in zip(*np.nonzero(ends)):
                    a = 0.0 if held_end[lane, c] else a_end[lane, c]
                    if crossed[lane, c]:
                        x[lane, c] = x[lane, c] + 0.5 * a * left[lane, c] * left[lane, c]
                        v[lane, c] = a * left[lane, c]
                        events["stuck" if held_end[lane, c] else "moved off"] += 1
                    elif not held_end[lane, c]:      # broke away where its force crossed
                        a0 = start_limits[lane, c, 0 if plus_end[lane, c] else 1]
                        tau = h * a / (a - a0)
                        x[lane, c] = x[lane, c] + a * tau * tau / 6.0
                        v[lane, c] = 0.5 * a * tau
                        events["moved off"] += 1
        out[j] = x
    return out, events


@pytest.mark.parametrize("case", ["axis", "joint", "joint_two_frictions"])
def test_rk4_stick_slip_as_written_here(case, request):
    """The compiled RK4 windows and the package's numpy path against the RK4 with stick-slip
    written here on the test's own tape interpreter (:func:`_rk4_stick_slip_here`). The axis
    holds a plain sign and a direction test (asymmetric friction, v > 0), the joints a plain
    sign on the motor, and on the motor and the link; the windows start from quantised
    encoders, so many start at rest, stick and break away."""
    g, U, Y = request.getfixturevalue(case)
    tape = g._trace(*g._inputs(U), {})[0]
    assert np.array_equal(g._sticky(*g._inputs(U), {}), _sticky_here(tape, Y.shape[1]))
    starts = np.arange(10, Y.shape[0] - 60, 97)
    want, events = _rk4_stick_slip_here(g, U, Y, starts, 40)
    if case != "joint":     # the open-loop joint's motor never comes to rest in its windows
        assert min(events.values()) >= 3, events
    for h in (g, _numpy_only(g)):
        got = h.windows(U, Y, starts, 40, integrator="rk4-stickslip")
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def _exact_stick_slip(u, dt, M, Fv, Fc, x0=0.0, v0=0.0):
    """M v' = u_k - Fv v - Fc sign(v) with u_k held over each sample, at rest held by a static
    friction up to Fc: the exact solution, event by event. While moving in direction s the
    velocity relaxes to vinf = (u_k - Fc s) / Fv, v(t) = vinf + (v - vinf) e^(-Fv t / M); it
    reaches 0 at t = M / Fv ln((v - vinf) / -vinf) when vinf is on the other side; at rest it
    stays there while |u_k| <= Fc and starts in the direction of u_k otherwise."""
    n = len(u)
    a = Fv / M
    x, v = np.zeros(n), np.zeros(n)
    x[0], v[0] = x0, v0
    for k in range(n - 1):
        xx, vv, left = x[k], v[k], dt
        while left > 0.0:
            if vv == 0.0 and abs(u[k]) <= Fc:
                break
            s = np.sign(vv) if vv != 0.0 else np.sign(u[k])
            vinf = (u[k] - Fc * s) / Fv
            t_stop = np.log((vv - vinf) / -vinf) / a if vinf * s < 0 else np.inf
            t = min(t_stop, left)
            xx = xx + vinf * t + (vv - vinf) * (1 - np.exp(-a * t)) / a
            vv = 0.0 if t == t_stop else vinf + (vv - vinf) * np.exp(-a * t)
            left -= t
        x[k + 1], v[k + 1] = xx, vv
    return x, v


def _held_from(u, dt, M, Fv, Fc, x0, v0):
    """The sign of v held over each sample, solved exactly per sample from (x0, v0) at the
    first row of ``u``."""
    a = Fv / M
    n = len(u)
    xs, vs = np.zeros(n), np.zeros(n)
    xs[0], vs[0] = x0, v0
    for k in range(n - 1):
        vinf = (u[k] - Fc * np.sign(vs[k])) / Fv
        xs[k + 1] = xs[k] + vinf * dt + (vs[k] - vinf) * (1 - np.exp(-a * dt)) / a
        vs[k + 1] = vinf + (vs[k] - vinf) * np.exp(-a * dt)
    return xs


@pytest.mark.parametrize("force", ["sticks", "reverses"])
def test_rk4_stick_slip_against_the_exact_solution(force):
    """A mass with Coulomb and viscous friction (M 0.5, Fv 0.1, Fc 1), the force held over each
    2 ms sample, against the exact event-by-event solution written here
    (:func:`_exact_stick_slip`). "sticks": 1.5 sin 2 pi t + 0.3 sin 2 pi 3.3 t keeps falling
    inside the Coulomb level: at rest 20 % of the time, 11 stops. "reverses": a +-3 square
    wave (plus 0.5 sin 2 pi 0.4 t) drives the mass back through zero speed 15 times without
    rest. The RK4 windows with stick-slip follow it to 1e-7 / 1e-5 of the motion with one
    substep and 1e-9 / 1e-6 with four (measured 9.6e-9 / 6.5e-7 and 1.0e-10 / 4.0e-8, windows
    of 1200 samples from three starts); the
    plain sign held over each step (what the windows did before: its exact per-sample
    solution, written here) is off by more than 5 % / 1 % (measured 7.8 % and 1.7 %: the
    stuck mass chatters and creeps; a reversal keeps the old friction for a step)."""
    M, Fv, Fc, dt, n = 0.5, 0.1, 1.0, 0.002, 3000
    t = np.arange(n) * dt
    if force == "sticks":
        u = 1.5 * np.sin(2 * np.pi * t) + 0.3 * np.sin(2 * np.pi * 3.3 * t)
        tol, off = (1e-7, 1e-9), 0.05
    else:
        u = 3.0 * np.sign(np.sin(2 * np.pi * 1.3 * t + 0.1)) + 0.5 * np.sin(2 * np.pi * 0.4 * t)
        tol, off = (1e-5, 1e-6), 0.01
    x, v = _exact_stick_slip(u, dt, M, Fv, Fc)
    moving = np.sign(v[v != 0.0])
    if force == "sticks":
        assert 0.1 < np.mean(v == 0.0) < 0.5
        assert np.sum(np.diff((v == 0.0).astype(int)) == 1) >= 5      # stops
    else:
        assert np.mean(v == 0.0) < 0.01 and np.sum(moving[1:] != moving[:-1]) >= 10
    xs = _held_from(u, dt, M, Fv, Fc, 0.0, 0.0)
    starts = np.array([1, 700, 1500])
    rows = starts[None, :] + np.arange(1, 1201)[:, None]
    span = np.ptp(x)
    assert np.max(np.abs(xs[rows] - x[rows])) > off * span
    for substeps, tl in zip((1, 4), tol):
        g = GreyBox("rigid_axis", dt, [CoulombFriction("tau")], fixed={"offset": 0.0, **LINEAR})
        g._set(g._structure(), {"M": M, "Fv": Fv, "offset": 0.0, **LINEAR,
                                "coulomb_friction@tau.Fc": Fc},
               {}, ["M", "Fv", "coulomb_friction@tau.Fc"], 1, 1, substeps=substeps)
        for h in (g, _numpy_only(g)):
            got = h.windows(u[:, None], x[:, None], starts, 1200, x[starts][:, None],
                            v[starts][:, None], integrator="rk4-stickslip")[:, :, 0]
            np.testing.assert_allclose(got, x[rows], rtol=0, atol=tl * span,
                                       err_msg=f"substeps {substeps}, compiled {h.compiled}")
            # the held rollout ("rk4", the other choice) is the sign held over each step
            if substeps == 1:
                held = h.windows(u[:, None], x[:, None], starts, 1200, x[starts][:, None],
                                 v[starts][:, None], integrator="rk4")[:, :, 0]
                xh = np.column_stack([_held_from(u[s:], dt, M, Fv, Fc, x[s], v[s])[1:1201]
                                      for s in starts])
                np.testing.assert_allclose(held, xh, rtol=0, atol=1e-6 * span)


def test_which_coordinates_stick():
    """A coordinate sticks where a switching term jumps at its zero velocity: a plain sign on
    the motor (and the link), the direction test of an asymmetric friction; not a smoothed sign
    (tanh, continuous), a backlash (a switch on the deflection, a position) or a model without
    dry friction."""
    def sticky(name, effects):
        g = GreyBox(name, 0.002, effects)
        m = g._structure()
        theta = {p: 1.0 for p in _parameter_names_of(g, m)}
        g._set(m, theta, {}, list(theta), 1, len(m.positions))
        return g._sticky(*g._inputs(np.zeros((10, 1))), {}).tolist()
    assert sticky("rigid_axis", [CoulombFriction("tau")]) == [True]
    assert sticky("rigid_axis", [CoulombFriction("tau", eps=0.01)]) == [False]
    assert sticky("rigid_axis", [CoulombFriction("tau"), AsymmetricFriction("tau")]) == [True]
    assert sticky("rigid_axis", []) == [False]
    assert sticky("flexible_joint", [CoulombFriction("tau_m")]) == [True, False]
    assert sticky("flexible_joint", [CoulombFriction("tau_m"), CoulombFriction("tau_l")]) == \
        [True, True]
    assert sticky("flexible_joint", [Backlash("tau_l", width=0.01)]) == [False, False]


def _parameter_names_of(g, m):
    from cdam_core.models.greybox.augmented import _parameter_names
    return sorted(_parameter_names(m, g.effects, g))


def test_sine_and_cosine_of_one_operand_in_any_order():
    """The kernel evaluates sin and cos of the same node together (sincos): a tape with cos
    before sin of x, a second sin of x (left unpaired), sin of v and cos of a sum, one
    semi-implicit Euler step of every lane against numpy."""
    from cdam_core import _core
    ops, a, b, c = [], [], [], []

    def node(op, x=-1, y=-1, k=0.0):
        ops.append(tr.OPS.index(op))
        a.append(x)
        b.append(y)
        c.append(k)
        return len(ops) - 1
    x, v = node("X", k=0), node("V", k=0)
    p = [node("P", k=i) for i in range(5)]
    cx, sx, sx2, sv = node("cos", x), node("sin", x), node("sin", x), node("sin", v)
    cs = node("cos", node("add", x, v))
    terms = [node("mul", p[i], t) for i, t in enumerate((cx, sx, sx2, sv, cs))]
    acc = terms[0]
    for t in terms[1:]:
        acc = node("add", acc, t)
    rng = np.random.default_rng(4)
    L, h = 70, 0.01
    th = rng.standard_normal((L, 5))
    x0, v0 = 3.0 * rng.standard_normal((L, 1)), rng.standard_normal((L, 1))
    got, div = _core.greybox_rollout(
        np.array(ops, np.int32), np.array(a, np.int32), np.array(b, np.int32),
        np.array(c, float), np.array([acc], np.int32), np.zeros((3, 1)), th,
        np.ones((L, 1, 1)), x0, v0, np.zeros(L, np.int64), 1, 1, False, h, 0.0, False)
    X, V = x0[:, 0], v0[:, 0]
    want_acc = (th[:, 0] * np.cos(X) + th[:, 1] * np.sin(X) + th[:, 2] * np.sin(X)
                + th[:, 3] * np.sin(V) + th[:, 4] * np.cos(X + V))
    want = X + h * (V + h * want_acc)
    assert div == -1
    np.testing.assert_allclose(got[:, 0], want, rtol=1e-14, atol=1e-15)
