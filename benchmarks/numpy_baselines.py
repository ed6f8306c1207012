"""The fairest numpy baselines the benchmarks divide by (written for speed, unlike the
package's ``cdam_core.reference``, which is written for clarity and forms J explicitly).

Network layout as everywhere: theta = [W1(:); b1; W2(:); b2] (MATLAB column-major), W1 h x i,
W2 m x h, tanh hidden layer, linear output; e = T - Y, MSE = sum(e^2) / (N m).

``jtj_structured`` builds J'J and J'e from the network's structure without forming J
(80,000 x 308 at the paper's size). With x~ = [x, 1] and a~ = [a, 1]:
- output block: d y_k / d W2[k', j'] = delta_kk' a~_j', so J'J_oo = (A~'A~) kron I_m, one
  (h+1) x (h+1) product shared by all m outputs;
- hidden block: d y_k / d W1[j, l] = W2[k, j] a'_j x~_l, so with Z[n, l h + j] = a'_nj x~_nl
  (the sensitivities times the inputs), J'J_hh = (Z'Z) .* tile(W2'W2) (one SYRK of N x h(i+1));
- cross block: J'J_ho[l h + j, j' m + k] = W2[k, j] (Z'A~)[l h + j, j'];
- J'e: hidden [x~' ((E W2) .* A')](:) row-major, output (A~'E)(:) row-major.

``train_lm_structured`` is trainlm's epoch loop of ``cdam_core.reference.levenberg_marquardt``
(no validation set, no callback) on those pieces; tests/reference/test_numpy_baselines.py checks
its steps against ``reference.train_lm``.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg


def _unpack(theta, i, h, m):
    W1 = theta[:i * h].reshape(h, i, order="F")
    b1 = theta[i * h:i * h + h]
    W2 = theta[i * h + h:i * h + h + h * m].reshape(m, h, order="F")
    return W1, b1, W2, theta[i * h + h + h * m:]


def structured_macs(n: int, i: int, h: int) -> dict:
    """Multiply-adds of one J'J by :func:`jtj_structured` (lower triangles of the symmetric
    products) and by the reduced form that also uses the symmetry of the pairs of hidden units
    and of the pairs of inputs separately (Z'Z[(j,l),(j',l')] = sum a'_j a'_j' x~_l x~_l')."""
    ph = h * (i + 1)
    cross, out = (h + 1) * ph, (h + 1) * (h + 2) / 2
    hh_reduced = h * (h + 1) / 2 * ((i + 1) * (i + 2) / 2)
    return {"structured": n * (ph * (ph + 1) / 2 + cross + out),
            "reduced": n * (hh_reduced + cross + out)}


def jtj_structured(theta, X, T, h, jtj=True):
    """(J'J (D, D), J'e (D,), sse) of the 6-20-8-style tanh network, J never formed; with
    jtj=False, (None, J'e, sse)."""
    n, i = X.shape
    m = T.shape[1]
    W1, b1, W2, b2 = _unpack(theta, i, h, m)
    A = np.tanh(X @ W1.T + b1)
    E = T - (A @ W2.T + b2)
    dA = 1.0 - A * A
    ph = h * (i + 1)
    Z = np.empty((n, ph))
    Z3 = Z.reshape(n, i + 1, h)                       # column l h + j
    np.multiply(X[:, :, None], dA[:, None, :], out=Z3[:, :i, :])
    Z3[:, i, :] = dA
    At = np.empty((n, h + 1))
    At[:, :h] = A
    At[:, h] = 1.0
    Xt = np.empty((n, i + 1))
    Xt[:, :i] = X
    Xt[:, i] = 1.0
    Jte = np.concatenate([(Xt.T @ ((E @ W2) * dA)).ravel(), (At.T @ E).ravel()])
    if not jtj:
        return None, Jte, float(np.sum(E * E))
    D = ph + (h + 1) * m
    JtJ = np.empty((D, D))
    JtJ[:ph, :ph] = (Z.T @ Z) * np.tile(W2.T @ W2, (i + 1, i + 1))
    ho = ((Z.T @ At)[:, :, None] * np.tile(W2.T, (i + 1, 1))[:, None, :]).reshape(ph, -1)
    JtJ[:ph, ph:] = ho
    JtJ[ph:, :ph] = ho.T
    JtJ[ph:, ph:] = np.kron(At.T @ At, np.eye(m))
    return JtJ, Jte, float(np.sum(E * E))


def _mse(theta, X, T, h):
    n, i = X.shape
    m = T.shape[1]
    W1, b1, W2, b2 = _unpack(theta, i, h, m)
    E = T - (np.tanh(X @ W1.T + b1) @ W2.T + b2)
    return float(np.sum(E * E) / E.size)


def _solve(JtJ, Jte, mu):
    A = JtJ.copy()
    A.flat[::A.shape[0] + 1] += mu
    try:
        c = scipy.linalg.cho_factor(A, lower=True, overwrite_a=True, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    d = scipy.linalg.cho_solve(c, Jte, check_finite=False)
    return d if np.all(np.isfinite(d)) else None


def train_lm_structured(theta0, X, T, h, *, epochs, goal=0.0, mu=1e-3, mu_dec=0.1,
                        mu_inc=10.0, mu_max=1e10, min_grad=1e-7):
    """trainlm on :func:`jtj_structured`; returns (theta, {"mse": [...], "mu": [...], "stop"})."""
    theta = np.array(theta0, dtype=np.float64)
    mse = _mse(theta, X, T, h)
    hist = {"mse": [], "mu": [], "grad_norm": []}
    epoch = 0
    while True:
        # as the core: no J'J when a stop that does not read ||J'e|| ends the run
        last = mse <= goal or epoch == epochs or mu >= mu_max
        JtJ, Jte, _ = jtj_structured(theta, X, T, h, jtj=not last)
        gnorm = float(np.linalg.norm(Jte))
        hist["mse"].append(mse)
        hist["mu"].append(mu)
        hist["grad_norm"].append(gnorm)
        stop = ("goal" if mse <= goal else "epochs" if epoch == epochs else
                "min_grad" if gnorm <= min_grad else "mu_max" if mu >= mu_max else None)
        if stop is not None:
            hist["stop"] = stop
            return theta, hist
        while mu <= mu_max:
            d = _solve(JtJ, Jte, mu)
            if d is not None:
                trial = theta + d
                mse2 = _mse(trial, X, T, h)
                if mse2 < mse:
                    theta, mse = trial, mse2
                    mu = max(mu * mu_dec, 1e-20)
                    break
            mu *= mu_inc
        epoch += 1


def fitness_batched(thetas, X, T, h):
    """MSE of each network (rows of thetas): the first layers of all networks as one GEMM,
    one tanh over all hidden units, the output layers as one batched matmul."""
    P = thetas.shape[0]
    n, i = X.shape
    m = T.shape[1]
    W1t = thetas[:, :i * h].reshape(P, i, h)           # [p, l, j] = W1_p[j, l]
    b1 = thetas[:, i * h:i * h + h]
    W2t = thetas[:, i * h + h:i * h + h + h * m].reshape(P, h, m)   # [p, j, k] = W2_p[k, j]
    b2 = thetas[:, i * h + h + h * m:]
    Z = X @ W1t.transpose(1, 0, 2).reshape(i, P * h)
    Z += b1.reshape(-1)
    np.tanh(Z, out=Z)
    E = Z.reshape(n, P, h).transpose(1, 0, 2) @ W2t    # (P, n, m)
    E += b2[:, None, :]
    E -= T
    return np.einsum("pnk,pnk->p", E, E) / (n * m)


def fitness_loop(thetas, X, T, h):
    """MSE of each network, one vectorised forward pass per network (in the arrays' dtype:
    float32 arrays give float32 matmuls and numpy's float32 np.tanh)."""
    out = np.empty(thetas.shape[0])
    for p, th in enumerate(thetas):
        out[p] = _mse(th, X, T, h)
    return out
