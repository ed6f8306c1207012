"""scikit-learn compatibility (issue 22 item 4): BPNetwork (static and NARX), HybridNarx and the
MinMaxScaler pass scikit-learn's own estimator checks, except the documented ones below, and
work in clone, Pipeline and GridSearchCV. scikit-learn is a test dependency only: the protocol
is written in cdam_core.base.estimator."""
import numpy as np
import pytest

sklearn = pytest.importorskip("sklearn")
# scikit-learn advises validating in fit; the project refuses a bad argument where it is given
pytestmark = pytest.mark.filterwarnings("ignore:.*delay parameter validation:UserWarning")

from sklearn.base import clone  # noqa: E402
from sklearn.metrics import r2_score  # noqa: E402
from sklearn.model_selection import GridSearchCV, TimeSeriesSplit  # noqa: E402
from sklearn.pipeline import Pipeline  # noqa: E402
from sklearn.utils.estimator_checks import parametrize_with_checks  # noqa: E402

from cdam_core.models import BPNetwork, HybridNarx  # noqa: E402
from cdam_core.preprocess import MinMaxScaler  # noqa: E402

# Checks that fail by design, each with its reason (the project's conventions win where they
# differ from scikit-learn's; every one of these still raises a ValueError naming the problem).
COMMON = {
    "check_n_features_in_after_fitting":
        "wording only: the error is 'U: expected 3 columns, got 2', not scikit-learn's sentence",
    "check_complex_data": "wording only: 'dtype complex128 is not supported'",
    "check_estimators_empty_data_messages": "wording only: 'empty array (shape (12, 0))'",
    "check_dtype_object":
        "object arrays are refused outright (a column of Python objects is a reading error "
        "upstream), not converted",
    "check_fit2d_predict1d":
        "a 1-D array is one channel (N,) -> (N, 1), the protocol's convention for single-input "
        "systems, so the error is about the column count, not 'Reshape your data'",
}
MODEL = {
    **COMMON,
    "check_do_not_raise_errors_in_init_or_set_params":
        "a bad argument is refused where it is given (project rule), in __init__ and set_params",
    "check_estimators_unfitted":
        "raises ValueError('... not fitted; call fit(U, Y) first'); scikit-learn's "
        "NotFittedError cannot be raised without making scikit-learn a dependency",
    "check_fit1d": "a 1-D U is one input channel (the protocol's convention), not an error",
}
DYNAMIC = {
    **MODEL,
    "check_methods_sample_order_invariance":
        "a dynamic model's prediction at t depends on the rows before t: reordering rows "
        "changes it by definition",
    "check_methods_subset_invariance":
        "predict(U) runs free from the first row: a subset starts elsewhere",
}
FEW_ROWS = "the least-squares ARX part needs at least 4 (t0 + 1) + 10 rows; the check gives fewer"
HYBRID = {**DYNAMIC, **{c: FEW_ROWS for c in (
    "check_n_features_in_after_fitting", "check_estimators_nan_inf", "check_regressor_multioutput",
    "check_regressors_no_decision_function", "check_fit2d_1feature")}}


def _expected(est):
    if isinstance(est, MinMaxScaler):
        return COMMON
    if isinstance(est, HybridNarx):
        return HYBRID
    return DYNAMIC if est.dynamic else MODEL


@parametrize_with_checks([BPNetwork(hidden=4, epochs=30), BPNetwork(hidden=4, epochs=30,
                                                                     narx=(1, 1, 1)),
                          # 0.1: the checks' 20-row records leave the held-out ARX fit (rows
                          # before the validation tail) its 4 (t0 + 1) + 10 rows
                          HybridNarx((1, 1, 1), validation_fraction=0.1), MinMaxScaler()],
                         expected_failed_checks=_expected)
def test_sklearn_estimator_checks(estimator, check):
    check(estimator)


def test_clone_keeps_parameters_as_given_and_set_params_refuses_bad_values():
    net = BPNetwork(hidden=np.int64(5), narx=[2, 2, 1], epochs=7)
    twin = clone(net)
    assert twin.get_params() == net.get_params() and twin is not net
    assert twin.narx == [2, 2, 1] and type(twin.hidden) is np.int64
    with pytest.raises(ValueError, match="hidden"):
        net.set_params(hidden=0)
    with pytest.raises(ValueError, match="nope"):
        net.set_params(nope=1)
    assert net.hidden == 5                                     # unchanged by the refusals
    assert net.set_params(hidden=3, narx=None).get_params()["hidden"] == 3
    assert not net.dynamic
    h = HybridNarx((2, 2, 1), seed=3)
    assert clone(h).get_params() == {"narx": (2, 2, 1), "features": "raw", "fit_residual": None,
                                     "seed": 3, "validation_fraction": 0.2, "ensemble": 1,
                                     "weights": (0.0, 1.0), "validation_blocks": 0,
                                     "training": "one_step", "refine_epochs": 10}


def test_scaler_is_sklearn_minmax_to_minus_one_one():
    from sklearn.preprocessing import MinMaxScaler as SkScaler
    X = np.random.default_rng(0).normal(size=(50, 3)) * [1, 10, 100]
    ours = MinMaxScaler().fit_transform(X)
    np.testing.assert_allclose(ours, SkScaler(feature_range=(-1, 1)).fit_transform(X),
                               atol=1e-12)


def _narx_system(n=400, seed=0):
    """y(t) = 0.7 y(t-1) + 0.4 tanh(u(t-1)) + noise, u a random staircase (independent of us)."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-2, 2, n // 10 + 1), 10)[:n]
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.7 * y[t - 1] + 0.4 * np.tanh(u[t - 1])
    return u[:, None], y + 0.01 * rng.standard_normal(n)


def test_pipeline_equals_the_steps_by_hand():
    X, y = _narx_system()
    pipe = Pipeline([("scale", MinMaxScaler()), ("net", BPNetwork(hidden=4, epochs=20))])
    P = pipe.fit(X, y).predict(X)
    Xs = MinMaxScaler().fit_transform(X)
    by_hand = BPNetwork(hidden=4, epochs=20).fit(Xs, y).predict(Xs)
    assert P.shape == y.shape
    np.testing.assert_array_equal(P, by_hand)
    pipe.set_params(net__hidden=2)
    assert pipe.named_steps["net"].hidden == 2


def test_grid_search_picks_orders_by_one_step_r2_on_time_series_splits():
    """GridSearchCV's best score is recomputed here: per split, the one-step prediction of a
    clone fitted on the split's past, scored by sklearn.metrics.r2_score after the t0 rows."""
    X, y = _narx_system()
    cv = TimeSeriesSplit(n_splits=3)
    grid = GridSearchCV(BPNetwork(hidden=4, epochs=20), cv=cv,
                        param_grid={"narx": [(1, 1, 1), (2, 2, 1)], "hidden": [2, 4]}).fit(X, y)
    best = grid.best_params_
    scores = []
    for tr, te in cv.split(X):
        m = BPNetwork(epochs=20, **best).fit(X[tr], y[tr])
        P = m.predict(X[te], y[te])
        scores.append(r2_score(y[te][m.t0:], P[m.t0:]))
    assert grid.best_score_ == pytest.approx(np.mean(scores), rel=1e-12)
    assert grid.best_score_ > 0.9             # a NARX of the right structure fits this system
