"""Integer overflow on sizes, lags and parameter counts (issue 24 item 2): every huge lag or
size passed to ``_core`` is a ValueError naming the argument, never a wrapped size, a crash or
silently wrong output. Each call runs in a child interpreter (tests/robust/_subproc.py), so a
segfault fails the test instead of killing pytest.

The boundary values are worked out here from the closed forms: t0 = max(na, nk + nb - 1) must
fit in 32 bits, D = i h + h + h m + m in 64 bits.
"""
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _subproc import run_call  # noqa: E402

INT_MAX = 2 ** 31 - 1
# With i = m = 1, D = 3 h + 1; h = (2**64 + 2) / 3 makes 3 h + 1 = 2**64 + 3, i.e. D wraps to 3
# in 64-bit arithmetic, so a 3-element theta used to pass the length check.
H_WRAPS_TO_3 = (2 ** 64 + 2) // 3
assert 3 * H_WRAPS_TO_3 + 1 == 2 ** 64 + 3 and H_WRAPS_TO_3 < 2 ** 63

U10 = "U = np.linspace(0, 1, 10).reshape(-1, 1); Y = np.cos(U)"


def expect_value_error(res, *names):
    assert res["returncode"] == 0, f"child crashed ({res['returncode']}): {res['message']}"
    assert res["type"] == "ValueError", res
    for name in names:
        assert name in res["message"], res


@pytest.mark.parametrize("na, nb, nk, name", [
    (1, 2, INT_MAX, "nk"),            # the case: nk + nb - 1 = 2**31
    (0, INT_MAX, 5, "nb"),
    (1, 1, 2 ** 40, "nk"),            # not even a 32-bit lag
    (2 ** 33, 1, 0, "na"),
    (1, -1, 0, "nb"),
])
def test_narx_regressors_huge_lags(na, nb, nk, name):
    res = run_call(f"_core.narx_regressors(U, Y, {na}, {nb}, {nk})", setup=U10)
    expect_value_error(res, name)


def test_narx_regressors_largest_valid_t0_is_too_long_for_the_record():
    # nk + nb - 1 = 2**31 - 1 exactly: representable, so the record (10 samples) is too short
    res = run_call(f"_core.narx_regressors(U, Y, 1, 1, {INT_MAX})", setup=U10)
    expect_value_error(res, "U", f"t0 = max(na, nk + nb - 1) = {INT_MAX}")


@pytest.mark.parametrize("na, nb, nk, name", [
    (1, 2, INT_MAX, "nk"),
    (0, INT_MAX, 2, "nb"),
    (1, 2, 2 ** 62, "nk"),
])
def test_narx_simulate_huge_lags(na, nb, nk, name):
    res = run_call(f"_core.narx_simulate(np.zeros(7), U, np.zeros((0, 1)), 1, 'tansig', "
                   f"{na}, {nb}, {nk})", setup=U10)
    expect_value_error(res, name)


def test_narx_simulate_hidden_that_wraps_the_parameter_count():
    # regressors na m + nb i = 2, so D = 2 h + h + h + 1 = 4 h + 1; h = 2**62 wraps D to 1
    res = run_call(f"_core.narx_simulate(np.zeros(1), U, np.zeros((1, 1)), {2 ** 62}, "
                   "'tansig', 1, 1, 0)", setup=U10)
    expect_value_error(res, "hidden")


def test_mlp_num_params_overflow_is_refused():
    res = run_call(f"_core.mlp_num_params({2 ** 62}, 8, 4)")  # used to return 44
    expect_value_error(res, "inputs", "overflows")
    res = run_call(f"_core.mlp_num_params(1, {H_WRAPS_TO_3}, 1)")
    expect_value_error(res, "hidden", "overflows")
    # the largest network whose count fits: i = m = 1, 3 h + 1 <= 2**63 - 1
    h = (2 ** 63 - 2) // 3
    res = run_call(f"_core.mlp_num_params(1, {h}, 1)")
    assert res["type"] == "ok" and res["message"] == str(3 * h + 1), res


@pytest.mark.parametrize("call", [
    "_core.mlp_forward(np.zeros(3), X, {h}, 1)",
    "_core.mlp_jacobian(np.zeros(3), X, {h}, 1)",
    "_core.mlp_mse_gradient(np.zeros(3), X, T, {h})",
    "_core.mlp_jtj(np.zeros(3), X, T, {h})",
    "_core.train_lm(np.zeros(3), X, T, {h}, epochs=1)",
    "_core.train_gd(np.zeros(3), X, T, {h}, epochs=1)",
    "_core.bp_fitness(np.zeros(3), X, T, {h})",
    "_core.optimise('boa', 'bp', X=X, T=T, hidden={h})",
])
def test_a_hidden_size_that_wraps_the_parameter_count_is_refused(call):
    res = run_call(call.format(h=H_WRAPS_TO_3),
                   setup="X = np.ones((4, 1)); T = np.ones((4, 1))")
    expect_value_error(res, "hidden")


@pytest.mark.parametrize("call, name", [
    ("_core.five_point_cubic_smooth(np.ones(10), {big})", "passes"),
    ("_core.train_lm(th, X, T, 1, epochs={big})", "epochs"),
    ("_core.train_lm(th, X, T, 1, max_fail={big})", "max_fail"),
    ("_core.train_gd(th, X, T, 1, epochs={big})", "epochs"),
    ("_core.mlp_jtj(th, X, T, 1, 'tansig', {big})", "threads"),
    ("_core.optimise('boa', 'sphere', dim=2, options={{'iterations': {big}}})",
     "options['iterations']"),
    ("_core.sim_open_loop(P, np.zeros(21), np.zeros((3, 6)), 1e-3, {big})", "substeps"),
])
def test_int_arguments_beyond_32_bits_name_the_argument(call, name):
    setup = ("X = np.ones((4, 1)); T = np.ones((4, 1)); th = np.zeros(4)\n"
             "from cdam_core.sim.parameters import plant_vector; P = plant_vector()")
    res = run_call(call.format(big=2 ** 40), setup=setup)
    expect_value_error(res, name)


def test_train_gd_rejects_an_infinite_learning_rate():
    setup = "X = np.linspace(-1, 1, 8).reshape(-1, 1); T = X ** 2; th = np.full(4, 0.1)"
    expect_value_error(run_call("_core.train_gd(th, X, T, 1, lr=float('inf'))", setup=setup), "lr")
    expect_value_error(run_call("_core.train_gd(th, X, T, 1, lr=float('nan'))", setup=setup), "lr")
    # a finite lr so large that the weights overflow: reported as divergence, naming lr
    res = run_call("_core.train_gd(th, X, T, 1, lr=1e300, epochs=50)", setup=setup)
    expect_value_error(res, "lr", "diverged")
    res = run_call("_core.train_lm(th, X, T, 1, mu=float('inf'))", setup=setup)
    expect_value_error(res, "mu")


def test_closed_loop_simulation_that_diverges_names_dt():
    setup = ("from cdam_core.sim.parameters import plant_vector, control_vector\n"
             "from cdam_core.sim import flight\n"
             "P = plant_vector(); C = control_vector()\n"
             "x0 = np.zeros(21); x0[3] = 1.0\n"
             "SP = np.zeros((100, 8))")
    # RK4 steps of 100 s on modes of thousands of rad/s (h * rate_max far beyond 2.78): the
    # states overflow to Inf / NaN within the 100 ticks
    res = run_call("_core.sim_closed_loop(P, C, x0, SP, 100.0, 1)", setup=setup)
    expect_value_error(res, "dt", "diverged")
    # with a stable step the same call works and returns finite states
    res = run_call("bool(np.isfinite(_core.sim_closed_loop(P, C, x0, SP, 1e-3, "
                   "_core.sim_substeps(P, 1e-3))[0]).all())", setup=setup)
    assert res["type"] == "ok" and res["message"] == "True", res


def test_substeps_for_a_huge_dt_saturates_instead_of_overflowing():
    setup = "from cdam_core.sim.parameters import plant_vector; P = plant_vector()"
    res = run_call("_core.sim_substeps(P, 1e300)", setup=setup)
    assert res["type"] == "ok" and res["message"] == str(INT_MAX), res
    expect_value_error(run_call("_core.sim_substeps(P, float('inf'))", setup=setup), "dt")
