"""Real data: the AR.Drone 2.0 flight (../shared/data/ardrone2; tud-cor/ardrone2_dem_filter,
Apache-2.0). Identify on the first 75 %, test on the last 25 % (decimated to 30 Hz)."""
import numpy as np
import pytest

from cdam_core.identify import IdentifyConfig, evaluate, identify

ardrone2 = pytest.importorskip("cdam_core.realdata.ardrone2")


@pytest.fixture(scope="module")
def split():
    try:
        ds = ardrone2.load_ardrone2()
    except FileNotFoundError:
        pytest.skip("shared AR.Drone data not present")
    U, Y = ds.select(ds.inputs)[::4], ds.select(ds.outputs)[::4]
    n = int(0.75 * len(U))
    return U[:n], Y[:n], U[n:], Y[n:], ds.outputs


def _linear_baseline(U, Y, Ut):
    """Static linear ARX(0, 1, 0) baseline y = [u, 1] W fitted by numpy least squares."""
    W = np.linalg.lstsq(np.c_[U, np.ones(len(U))], Y, rcond=None)[0]
    return np.c_[Ut, np.ones(len(Ut))] @ W


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
