"""The quad_hybrid kind (physics + k-step-trained network) on the nano-drone flights through the
documented path: `cdam identify FLIGHTS --loader nanodrone --model quad_hybrid ... --save M`
then `cdam evaluate M FLIGHT` on a trajectory type it did not train on. Small settings (two
flights, 4 hidden units, 3 epochs) keep it quick; the claim checked is that the saved model
loads and scores, beats holding the state on every group at h = 10 on the other type, and that
its options are checked with one line each."""
import json

import pytest

from cdam_core.cli.main import main
from cdam_core.record.realdata import shared_data_dir

FLIGHTS = shared_data_dir() / "nanodrone"
TRAIN = ["random1_20251017_run1", "multisine_20251017_run1"]


@pytest.mark.skipif(not (FLIGHTS / "square_20251017_run2.parquet").is_file(),
                    reason=f"nano-drone flights not found at {FLIGHTS} (set CDAM_SHARED_DATA)")
def test_identify_then_evaluate_on_another_trajectory_type(tmp_path, capsys):
    model = tmp_path / "hybrid.json"
    train = [str(FLIGHTS / f"{n}.parquet") for n in TRAIN]
    assert main(["identify", *train, "--loader", "nanodrone", "--model", "quad_hybrid",
                 "--hidden", "4", "--horizon", "10", "--lags", "2", "--epochs", "3",
                 "--save", str(model), "--json", str(tmp_path / "id.json"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "network_weights" in out and "k-step LM: 3 epochs" in out
    hist = json.loads((tmp_path / "id.json").read_text())["training"]["mse"]
    assert len(hist) == 4 and hist[-1] < hist[0]
    assert main(["evaluate", str(model), str(FLIGHTS / "square_20251017_run2.parquet"),
                 "--loader", "nanodrone", "--horizon", "10", "--no-free-run", "--json",
                 str(tmp_path / "ev.json"), "--quiet"]) == 0
    js = json.loads((tmp_path / "ev.json").read_text())
    assert js["model"]["kind"] == "quad_hybrid"
    rm = js["group_rmse"]
    for group in rm["model"]:
        assert rm["model"][group][-1] < rm["naive"][group][-1], (group, rm)


@pytest.mark.parametrize("extra, message", [
    (["--model", "quad_hybrid", "--horizon", "0"], "--horizon: must be"),
    (["--model", "quad_hybrid", "--hidden", "-1"], "--hidden: must be"),
    (["--lags", "3"], "--lags: needs --model quad_hybrid"),
])
def test_options_are_checked(tmp_path, capsys, extra, message):
    csv = tmp_path / "small.csv"
    csv.write_text("t,u,y\n" + "".join(f"{0.01 * k},{k % 3},{k % 5}\n" for k in range(200)))
    flights = [str(FLIGHTS / f"{TRAIN[0]}.parquet"), "--loader", "nanodrone"] \
        if "quad_hybrid" in extra else [str(csv), "--inputs", "u", "--outputs", "y"]
    assert main(["identify", *flights, *extra, "--quiet"]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.skipif(not (FLIGHTS / "square_20251017_run2.parquet").is_file(),
                    reason=f"nano-drone flights not found at {FLIGHTS} (set CDAM_SHARED_DATA)")
def test_hybrid_fold_chooses_on_validation_and_scores_beside_the_baselines():
    from cdam_core.evaluate.crossfold import hybrid_fold
    from cdam_core.record.realdata.nanodrone import nanodrone_files
    grid = {"hold": {"prior": "hold"}, "dynamic": {"prior": "dynamic"}}
    r = hybrid_fold(nanodrone_files(), "square", grid=grid, horizon=3,
                    fixed={"hidden": 2, "lags": 1, "epochs": 1, "horizon": 5},
                    arx_grid=[(1, 1, 1)])
    assert r["chosen"] == min(r["validation"], key=r["validation"].get)
    g = r["fold"].scores.group_rmse
    assert {"naive", "arx", "physics_hold", "hybrid"} <= set(g)
    assert g["hybrid"].shape == g["naive"].shape == (3, 4)
