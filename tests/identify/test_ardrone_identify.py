"""Real data: the AR.Drone 2.0 flight (data/ardrone2; tud-cor/ardrone2_dem_filter,
Apache-2.0). Identify on the first 75 %, test on the last 25 % (decimated to 30 Hz).

The baselines are computed here independently with numpy least squares and their own
regressor and simulation loops (nothing from cdam_core.models.hybrid)."""
import numpy as np
import pytest

from cdam_core.evaluate import evaluate
from cdam_core.identify import IdentifyConfig, identify, select_structure

from cdam_core.record.realdata import ardrone2
from numpy_arx import arx_free_run


@pytest.fixture(scope="module")
def split(bundled_record):
    ds = ardrone2.load_ardrone2(bundled_record(ardrone2.ARDRONE2_FILE))   # ships in data/
    U, Y = ds.select(ds.inputs)[::4], ds.select(ds.outputs)[::4]
    n = int(0.75 * len(U))
    return U[:n], Y[:n], U[n:], Y[n:], ds.outputs


def _linear_baseline(U, Y, Ut):
    """Static linear ARX(0, 1, 0) baseline y = [u, 1] W fitted by numpy least squares."""
    W = np.linalg.lstsq(np.c_[U, np.ones(len(U))], Y, rcond=None)[0]
    return np.c_[Ut, np.ones(len(Ut))] @ W


def _r_rmse(Y, P):
    r = np.array([np.corrcoef(Y[:, k], P[:, k])[0, 1] for k in range(Y.shape[1])])
    rmse = np.sqrt(np.mean((Y - P) ** 2, axis=0))
    return r, rmse, rmse / np.std(Y, axis=0)


def test_static_iboa_bp_beats_the_linear_baseline(split):
    U, Y, Ut, Yt, names = split
    cfg = IdentifyConfig(hidden=10, iterations=20, smoothing_passes=0)
    run = identify("iboa", U, Y, seed=0, config=cfg)
    m = evaluate(run.model, Ut, Yt, names)["one_step"]
    P = _linear_baseline(U, Y, Ut)
    r_lin = np.mean([np.corrcoef(Yt[:, k], P[:, k])[0, 1] for k in range(Yt.shape[1])])
    nrmse_lin = np.mean(np.sqrt(np.mean((Yt - P) ** 2, axis=0)) / np.std(Yt, axis=0))
    r_net = np.mean([v["r"] for v in m.values()])
    nrmse_net = np.mean([v["nrmse"] for v in m.values()])
    # measured here: r 0.24 against -0.07; NRMSE 1.79 against 1.73 (both worse than the mean:
    # a static map cannot follow the drifting pose; the correlation is what the network wins)
    assert r_net > r_lin + 0.1
    assert nrmse_net < 1.2 * nrmse_lin


def test_hybrid_beats_the_independent_arx4_baseline_in_free_run(split):
    """Structure chosen on the training part only; free run on the held-out 25 %."""
    U, Y, Ut, Yt, names = split
    sel = select_structure(U, Y)  # orders, delay, features by validation inside U, Y
    cfg = IdentifyConfig(hidden=5, iterations=20, lm_epochs=30, smoothing_passes=0,
                         model="hybrid", narx=sel["narx"], features=sel["features"])
    run = identify("iboa", U, Y, seed=0, config=cfg)
    P_h = run.model.predict(Ut, Yt, mode="free_run")
    P_a = arx_free_run(U, Y, Ut, Yt)
    s = slice(4, None)  # both models' first predicted sample onwards (ARX(4): t0 = 4)
    r_h, rmse_h, nr_h = _r_rmse(Yt[s], P_h[s])
    r_a, rmse_a, nr_a = _r_rmse(Yt[s], P_a[s])
    # measured here: selected (4, 4, 0) with physics features; hybrid mean r 0.65, NRMSE 0.88
    # (the residual network was dropped: alpha 0 on validation); ARX(4) mean r 0.39, NRMSE 6.45
    # (its Y and phi drift away in free run)
    assert r_h.mean() > r_a.mean() + 0.15
    assert nr_h.mean() < nr_a.mean()
    assert np.sum(r_h > r_a) >= 4  # better on most outputs, not only on average
    # most of that gain is the direct term u(t) (nk = 0): ARX(4) with nk = 0 measured here mean
    # r 0.61, NRMSE 1.13; the physics features add a little correlation and cut the error
    r_0, _, nr_0 = _r_rmse(Yt[s], arx_free_run(U, Y, Ut, Yt, nk=0)[s])
    assert r_h.mean() > r_0.mean() + 0.01
    assert nr_h.mean() < 0.85 * nr_0.mean()
    # the pipeline's own metrics agree with the independent computation
    m = evaluate(run.model, Ut, Yt, names)["free_run"]
    t0 = run.model.t0
    r_own, _, _ = _r_rmse(Yt[t0:], P_h[t0:])
    assert [m[n]["r"] for n in names] == pytest.approx(r_own, abs=1e-12)



@pytest.mark.parametrize("algo", ["iboa", "boa", "cabc", "bp"])
def test_every_algorithm_static_narx_and_hybrid_on_the_test_part(split, algo):
    """The comparison behind the report (under a second per algorithm): for each algorithm the
    paper's static network, a NARX network (2, 2, 1) in free run and the hybrid in free run,
    against the ARX(4) baseline. Measured here (mean r over outputs, seeds 0-2): static
    0.17-0.22, NARX network -0.01 to 0.23 (it drifts), hybrid 0.65-0.69, ARX(4) 0.39."""
    U, Y, Ut, Yt, names = split
    s = slice(4, None)
    r_arx = _r_rmse(Yt[s], arx_free_run(U, Y, Ut, Yt)[s])[0].mean()
    static = identify(algo, U, Y, seed=0, config=IdentifyConfig(hidden=10, iterations=20,
                                                                 smoothing_passes=0)).model
    r_static = _r_rmse(Yt[s], static.predict(Ut)[s])[0].mean()
    narx = identify(algo, U, Y, seed=0, config=IdentifyConfig(hidden=10, iterations=20,
                                                               smoothing_passes=0,
                                                               narx=(2, 2, 1))).model
    try:
        P = narx.predict(Ut, Yt, mode="free_run")
        r_narx = _r_rmse(Yt[s], P[s])[0].mean() if np.all(np.isfinite(P)) else -1.0
    except ValueError:
        r_narx = -1.0
    sel = select_structure(U, Y)
    hyb = identify(algo, U, Y, seed=0, config=IdentifyConfig(
        hidden=5, iterations=20, lm_epochs=30, smoothing_passes=0, model="hybrid",
        narx=sel["narx"], features=sel["features"])).model
    r_hyb = _r_rmse(Yt[s], hyb.predict(Ut, Yt, mode="free_run")[s])[0].mean()
    assert r_hyb > max(r_arx, r_static, r_narx) + 0.1
