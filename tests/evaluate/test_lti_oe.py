"""The linear output-error baseline of the EMPS benchmark (evaluate.lti_oe)."""
import numpy as np
import pytest
from scipy.signal import dlsim, tf2ss

from cdam_core.evaluate.lti_oe import Lti, fit, score
from cdam_core.record.realdata.emps import load_emps


@pytest.fixture(scope="module")
def emps():
    return load_emps("DATA_EMPS"), load_emps("DATA_EMPS_PULSES")


@pytest.fixture(scope="module")
def second_order(emps):
    d, _ = emps
    return Lti(fit(2, False, [(d["vir"], d["qm"])]), 2, False)


def test_free_run_is_the_transfer_function_simulated_by_dlsim(emps, second_order):
    # independent simulation: scipy's state-space form of B/A, the initial state fitted to the
    # protocol's 20-sample window by least squares on dlsim's free responses
    _, p = emps
    th = second_order.theta
    a, b = np.r_[1.0, th[:2]], th[2:5]
    A, B, C, D = tf2ss(b, a)
    u, y = p["vir"], p["qm"]
    forced = dlsim((A, B, C, D, 1.0), u)[1][:, 0]
    free = np.column_stack([dlsim((A, B, C, D, 1.0), np.zeros(20), x0=e)[1][:, 0]
                            for e in np.eye(2)])
    x0 = np.linalg.lstsq(free, y[:20] - forced[:20], rcond=None)[0]
    ref = forced + dlsim((A, B, C, D, 1.0), np.zeros(len(u)), x0=x0)[1][:, 0]
    got = second_order.predict(u[:, None], y[:, None])[:, 0]
    assert np.max(np.abs(got - ref)) < 1e-6 * np.max(np.abs(y))


def test_pulses_score_below_the_target_and_the_naive_run(emps, second_order):
    _, p = emps
    u, y = p["vir"], p["qm"]
    rmse = score(second_order, u, y)
    naive = 1000 * np.sqrt(np.mean((y[20:] - y[19]) ** 2))   # qm held at the window's end
    assert rmse < 6.0          # the target; Champneys et al. 2024 publish 5.53 mm
    assert rmse < naive / 10


def test_fit_rejects_bad_input():
    u = np.zeros(100)
    with pytest.raises(ValueError, match="n: must be"):
        fit(0, False, [(u, u)])
    with pytest.raises(ValueError, match="segments: u and y"):
        fit(2, False, [(u, u[:50])])
    with pytest.raises(ValueError, match="too short"):
        fit(2, False, [(u[:25], u[:25])])
    with pytest.raises(ValueError, match="NaN"):
        fit(2, False, [(np.full(100, np.nan), u)])


def _rigid_free_run(th, u, y0, y1, dt, gtau):
    """M q'' = gtau u - Fv q' - Fc sign(q') + c by semi-implicit Euler from two samples."""
    M, Fv, Fc, c = th
    q = np.empty(len(u))
    q[0], q[1] = y0, y1
    v = (y1 - y0) / dt
    for k in range(1, len(u) - 1):
        v += dt * (gtau * u[k] - Fv * v - Fc * np.sign(v) + c) / M
        q[k + 1] = q[k] + dt * v
    return q


def test_fitted_on_half_it_loses_the_other_half_to_the_physical_model(emps):
    # README: on DATA_EMPS itself the physical model (M, Fv, Fc, offset), fitted by simulation
    # error on one half, simulates the other half better than the linear model fitted on the
    # same half (measured, session 18: 6.04 / 6.09 mm against 6.75 / 9.44 mm)
    from scipy.optimize import least_squares
    d, _ = emps
    u, y = d["vir"], d["qm"]
    dt, gt = float(np.mean(np.diff(d["t"]))), float(d["gtau"])
    h = len(y) // 2
    for (a, b), (c, e) in (((0, h), (h, len(y))), ((h, len(y)), (0, h))):
        lti = score(Lti(fit(2, False, [(u[a:b], y[a:b])]), 2, False), u[c:e], y[c:e])
        ph = least_squares(lambda th: _rigid_free_run(th, u[a:b], y[a], y[a + 1], dt, gt)
                           - y[a:b], [95.0, 200.0, 20.0, 0.0], x_scale="jac").x
        q = _rigid_free_run(ph, u[c:e], y[c], y[c + 1], dt, gt)
        phys = 1000 * np.sqrt(np.mean((q[20:] - y[c:e][20:]) ** 2))
        assert phys < lti
        assert phys < 7.0


def test_model_and_score_reject_bad_input(second_order):
    from cdam_core.evaluate.lti_oe import blocks, emps_lti_baseline
    x = np.zeros((100, 1))
    with pytest.raises(ValueError, match="mode"):
        second_order.predict(x, x, mode="one_step")
    with pytest.raises(ValueError, match="U, Y"):
        second_order.predict(x, x[:50])
    with pytest.raises(ValueError, match="Y: needs"):
        second_order.predict(x[:20], x[:20])
    with pytest.raises(ValueError, match="u, y"):
        score(second_order, x, x)
    with pytest.raises(ValueError, match="n_blocks"):
        blocks(1, 1000)
    with pytest.raises(ValueError, match="orders"):
        emps_lti_baseline(orders=(0, 2))


# Two order searches on DATA_EMPS's four held-out blocks (emps_lti_baseline's table, mm),
# measured in session 17 with the simulation computed two ways that differ by 1e-11 relative
# (forced + free response as two filter runs, then as one): the well-determined structures
# agree to 0.05 mm, the high orders land in other local optima (n 5 with offset 15.93 -> 12.91).
# A plain minimum chose n 2 (PULSES 5.30 mm) from the first and n 5 with offset (21.2 mm) from
# the second.
_SEARCH_A = {(1, False): (18.63, 16.81, 18.24, 18.30), (2, False): (15.62, 10.31, 19.50, 13.55),
             (3, False): (28.33, 16.88, 17.57, 13.42), (4, False): (27.28, 9.98, 141.82, 13.49),
             (5, False): (24.08, 9.69, 6.21, 19.90), (1, True): (18.56, 8.06, 17.66, 35.41),
             (2, True): (9.58, 10.24, 37.48, 13.55), (3, True): (24.44, 10.70, 17.57, 14.61),
             (4, True): (27.28, 10.36, 145.28, 18.54), (5, True): (8.43, 17.40, 20.03, 17.87)}
_SEARCH_B = {(1, False): (18.63, 16.81, 18.24, 18.30), (2, False): (15.63, 10.31, 19.50, 13.55),
             (3, False): (28.33, 18.63, 17.57, 13.43), (4, False): (27.32, 9.98, 144.87, 13.49),
             (5, False): (24.12, 9.69, 14.34, 13.96), (1, True): (18.56, 8.06, 17.66, 35.41),
             (2, True): (9.57, 10.23, 37.39, 13.55), (3, True): (24.33, 10.73, 17.57, 14.60),
             (4, True): (13.67, 10.31, 148.58, 18.59), (5, True): (9.19, 10.00, 14.34, 18.09)}


def _table(search):
    return [(float(np.mean(v)), n, o, list(v)) for (n, o), v in search.items()]


@pytest.mark.parametrize("search", [_SEARCH_A, _SEARCH_B], ids=["two runs", "one run"])
def test_order_choice_does_not_follow_differences_the_blocks_cannot_resolve(search):
    from statistics import mean, stdev

    from cdam_core.evaluate.lti_oe import choose
    table = _table(search)
    # the rule by hand: the best mean, its blocks' standard error, the fewest parameters
    # (2n + 1 + offset) among the structures within it
    best = min(search, key=lambda k: mean(search[k]))
    se = stdev(search[best]) / 2.0
    ok = [k for k in search if mean(search[k]) <= mean(search[best]) + se]
    want = min(ok, key=lambda k: 2 * k[0] + 1 + k[1])
    assert want == (2, False)                      # both searches: the order-2 model
    assert choose(table)[1:3] == want
    assert min(table)[1:3] == ((2, False) if search is _SEARCH_A else (5, True))  # the minimum


def test_choose_rejects_a_table_without_a_finite_score():
    from cdam_core.evaluate.lti_oe import choose
    with pytest.raises(ValueError, match="no structure has a finite"):
        choose([(np.inf, 1, False, [np.inf, np.inf])])
    with pytest.raises(ValueError, match="no structure has a finite"):
        choose([])


def _free_run_complex_step(theta, n, offset, u, y):
    """The free run of evaluate.lti_oe written with analytic operations only (the window's
    initial state by the normal equations with a plain transpose), so that a complex step
    in theta gives its exact derivative: Im f(theta + i h e_j) / h."""
    from scipy.signal import lfilter
    a = np.r_[1.0, theta[:n]]
    b = theta[n:2 * n + 1]
    c = theta[2 * n + 1] if offset else 0.0
    k = 20
    bb = np.r_[b, np.zeros(max(0, len(a) - len(b)))]
    free = lfilter(bb, a, np.zeros((n, k), complex), axis=-1, zi=np.eye(n, dtype=complex))[0].T
    x0 = np.linalg.solve(free.T @ free, free.T @ (y[:k] - lfilter(b, a, u[:k] + c)))
    return lfilter(b, a, u + c, zi=x0)[0]


@pytest.mark.parametrize("n,offset", [(1, False), (1, True), (2, False), (2, True), (3, True)])
def test_jacobian_of_the_free_run_equals_the_complex_step_derivative(emps, n, offset):
    # EMPS's input and output (a pole at 1 over 6000 samples: where finite differences fail)
    from cdam_core.evaluate.lti_oe import _arx_init, _simulate_jac
    d, _ = emps
    u, y = d["vir"][:6000], d["qm"][:6000]
    th = _arx_init(n, offset, [(u, y)])
    if offset:
        th[-1] = 0.3
    s, J = _simulate_jac(th, n, offset, u, y[:20])
    h = 1e-30
    ref = np.column_stack([_free_run_complex_step(th + 1j * h * e, n, offset, u, y).imag / h
                           for e in np.eye(len(th))])
    assert np.max(np.abs(s - _free_run_complex_step(th, n, offset, u, y).real)) < \
        1e-9 * np.max(np.abs(y))
    assert np.max(np.abs(J - ref)) < 1e-8 * np.max(np.abs(ref))


def test_order_two_fit_on_data_emps_is_a_stationary_point(emps, second_order):
    # the gradient J'r of the simulation error at the fitted coefficients, J by complex step:
    # small against |J| |r| (a fit stopped early, as with finite differences, is not)
    d, _ = emps
    u, y = d["vir"], d["qm"]
    th, h = second_order.theta, 1e-30
    r = _free_run_complex_step(th, 2, False, u, y).real - y
    J = np.column_stack([_free_run_complex_step(th + 1j * h * e, 2, False, u, y).imag / h
                         for e in np.eye(len(th))])
    cos = np.abs(J.T @ r) / (np.linalg.norm(J, axis=0) * np.linalg.norm(r))
    assert np.max(cos) < 1e-5


def _oe_record(seed, N=3000):
    """An output-error system simulated by a plain loop (not lfilter): poles 0.97 and 0.85,
    a PRBS-like input held over 5 samples, white noise on the output only."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.choice([-1.0, 1.0], N // 5), 5)
    a1, a2 = -(0.97 + 0.85), 0.97 * 0.85
    b0, b1, b2 = 0.0, 0.02, 0.015
    x = np.zeros(N)
    for t in range(N):
        x[t] = (-a1 * x[t - 1] - a2 * x[t - 2] if t >= 2 else 0.0) + \
            b1 * (u[t - 1] if t >= 1 else 0.0) + b2 * (u[t - 2] if t >= 2 else 0.0) + b0 * u[t]
    return u, x + 0.01 * np.std(x) * rng.standard_normal(N), (a1, a2, b0, b1, b2)


@pytest.mark.parametrize("seed", [0, 1])
def test_select_finds_the_order_of_an_independent_output_error_system(seed):
    from cdam_core.evaluate.lti_oe import select
    u, y, (a1, a2, b0, b1, b2) = _oe_record(seed)
    m, table, row = select(u, y, orders=(1, 2, 3, 4, 5), patience=2, log=lambda *a: None)
    assert (m.n, m.offset) == (2, False)
    assert np.allclose(m.theta, [a1, a2, b0, b1, b2], atol=2e-3)
    # the stopping rule by hand: orders upward until `patience` (2) orders in a row do not
    # lower the best held-out mean, or the last order
    means = {}
    for v, n, o, _ in table:
        means.setdefault(n, []).append(v)
    tried = sorted(means)
    assert tried == list(range(1, len(tried) + 1)) and all(len(means[n]) == 2 for n in tried)
    best, stale, stop = np.inf, 0, 5
    for n in range(1, 6):
        low = min(means[n])
        stale = 0 if low < best else stale + 1
        best = min(best, low)
        if stale == 2:
            stop = n
            break
    assert tried[-1] == stop


def test_select_rejects_bad_input():
    from cdam_core.evaluate.lti_oe import select
    u = np.zeros(1000)
    with pytest.raises(ValueError, match="patience"):
        select(u, u, patience=0)
    with pytest.raises(ValueError, match="u, y"):
        select(u, u[:500])
    with pytest.raises(ValueError, match="orders"):
        select(u, u, orders=())
