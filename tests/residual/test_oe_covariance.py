"""Output error's standard deviations (residual.output_error.window_covariance) against the
sampling spread of the estimate itself, on a problem whose estimate is plain least squares:
W windows of n samples, residual e_w = y_w - X_w theta, the noise an AR(1) within each window
(phi 0.8) and independent between windows, the regressors slow within a window (as a
simulated window's sensitivities are). The estimate's standard deviation over 400 noise draws
is the reference (plain numpy here); the sandwich with windows as clusters matches it, the
independent-samples formula s^2 (X'X)^-1 is several times too small."""
import numpy as np

from cdam_core.residual.output_error import window_covariance

W, N, PHI, THETA = 120, 40, 0.8, np.array([1.0, 2.0])


class _Params:
    def __init__(self, theta):
        self.theta_ = {"a": float(theta[0]), "b": float(theta[1])}


def _problem(rng):
    t = np.arange(N) / N
    X = np.stack([np.column_stack([np.ones(N), np.sin(2 * np.pi * (t + rng.random()))])
                  for _ in range(W)])                                     # (W, N, 2)
    return X


def _noise(rng):
    e = np.empty((W, N))
    e[:, 0] = rng.normal(0, 1, W) / np.sqrt(1 - PHI ** 2)
    for k in range(1, N):
        e[:, k] = PHI * e[:, k - 1] + rng.normal(0, 1, W)
    return 0.01 * e


def test_sandwich_matches_the_spread_of_the_estimate():
    rng = np.random.default_rng(4)
    X = _problem(rng)
    A = X.reshape(-1, 2)
    draws = []
    for _ in range(400):
        y = X @ THETA + _noise(rng)
        draws.append(np.linalg.lstsq(A, y.ravel(), rcond=None)[0])
    spread = np.std(draws, axis=0, ddof=1)

    y = X @ THETA + _noise(rng)
    est = np.linalg.lstsq(A, y.ravel(), rcond=None)[0]

    def shooting(g, U, Y, starts, thetas=None, samples=False):
        assert samples
        return np.stack([y - X @ th for th in np.atleast_2d(thetas)])    # (G, W, N)
    scale = np.abs(est)
    sd, _, n = window_covariance(_Params(est), None, None, np.arange(W), shooting, ["a", "b"],
                                 est / scale, scale, np.full(2, -np.inf), np.full(2, np.inf))
    got = sd * scale
    assert n == N
    np.testing.assert_allclose(got, spread, rtol=0.25)
    r = y.ravel() - A @ est                       # the independent-samples formula
    naive = np.sqrt(np.diag(r @ r / (r.size - 2) * np.linalg.inv(A.T @ A)))
    assert np.all(naive < 0.5 * spread), (naive, spread)
