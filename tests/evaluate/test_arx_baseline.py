"""The ARX baseline: orders and delay chosen on training records only (evaluate.baselines),
and the cross-trajectory protocol on the nano-drone flights (slow)."""
import numpy as np
import pytest

from cdam_core.evaluate.baselines import select_arx
from cdam_core.record.dataset import Dataset
from cdam_core.record.realdata import shared_data_dir
from cdam_core.record.stack import stack_records


def _record(n, seed):
    """y1(t) = 1.2 y1(t-1) - 0.5 y1(t-2) + 0.8 u(t-2), y2(t) = 0.7 y2(t-1) + 0.3 u(t-2):
    true orders na = 2, nb = 1, nk = 2."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = np.zeros((n, 2))
    for t in range(2, n):
        y[t, 0] = 1.2 * y[t - 1, 0] - 0.5 * y[t - 2, 0] + 0.8 * u[t - 2]
        y[t, 1] = 0.7 * y[t - 1, 1] + 0.3 * u[t - 2]
    y += 0.001 * rng.standard_normal((n, 2))
    return Dataset(t=np.arange(n) * 0.01, columns=["u", "y1", "y2"],
                   data=np.column_stack([u, y]),
                   meta={"inputs": ["u"], "outputs": ["y1", "y2"], "path": f"r{seed}"})


def test_select_arx_finds_the_generating_orders():
    train = stack_records([_record(400, 1), _record(300, 2)])
    valid = stack_records([_record(300, 3)])
    grid = [(1, 1, 1), (1, 1, 2), (2, 1, 1), (2, 1, 2), (3, 1, 1)]   # no superset of the truth
    model, orders, scores = select_arx(train, valid, grid, horizons=(1, 5, 20))
    assert orders == (2, 1, 2)
    assert scores[(2, 1, 2)] < min(v for k, v in scores.items() if k != (2, 1, 2))
    np.testing.assert_allclose(model.coef_[[0, 2, 4], 0], [1.2, -0.5, 0.8], atol=0.02)
    with pytest.raises(ValueError, match="grid: no candidate"):
        select_arx(train, valid, [])


FLIGHTS = shared_data_dir() / "nanodrone"


@pytest.mark.slow
@pytest.mark.skipif(not (FLIGHTS / "square_20251017_run1.parquet").is_file(),
                    reason=f"nano-drone flights not found at {FLIGHTS} (set CDAM_SHARED_DATA)")
def test_cross_trajectory_fold_on_the_flights():
    from cdam_core.evaluate.crossfold import cross_trajectory_fold
    from cdam_core.record.realdata.nanodrone import nanodrone_files
    fold = cross_trajectory_fold(nanodrone_files(), "square", grid=[(1, 1, 1), (2, 2, 2)])
    sc = fold.scores
    assert sc.horizons == list(range(1, 51)) and set(sc.group_mae) == {"naive", "arx1", "arx"}
    assert len(fold.test_files) == 5 and len(fold.train_files) == 12
    h50 = sc.horizons.index(50)
    # a linear model beats holding the state at 0.5 s on every group of the square flights
    assert np.all(sc.group_rmse["arx1"][h50] < sc.group_rmse["naive"][h50])
