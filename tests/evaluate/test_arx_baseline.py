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
    assert sc.horizons == list(range(1, 51)) and set(sc.group_mae) == {"naive", "arx1", "arx", "physics",
                                                             "physics_hold"}
    assert len(fold.test_files) == 5 and len(fold.train_files) == 12
    h50 = sc.horizons.index(50)
    # a linear model beats holding the state at 0.5 s on every group of the square flights
    assert np.all(sc.group_rmse["arx1"][h50] < sc.group_rmse["naive"][h50])


def test_evaluate_with_the_arx_baseline(tmp_path, capsys):
    """`cdam evaluate --baselines`: the ARX baseline chosen on training records holds the
    generating lags and is scored beside the model and the naive predictor."""
    import json

    from cdam_core.cli.main import main
    from cdam_core.models import ArxModel, save_model
    from cdam_core.record.dataset import write_dataset
    paths = []
    for k, n in enumerate((400, 300, 300, 250)):
        paths.append(tmp_path / f"r{k}.{'csv' if k % 2 else 'parquet'}")
        write_dataset(paths[-1], _record(n, k + 1))
    st = stack_records(paths[:1])
    save_model(tmp_path / "m.json", ArxModel((1, 1, 1)).fit(st.U, st.Y),
               inputs=["u"], outputs=["y1", "y2"])
    argv = ["evaluate", str(tmp_path / "m.json"), str(paths[3]), "--horizon", "20", "--json",
            str(tmp_path / "e.json"), "--quiet", "--baselines"]
    assert main(argv + [str(p) for p in paths[:3]]) == 0
    js = json.loads((tmp_path / "e.json").read_text())
    na, nb, nk = js["baselines"]["arx"]["narx"]     # y(t-1), y(t-2) and u(t-2) among its lags
    assert na >= 2 and nk <= 2 <= nk + nb - 1
    assert js["baselines"]["arx"]["validation"] == [str(paths[2])]
    rm = js["rmse"]
    assert set(rm) == {"model", "naive", "arx"}
    # the generating structure beats the misspecified ARX(1,1,1) and holding the output
    assert rm["arx"]["y1"][-1] < 0.5 * min(rm["model"]["y1"][-1], rm["naive"]["y1"][-1])
    assert main(argv + [str(paths[0])]) == 2
    assert "--baselines: needs at least two" in capsys.readouterr().err
