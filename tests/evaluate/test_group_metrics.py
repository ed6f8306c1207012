"""The nano-drone benchmark's metrics in `cdam evaluate` (MAE per group with the attitude as the
quaternion geodesic angle, its sum over h = 1..50, RMSE per group) and --predictions, against
an independent numpy computation of an ARX model's h-step predictions."""
import json

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from cdam_core.cli.main import main
from cdam_core.evaluate.groups import parse_groups, quaternion_angle
from cdam_core.models import ArxModel, save_model
from cdam_core.record.dataset import Dataset, write_dataset

STATES = ["x", "y", "z", "vx", "vy", "vz", "qx", "qy", "qz", "qw", "wx", "wy", "wz"]
INPUTS = ["w1", "w2", "w3", "w4"]


def _flight(n, seed):
    rng = np.random.default_rng(seed)
    u = rng.uniform(0, 1, (n, 4))
    rates = np.cumsum(0.05 * rng.standard_normal((n, 3)), axis=0)
    att = Rotation.from_rotvec(np.cumsum(0.01 * rates, axis=0)).as_quat()   # x, y, z, w
    att *= np.sign(att[:, 3:])
    vel = np.cumsum(0.02 * rng.standard_normal((n, 3)) + 0.01 * (u[:, :3] - 0.5), axis=0)
    pos = np.cumsum(0.01 * vel, axis=0)
    return u, np.column_stack([pos, vel, att, rates])


def _numpy_h_step(coef, u, y, h):
    """Targets t = h..n-1 of y(t) = A' y(t-1) + B' u(t-1) + c from the measured y(t-h)."""
    A, B, c = coef[:13], coef[13:17], coef[17]
    t = np.arange(h, len(y))
    p = y[t - h]
    for j in range(1, h + 1):
        p = p @ A + u[t - h + j - 1] @ B + c
    return t, p


def _angle(qt, qp):      # independent form: 2 arccos |<q_t, q_p>| of unit quaternions
    qt = qt / np.linalg.norm(qt, axis=1, keepdims=True)
    qp = qp / np.linalg.norm(qp, axis=1, keepdims=True)
    return 2 * np.arccos(np.clip(np.abs(np.sum(qt * qp, axis=1)), 0, 1))


def test_quaternion_angle_against_scipy():
    rng = np.random.default_rng(3)
    a, b = Rotation.random(200, random_state=1), Rotation.random(200, random_state=2)
    want = (a.inv() * b).magnitude()
    qa, qb = a.as_quat(), b.as_quat() * rng.choice([-1, 1], (200, 1)) * 3.0   # sign, scale
    np.testing.assert_allclose(quaternion_angle(qa, qb), want, atol=1e-12)
    np.testing.assert_allclose(quaternion_angle(qa[:, [3, 0, 1, 2]], qb[:, [3, 0, 1, 2]],
                                                scalar_last=False), want, atol=1e-12)
    with pytest.raises(ValueError, match="zero quaternion"):
        quaternion_angle(qa[:2], np.zeros((2, 4)))


def test_benchmark_metrics_and_predictions_match_numpy(tmp_path):
    u0, y0 = _flight(400, 0)
    model = ArxModel((1, 1, 1)).fit(u0, y0)
    save_model(tmp_path / "m.json", model, inputs=INPUTS, outputs=STATES)
    coef = np.array(json.loads((tmp_path / "m.json").read_text())["model"]["coef"])
    recs = []
    for k, (n, name) in enumerate(((130, "a.csv"), (110, "b.parquet"))):
        u, y = _flight(n, k + 1)
        write_dataset(tmp_path / name, Dataset(t=np.arange(n) * 0.01, columns=INPUTS + STATES,
                                               data=np.column_stack([u, y])))
        recs.append((u, y))
    assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / "a.csv"),
                 str(tmp_path / "b.parquet"), "--horizon", "50", "--no-free-run", "--json",
                 str(tmp_path / "e.json"), "--predictions", str(tmp_path / "p.parquet"),
                 "--quiet"]) == 0
    js = json.loads((tmp_path / "e.json").read_text())
    assert list(js["groups"]) == ["position", "velocity", "attitude", "rates"]
    sums = {g: 0.0 for g in js["groups"]}
    pred = pd.read_parquet(tmp_path / "p.parquet")
    for i, h in enumerate(js["horizons"]):
        errs = {g: [] for g in js["groups"]}
        naive_att = []
        for k, (u, y) in enumerate(recs):
            t, p = _numpy_h_step(coef, u, y, h)
            errs["position"].append(np.linalg.norm(p[:, :3] - y[t, :3], axis=1))
            errs["velocity"].append(np.linalg.norm(p[:, 3:6] - y[t, 3:6], axis=1))
            errs["attitude"].append(_angle(y[t, 6:10], p[:, 6:10]))
            errs["rates"].append(np.linalg.norm(p[:, 10:] - y[t, 10:], axis=1))
            naive_att.append(_angle(y[t, 6:10], y[t - h, 6:10]))
            if h in (1, 7, 50):
                rows = pred[(pred.record == str(tmp_path / ("a.csv", "b.parquet")[k])) &
                            (pred.horizon == h)].sort_values("start")
                assert np.array_equal(rows["start"].to_numpy(), t - h)
                np.testing.assert_allclose(rows[STATES].to_numpy(), p, rtol=1e-9, atol=1e-12)
                np.testing.assert_allclose(rows["t"].to_numpy(), t * 0.01, atol=1e-12)
        for g, e in errs.items():
            e = np.concatenate(e)
            assert js["group_mae"]["model"][g][i] == pytest.approx(np.mean(e), rel=1e-7, abs=1e-9)
            assert js["group_rmse"]["model"][g][i] == pytest.approx(
                np.sqrt(np.mean(e ** 2)), rel=1e-7, abs=1e-9)
            sums[g] += np.mean(e)
        assert js["group_mae"]["naive"]["attitude"][i] == pytest.approx(
            np.mean(np.concatenate(naive_att)), rel=1e-7, abs=1e-9)
    for g, v in sums.items():
        assert js["group_mae_sum_1_50"]["model"][g] == pytest.approx(v, rel=1e-7)
    assert len(pred) == sum(len(y) - h for _, y in recs for h in range(1, 51))


def test_groups_text_and_errors(tmp_path, capsys):
    g = parse_groups("pos=x,y;att=quat_wxyz:qw,qx,qy,qz", STATES)
    assert [x.kind for x in g] == ["vector", "quat_wxyz"]
    for text, words in (("pos=x,nope", "'nope' is not an output"), ("att=quat:qx,qy,qz", "4"),
                        ("a=x;a=y", "twice"), ("x,y", "expected name=columns")):
        with pytest.raises(ValueError, match=words):
            parse_groups(text, STATES)
    u, y = _flight(200, 0)
    save_model(tmp_path / "m.json", ArxModel((1, 1, 1)).fit(u, y), inputs=INPUTS, outputs=STATES)
    write_dataset(tmp_path / "r.csv", Dataset(t=np.arange(200) * 0.01, columns=INPUTS + STATES,
                                              data=np.column_stack([u, y])))
    assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / "r.csv"),
                 "--predictions", str(tmp_path / "p.csv")]) == 2
    assert "--predictions: expected a .parquet" in capsys.readouterr().err
    assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / "r.csv"),
                 "--groups", "p=x,zz"]) == 2
    assert "'zz' is not an output" in capsys.readouterr().err


def test_map_brings_a_record_with_its_own_names(tmp_path):
    """--map: the record's own column names (and units) reach the model and come back in
    --predictions; the scores equal those of the same record under the model's names."""
    u, y = _flight(200, 0)
    save_model(tmp_path / "m.json", ArxModel((1, 1, 1)).fit(u, y), inputs=INPUTS, outputs=STATES)
    write_dataset(tmp_path / "r.csv", Dataset(t=np.arange(200) * 0.01, columns=INPUTS + STATES,
                                              data=np.column_stack([u, y])))
    own = [f"m{k}_erpm" for k in range(1, 5)] + ["pos_x_mm"] + STATES[1:]
    data = np.column_stack([u / 0.5, y[:, :1] * 1000.0, y[:, 1:]])   # other names and units
    write_dataset(tmp_path / "own.parquet", Dataset(t=np.arange(200) * 0.01, columns=own,
                                                    data=data))
    (tmp_path / "map.json").write_text(json.dumps(
        {**{f"w{k}": f"m{k}_erpm*0.5" for k in range(1, 5)}, "x": "pos_x_mm*0.001"}))
    for rec, extra in (("r.csv", []), ("own.parquet", ["--map", str(tmp_path / "map.json")])):
        assert main(["evaluate", str(tmp_path / "m.json"), str(tmp_path / rec), "--horizon", "5",
                     "--no-free-run", "--json", str(tmp_path / f"{rec}.json"), "--predictions",
                     str(tmp_path / f"{rec}.p.parquet"), "--quiet", *extra]) == 0
    a, b = (json.loads((tmp_path / f"{r}.json").read_text()) for r in ("r.csv", "own.parquet"))
    np.testing.assert_allclose(b["group_rmse"]["model"]["position"],
                               a["group_rmse"]["model"]["position"], rtol=1e-9)
    pa_, pb = (pd.read_parquet(tmp_path / f"{r}.p.parquet") for r in ("r.csv", "own.parquet"))
    assert "pos_x_mm" in pb.columns and "x" not in pb.columns
    np.testing.assert_allclose(pb["pos_x_mm"].to_numpy(), pa_["x"].to_numpy() * 1000, rtol=1e-9)


def test_rollout_equals_k_step_prediction_on_segments():
    rng = np.random.default_rng(5)
    U, Y = rng.standard_normal((300, 2)), np.cumsum(rng.standard_normal((300, 3)), axis=0)
    m = ArxModel((3, 2, 2)).fit(U, Y)
    segs = [150, 90, 60]
    got = {}
    for k, rows, P in m.rollout(U, Y, 12, segments=segs, first=4):
        got.setdefault(k, []).append((rows, P))
    assert sorted(got) == list(range(1, 13))
    for k, parts in got.items():
        rows = np.concatenate([r for r, _ in parts])
        P = np.vstack([p for _, p in parts])
        want = m.predict(U, Y, mode="k_step", k=k, segments=segs)
        starts = [0, 150, 240]
        expect = np.concatenate([np.arange(a + 4 + k - 1, a + n) for a, n in zip(starts, segs)])
        assert np.array_equal(np.sort(rows), expect)
        np.testing.assert_allclose(P, want[rows], rtol=1e-12, atol=1e-12)
