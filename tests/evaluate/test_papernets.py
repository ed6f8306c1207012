"""The paper's pipelines beside the baselines on real flights (evaluate.papernets, the
report's table and the command docs/examples/nanodrone/cross_trajectory.py).

Every expected number is computed here with plain numpy (least squares, regressor and
simulation loops, the network's forward pass written out), never by the code under test."""
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from cdam_core.evaluate.groups import NANODRONE_GROUPS
from cdam_core.evaluate.horizons import score_horizons
from cdam_core.evaluate.papernets import (ardrone_comparison, blocked_free_run_r,
                                          blocked_hybrid_r, paper_network_fitters)
from cdam_core.models.arx import ArxModel
from cdam_core.models.network import BPNetwork
from cdam_core.record.realdata import ardrone2
from cdam_core.report.papernets import standing_table
from numpy_arx import arx_free_run

ROOT = Path(__file__).resolve().parents[2]


def _scale(A, lo, hi):
    span = np.where(hi > lo, hi - lo, 1.0)
    return np.where(hi > lo, 2.0 * (A - lo) / span - 1.0, 0.0)


def test_network_trains_on_segments_without_crossing_a_seam():
    """Epoch 0 (no LM step): the training MSE the network reports is that of its initial
    weights on the design, which numpy rebuilds here per segment (no regressor across the
    seam) and thinned to every 2nd row."""
    r = np.random.default_rng(3)
    U, Y = r.normal(size=(60, 2)), r.normal(size=(60, 1))
    Y[30:] += 50.0                   # a jump at the seam: a crossing regressor would show it
    net = BPNetwork(hidden=3, epochs=0, narx=(2, 1, 1), seed=5).fit(U, Y, segments=[30, 30],
                                                                    stride=2)
    Us = _scale(U, U.min(0), U.max(0))
    Ys = _scale(Y, Y.min(0), Y.max(0))
    X, T = [], []
    for a, b in ((0, 30), (30, 60)):
        for t in range(a + 2, b):                         # t0 = max(na, nk + nb - 1) = 2
            X.append([Ys[t - 1, 0], Ys[t - 2, 0], Us[t - 1, 0], Us[t - 1, 1]])
            T.append(Ys[t])
    X, T = np.array(X)[::2], np.array(T)[::2]
    th = net.theta_
    h, i = 3, 4
    W1, b1 = th[:i * h].reshape(i, h).T, th[i * h:i * h + h]
    W2, b2 = th[i * h + h:i * h + 2 * h].reshape(h, 1).T, th[-1:]
    P = np.tanh(X @ W1.T + b1) @ W2.T + b2
    assert net.history_["mse"][0] == pytest.approx(np.mean((P - T) ** 2), rel=1e-9)


def test_paper_fitters_refuse_unknown_names():
    with pytest.raises(ValueError, match="variants: unknown 'lstm'"):
        paper_network_fitters(variants=("lstm",))
    with pytest.raises(ValueError, match="algos: unknown 'pso'"):
        paper_network_fitters(algos=("pso",))


def _mean_r(Y, P):
    return np.mean([np.corrcoef(Y[:, k], P[:, k])[0, 1] for k in range(Y.shape[1])])


@pytest.fixture(scope="module")
def ardrone(bundled_record):
    return ardrone2.load_ardrone2(bundled_record(ardrone2.ARDRONE2_FILE))


@pytest.fixture(scope="module")
def rows(ardrone):
    grid = dict(decimations=(8,), passes=(0,), orders=(2,), delays=(1,), features=("raw",),
                hidden=(2,), seeds=(0,), iterations=1, lm_epochs=1, refine_epochs=1)
    return ardrone_comparison(ardrone, algos=("iboa",), variants=("static",),
                              paper_overrides=dict(iterations=1, lm_epochs=1, hidden=2),
                              hybrid=grid)


def test_ardrone_baselines_against_numpy(ardrone, rows):
    """The naive and ARX rows of the table, recomputed with numpy on the same split."""
    by = {r.name: r for r in rows}
    U, Y = ardrone.select(ardrone.inputs), ardrone.select(ardrone.outputs)
    n = int(0.75 * len(U))
    Yt = Y[n:]
    rmse = np.sqrt(np.mean((Yt - Y[:n].mean(0)) ** 2, axis=0))
    got = [by["naive"].metrics[o]["rmse"] for o in ardrone.outputs]
    np.testing.assert_allclose(got, rmse, rtol=1e-10)
    assert by["naive"].mean_r is None
    Ud, Yd = U[::8], Y[::8]
    nd = len(U[:n:8])
    P = arx_free_run(Ud[:nd], Yd[:nd], Ud[nd:], Yd[nd:], 2, 2, 1)[2:]
    Ym = Yd[nd + 2:]
    assert by["arx"].mean_r == pytest.approx(_mean_r(Ym, P), abs=1e-8)
    nr = np.sqrt(np.mean((Ym - P) ** 2, axis=0)) / np.std(Ym, axis=0)
    np.testing.assert_allclose([by["arx"].metrics[o]["nrmse"] for o in ardrone.outputs], nr,
                               rtol=1e-7)
    assert by["quad_physics"].metrics is None and "not applicable" in by["quad_physics"].note
    assert {"naive", "iboa_static", "arx", "hybrid_selected", "quad_physics"} == set(by)


def test_blocked_score_against_numpy():
    """Blocked validation: each of 3 blocks held out, ARX fitted on the rest (two records, no
    regressor across the gap), run free on the block; the mean over blocks of the mean r."""
    r = np.random.default_rng(1)
    n = 300
    U = r.normal(size=(n, 2))
    Y = np.zeros((n, 2))
    for t in range(1, n):
        Y[t] = 0.8 * Y[t - 1] + U[t - 1] @ np.array([[1.0, 0.3], [-0.5, 0.7]]) \
            + 0.1 * r.normal(size=2)
    got = blocked_free_run_r(U, Y, (1, 1, 1), "raw", blocks=3)
    rs = []
    for k in range(3):
        a, b = n * k // 3, n * (k + 1) // 3
        A, T = [], []
        for lo, hi in ((0, a), (b, n)):
            for t in range(lo + 1, hi):
                A.append(np.r_[Y[t - 1], U[t - 1], 1.0])
                T.append(Y[t])
        W = np.linalg.lstsq(np.array(A), np.array(T), rcond=None)[0]
        P = Y[a:b].copy()
        for t in range(1, b - a):
            P[t] = np.r_[P[t - 1], U[a + t - 1], 1.0] @ W
        rs.append(_mean_r(Y[a + 1:b], P[1:]))
    assert got == pytest.approx(np.mean(rs), abs=1e-10)


def _tanh_plant(n=300):
    """Two inputs through a tanh into a first-order linear recursion (seed 4)."""
    r = np.random.default_rng(4)
    U = r.normal(size=(n, 2))
    Y = np.zeros((n, 2))
    for t in range(1, n):
        Y[t] = 0.8 * Y[t - 1] + np.tanh(2 * U[t - 1]) @ np.array([[1.0, 0.3], [-0.5, 0.7]]) \
            + 0.05 * r.normal(size=2)
    return U, Y


def test_blocked_hybrid_score_against_numpy():
    """The hybrid's blocked score: on each of 3 blocks the ARX is fitted on the rest (numpy
    least squares, two records), the network on its one-step residual rows of both records
    (a spy checks what it is given), the two run free on the block: ARX recursion plus the
    network's term on u(t-1), written out here."""
    U, Y = _tanh_plant()
    n = len(U)
    nets = []

    def spy(X, R):
        nets.append((X.copy(), R.copy(), BPNetwork(hidden=3, epochs=5, seed=1,
                                                   threads=1).fit(X, R)))
        return nets[-1][2]
    got = blocked_hybrid_r(U, Y, (1, 1, 1), "raw", spy, blocks=3)
    rs = []
    for k in range(3):
        a, b = n * k // 3, n * (k + 1) // 3
        A, T, X = [], [], []
        for lo, hi in ((0, a), (b, n)):
            for t in range(lo + 1, hi):
                A.append(np.r_[Y[t - 1], U[t - 1], 1.0])
                T.append(Y[t])
                X.append(U[t - 1])
        A, T = np.array(A), np.array(T)
        W = np.linalg.lstsq(A, T, rcond=None)[0]
        Xs, Rs, net = nets[k]
        np.testing.assert_allclose(Xs, np.array(X), rtol=0, atol=0)
        np.testing.assert_allclose(Rs, T - A @ W, rtol=1e-8, atol=1e-10)
        P = Y[a:b].copy()
        term = net.predict(U[a:b - 1])
        for t in range(1, b - a):
            P[t] = np.r_[P[t - 1], U[a + t - 1], 1.0] @ W + term[t - 1]
        rs.append(_mean_r(Y[a + 1:b], P[1:]))
    assert len(nets) == 3
    assert got == pytest.approx(np.mean(rs), abs=1e-10)
    assert got > blocked_free_run_r(U, Y, (1, 1, 1), "raw", blocks=3)   # the tanh it learns


def test_standing_table_cells_against_numpy(rows):
    """The nano-drone cells are the group RMSE at h = 1 and h = 50 (position: the Euclidean
    norm of the error vector), here on a small 13-state record for the naive predictor."""
    r = np.random.default_rng(2)
    n = 200
    names = [c for g in NANODRONE_GROUPS for c in g.columns]
    Y = np.cumsum(r.normal(size=(n, 13)), axis=0)
    U = r.normal(size=(n, 4))
    model = ArxModel((1, 1, 1)).fit(U, Y)
    sc = score_horizons(model, U, Y, names, list(range(1, 51)), free_run=False,
                        groups=list(NANODRONE_GROUPS))
    table = standing_table(sc, rows)
    naive = next(line for line in table.splitlines() if line.startswith("| naive |"))
    pos = [np.sqrt(np.mean(np.sum((Y[h:, :3] - Y[:-h, :3]) ** 2, axis=1))) for h in (1, 50)]
    assert naive.split(" | ")[1] == f"{pos[0]:.3f} / {pos[1]:.3f}"
    ar = {x.name: x for x in rows}
    assert naive.rstrip(" |").endswith(
        f"{np.mean([v['nrmse'] for v in ar['naive'].metrics.values()]):.3f}")
    assert "| hybrid_selected | - | - | - | - |" in table       # AR.Drone only


def _script():
    spec = importlib.util.spec_from_file_location(
        "cross_trajectory", ROOT / "docs/examples/nanodrone/cross_trajectory.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_command_output_structure(tmp_path, capsys):
    """The one command (AR.Drone part, tiny settings): JSON, Markdown, HTML and the figure."""
    out = tmp_path / "rep"
    assert _script().main([str(out), "--no-flights", "--ardrone", "--paper-networks",
                           "--quick"]) == 0
    js = json.loads((out / "results.json").read_text())
    names = [r["name"] for r in js["ardrone"]]
    assert names == ["naive", "iboa_static", "boa_static", "cabc_static", "iboa_narx",
                     "boa_narx", "cabc_narx", "arx", "hybrid_selected", "quad_physics"]
    for r in js["ardrone"]:
        assert set(r) >= {"mean_r", "metrics", "rate_hz", "note"}
    sel = js["ardrone"][8]["details"]
    assert set(sel) >= {"decimation", "smoothing_passes", "narx", "network_kept",
                        "validation_r", "structure_candidates", "network_candidates"}
    md = (out / "index.md").read_text()
    assert "## Where the paper's method stands" in md and "ardrone_free_run.png" in md
    for name in names[:-1]:
        assert f"| {name} |" in md
    assert (out / "index.html").stat().st_size > 0
    assert (out / "ardrone_free_run.png").read_bytes()[:4] == b"\x89PNG"
    assert "AR.Drone free-run mean r" in capsys.readouterr().out


def test_command_refuses_nothing_to_run(tmp_path, capsys):
    assert _script().main([str(tmp_path / "x"), "--no-flights"]) == 2
    assert "error: --no-flights" in capsys.readouterr().err


def _stack(n, seed, lengths):
    from cdam_core.record.stack import Stack
    r = np.random.default_rng(seed)
    U = r.normal(size=(n, 2))
    Y = np.zeros((n, 1))
    for t in range(1, n):
        Y[t] = 0.7 * Y[t - 1] + np.tanh(U[t - 1, 0]) - 0.3 * U[t - 1, 1]
    return Stack(["r"], ["u1", "u2"], ["y"], U, Y, np.arange(n) * 0.01, lengths,
                 np.zeros(n, int), np.arange(n))


def test_chosen_network_decides_on_the_validation_flights():
    """Each setting is trained on the fit stack and scored on the validation stack; the one
    with the least validation score is retrained on the training stack (a network with 6
    hidden nodes, 2 optimiser iterations: seconds)."""
    from cdam_core.evaluate.papernets import ChosenNetworkFitter
    fit, valid = _stack(400, 0, [200, 200]), _stack(200, 1, [200])
    train = _stack(600, 2, [300, 300])
    grid = {"smoothing_passes": (0, 5)}
    f = ChosenNetworkFitter("iboa", "narx", grid=grid, horizons=(1, 5), iterations=2,
                            lm_epochs=5, hidden=6, population=6)
    model = f(train, fit, valid)
    (c,) = f.choices
    scores = {x["smoothing_passes"]: x["relative_mae"] for x in c["validation"]}
    assert c["chosen"]["smoothing_passes"] == min(scores, key=scores.get)
    # the validation score of a setting, recomputed from the naive MAE written out here
    ref = ChosenNetworkFitter("iboa", "narx", grid=grid, iterations=2, lm_epochs=5, hidden=6,
                              population=6)._fit(fit, {"smoothing_passes": 0})
    rel = []
    for h in (1, 5):
        P = ref.predict(valid.U, valid.Y, mode="k_step", k=h)
        rows = np.arange(max(ref.t0, 1) + h - 1, 200)
        rel.append(np.mean(np.abs(P[rows] - valid.Y[rows])) /
                   np.mean(np.abs(valid.Y[rows - h] - valid.Y[rows])))
    assert scores[0] == pytest.approx(np.mean(rel), rel=1e-9)
    assert model.narx == (2, 2, 1) and model.is_fitted()
    with pytest.raises(ValueError, match="grid: needs at least one value"):
        ChosenNetworkFitter(grid={"lm_goal": ()})
    with pytest.raises(ValueError, match="algo: unknown 'pso'"):
        ChosenNetworkFitter("pso")


def test_select_hybrid_chooses_the_seeds_mean_and_its_weight_on_the_blocks():
    """The candidates are the seeds' mean network at each weight; each one's blocked r is
    HybridNarx's blocked score with the same networks (checked against numpy in
    tests/identify/test_hybrid_validation.py); the best is kept only above the ARX's blocked r,
    and the model's network is the numpy mean of the seeds' networks fitted on the whole part."""
    from cdam_core.evaluate.papernets import _residual_fitter, select_hybrid
    from cdam_core.models import HybridNarx
    U, Y = _tanh_plant()
    grid = dict(iterations=2, lm_epochs=4)
    sel = select_hybrid(U, Y, decimations=(1,), passes=(0,), orders=(1,), delays=(1,),
                        features=("raw",), blocks=3, hidden=(2, 3), seeds=(0, 1),
                        weights=(0.5, 1.0), training=("one_step",), **grid)
    assert [(h, k, w) for h, k, w, _, _ in sel.ensembles] == [(2, 2, 0.5), (2, 2, 1.0),
                                                              (3, 2, 0.5), (3, 2, 1.0)]
    for h, _, w, rb, _ in sel.ensembles[1:3]:
        ref = HybridNarx((1, 1, 1), "raw", ensemble=2, weights=(w,), validation_blocks=3,
                         fit_residual=_residual_fitter("iboa", h, 0, grid["iterations"],
                                                       grid["lm_epochs"])).fit(U, Y)
        assert rb == pytest.approx(ref.validation_r_[w], abs=1e-12)
    arx = blocked_free_run_r(U, Y, (1, 1, 1), "raw", blocks=3)
    assert sel.validation_r["arx"] == arx
    best = max(sel.ensembles, key=lambda c: c[3])
    assert sel.chosen == best[:3] + best[4:] and sel.validation_r["network"] == best[3]
    assert sel.network_kept == (best[3] > arx)
    assert sel.model.residual_weight_ == (best[2] if sel.network_kept else 0.0)
    singles = [m for (h, *_), m in zip(sel.networks, sel.network_models) if h == best[0]]
    X = U[:-1]
    np.testing.assert_allclose(sel.model.net_.predict(X),
                               np.mean([m.net_.predict(X) for m in singles], axis=0),
                               rtol=1e-10, atol=1e-12)
