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


def test_fitted_on_half_it_misses_the_other_half_but_not_pulses(emps):
    # README: PULSES repeats DATA_EMPS's trajectory; the linear model fitted on the first half
    # of DATA_EMPS simulates PULSES below the 6 mm target and the unseen second half far worse
    d, p = emps
    h = len(d["qm"]) // 2
    m = Lti(fit(2, False, [(d["vir"][:h], d["qm"][:h])]), 2, False)
    assert score(m, p["vir"], p["qm"]) < 6.0
    assert score(m, d["vir"][h:], d["qm"][h:]) > 10.0


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
