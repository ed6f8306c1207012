"""The joint output-error estimate's standard deviations
(residual.output_error.joint_covariance): each window's own state columns projected out of the
parameters' sensitivities, then the cluster-robust sandwich over windows.

On a linear problem with per-window nuisance columns (the windows' states: an offset and a
slope per window, W windows of n samples, two shared parameters): the reference is plain
numpy written here, least squares of the whole problem with every window's nuisance columns
(P + 2W unknowns) and the sandwich of that whole problem (bread: the inverse of its J'J,
meat: the windows' scores over all columns) read at the parameters' block, times
W / (W - P). The same reference on the parameters' own columns alone (no projection) is
far off, so the projection is what is tested. The sandwich also matches the spread of the
estimate over noise draws (AR(1) noise within each window, independent between windows)."""
import numpy as np
import pytest
from scipy.signal import lfilter
from threadpoolctl import threadpool_limits

from cdam_core.residual.output_error import joint_covariance

W, N, P, PHI = 60, 30, 2, 0.8
THETA = np.array([1.0, -0.5])


@pytest.fixture(autouse=True)
def _one_blas_thread():
    """numpy's BLAS on one thread: this file's small dense algebra took 2-3 s, not 0.1 s, with
    a thread per core on a busy 2-core machine (measured)."""
    with threadpool_limits(1, user_api="blas"):
        yield


def _problem(rng):
    t = np.linspace(-1.0, 1.0, N)
    X = np.stack([np.column_stack([np.sin(3 * t + 6 * rng.random()),
                                   t ** 2 + 0.3 * rng.normal(size=N)]) for _ in range(W)])
    S = np.stack([np.column_stack([np.ones(N), t])] * W)                  # (W, N, 2)
    return X, S


def _noise(rng):
    """AR(1) within each window from its stationary start, independent between windows."""
    w = rng.normal(0, 1, (W, N))
    w[:, 0] /= np.sqrt(1 - PHI ** 2)
    return 0.01 * lfilter([1.0], [1.0, -PHI], w, axis=1)


def _full(X, S):
    """The whole problem's design: the parameters' columns, then each window's two."""
    J = np.zeros((W * N, P + 2 * W))
    for w in range(W):
        J[w * N:(w + 1) * N, :P] = X[w]
        J[w * N:(w + 1) * N, P + 2 * w:P + 2 * w + 2] = S[w]
    return J


class _Linear:
    """The windows' residuals y_w - X_w theta - S_w b_w at z = (theta, b_1 .. b_W), with the
    interface joint_covariance reads (as output_error._JointWindows')."""

    def __init__(self, X, S, y):
        self.X, self.S, self.y, self.P = X, S, y, P

    def _res(self, z):
        b = z[P:].reshape(W, 2)
        return self.y - self.X @ z[:P] - np.einsum("wnk,wk->wn", self.S, b)

    def sensitivities(self, z, h, hs, central=False):
        cols = []
        for j in range(P + 2):
            d = np.zeros(P + 2 * W)
            if j < P:
                d[j] = h[j]
            else:
                d[P + (j - P)::2] = hs
            lo = self._res(z - d) if central else self._res(z)
            step = h[j] if j < P else hs
            cols.append((self._res(z + d) - lo) / (step * (2 if central else 1)))
        return self._res(z), np.stack(cols)


def test_projected_sandwich_is_the_whole_problems_sandwich():
    rng = np.random.default_rng(7)
    X, S = _problem(rng)
    y = X @ THETA + np.einsum("wnk,wk->wn", S, rng.normal(0, 1, (W, 2))) + _noise(rng)
    J = _full(X, S)
    z = np.linalg.lstsq(J, y.ravel(), rcond=None)[0]
    e = (y.ravel() - J @ z).reshape(W, N)
    Ai = np.linalg.inv(J.T @ J)
    scores = np.stack([J[w * N:(w + 1) * N].T @ e[w] for w in range(W)])
    ref = np.sqrt(np.diag(Ai @ scores.T @ scores @ Ai)[:P] * W / (W - P))

    got = joint_covariance(_Linear(X, S, y), z, np.full(P, -np.inf), np.full(P, np.inf))
    np.testing.assert_allclose(got, ref, rtol=1e-6)
    # without the projection (the parameters' columns alone): not the same
    Jp = J[:, :P]
    Bi = np.linalg.inv(Jp.T @ Jp)
    sp = np.stack([X[w].T @ e[w] for w in range(W)])
    plain = np.sqrt(np.diag(Bi @ sp.T @ sp @ Bi) * W / (W - P))
    assert np.all(np.abs(plain / ref - 1) > 0.2), (plain, ref)


def test_projected_sandwich_matches_the_spread_of_the_estimate():
    rng = np.random.default_rng(11)
    X, S = _problem(rng)
    J = _full(X, S)
    b = rng.normal(0, 1, (W, 2))
    Jplus = np.linalg.pinv(J)                    # least squares of every draw
    draws, sds = [], []
    for _ in range(300):
        y = X @ THETA + np.einsum("wnk,wk->wn", S, b) + _noise(rng)
        z = Jplus @ y.ravel()
        draws.append(z[:P])
        if len(sds) < 20:
            sds.append(joint_covariance(_Linear(X, S, y), z, np.full(P, -np.inf),
                                        np.full(P, np.inf)))
    spread = np.std(draws, axis=0, ddof=1)       # uncertain by about 4 % (300 draws)
    np.testing.assert_allclose(np.mean(sds, axis=0), spread, rtol=0.2)
