"""k-step (simulation) error of a recurrent residual network, numpy twin of
``cpp/include/cdam/host/kstep.hpp`` (``_core.kstep_jacobian``, ``kstep_normal``,
``kstep_train_lm``).

Model (ns states s, ne exogenous inputs e, H tanh units; theta = [W1(:); b1; W2(:); b2],
column-major, W1 H x (ns + ne), W2 ns x H)::

    x_t = [(s_t - m) / c, e_t];   s_{t+1} = s_t + d_t + r * (W2 tanh(W1 x_t + b1) + b2)
                                            + sum_l L_l s_{t-l}

with the optional linear part L = [L_0 .. L_{na-1}] (``lin``, ns x na ns; a linear base model
such as an ARX: L_0 = A_1 - I, L_l = A_{l+1}); states before a window's start are measured.

Windows of K steps from the measured state at each start a; residual (S[a + j] - s_hat_j) / q,
j = 1..K. Everything is vectorised over the windows; the Jacobian is carried forward as the
sensitivity G_j = d s_hat_j / d theta (W, ns, D), written here from the chain rule on the
unpacked weights (no shared code with the C++ core).
"""
from __future__ import annotations

import numpy as np

__all__ = ["kstep_num_params", "kstep_residuals", "kstep_jacobian", "kstep_lm"]


def kstep_num_params(ns: int, ne: int, hidden: int) -> int:
    return hidden * (ns + ne) + hidden + ns * hidden + ns


def _unpack(theta, ns, ni, H):
    W1 = theta[:H * ni].reshape(ni, H).T                  # column-major H x ni
    b1 = theta[H * ni:H * ni + H]
    o = H * ni + H
    W2 = theta[o:o + ns * H].reshape(H, ns).T             # column-major ns x H
    b2 = theta[o + ns * H:o + ns * H + ns]
    return W1, b1, W2, b2


def kstep_jacobian(theta, S, E, D, starts, K, hidden, in_mean, in_scale, out_scale, err_scale,
                   step_weight=None, lin=None, jacobian: bool = True):
    """(e, J) in the core's row order: row (w K + j) ns + i; the errors of step j + 1 times
    ``step_weight[j]`` (None: 1), or ``err_scale`` (K, ns): one scale per step and state;
    ``lin``: the linear part (None: none); J None without
    ``jacobian``."""
    theta = np.asarray(theta, float)
    S, E, D = (np.asarray(a, float) for a in (S, E, D))
    starts = np.asarray(starts, int)
    ns, ne, H = S.shape[1], E.shape[1], int(hidden)
    ni = ns + ne
    P = kstep_num_params(ns, ne, H)
    W1, b1, W2, b2 = _unpack(theta, ns, ni, H)
    m, c, r, q = (np.asarray(v, float) for v in (in_mean, in_scale, out_scale, err_scale))
    omega = np.ones(K) if step_weight is None else np.asarray(step_weight, float)
    qk = q if q.ndim == 2 else np.tile(q, (K, 1)) / omega[:, None]   # (K, ns) scales
    Wn = starts.size
    L = np.zeros((ns, 0)) if lin is None else np.asarray(lin, float)
    na = L.shape[1] // ns
    Ls = [L[:, l * ns:(l + 1) * ns] for l in range(na)]
    s = S[starts].copy()                                   # (W, ns)
    hist = [s]                                             # s_hat_0 .. s_hat_j
    G = np.zeros((Wn, ns, P))
    Gh = [G]                                               # G_0 .. G_j
    e = np.empty((Wn, K, ns))
    J = np.empty((Wn, K, ns, P)) if jacobian else None
    o_b1, o_W2 = H * ni, H * ni + H
    o_b2 = o_W2 + ns * H
    for j in range(K):
        t = starts + j
        x = np.concatenate([(s - m) / c, E[t]], axis=1)    # (W, ni)
        a = np.tanh(x @ W1.T + b1)                         # (W, H)
        out = r * (a @ W2.T + b2)                          # (W, ns)
        if jacobian:
            g = 1.0 - a * a
            dodz = r[None, :, None] * W2[None, :, :] * g[:, None, :]   # (W, ns, H)
            A = np.einsum("wih,hk->wik", dodz, W1[:, :ns]) / c        # (W, ns, ns)
            B = np.zeros((Wn, ns, P))
            # W1[h, k] sits at k H + h
            B[:, :, :H * ni] = (dodz[:, :, None, :] * x[:, None, :, None]).reshape(Wn, ns, -1)
            B[:, :, o_b1:o_W2] = dodz
            for i in range(ns):
                B[:, i, o_W2 + i:o_b2:ns] = r[i] * a         # W2[i, h] at h ns + i
                B[:, i, o_b2 + i] = r[i]
            Gn = G + np.einsum("wik,wkp->wip", A, G) + B
            for l in range(na):
                if j - l >= 1:
                    Gn = Gn + np.einsum("ik,wkp->wip", Ls[l], Gh[j - l])
            G = Gn
            Gh.append(G)
        lin_term = np.zeros_like(s)
        for l in range(na):
            past = hist[j - l] if j - l >= 0 else S[t - l]   # measured before the start
            lin_term += past @ Ls[l].T
        s = s + D[t] + out + lin_term
        hist.append(s)
        e[:, j] = (S[t + 1] - s) / qk[j]
        if jacobian:
            J[:, j] = G / qk[j][None, :, None]
    e = e.reshape(-1)
    return (e, J.reshape(-1, P)) if jacobian else (e, None)


def kstep_residuals(theta, S, E, D, starts, K, hidden, in_mean, in_scale, out_scale,
                    err_scale, step_weight=None, lin=None):
    return kstep_jacobian(theta, S, E, D, starts, K, hidden, in_mean, in_scale, out_scale,
                          err_scale, step_weight, lin, jacobian=False)[0]


def kstep_lm(theta0, args, epochs, mu=1e-3, mu_dec=0.1, mu_inc=10.0, mu_max=1e10,
             min_grad=1e-7):
    """trainlm's loop (reference.levenberg_marquardt's order of stop tests, no validation) on
    the k-step error; ``args`` = (S, E, D, starts, K, hidden, in_mean, in_scale, out_scale,
    err_scale[, step_weight[, lin]]). Returns (theta, mse history)."""
    theta = np.array(theta0, float)

    def mse_of(th):
        e = kstep_residuals(th, *args)
        return float(e @ e / e.size)

    mse, hist = mse_of(theta), []
    for epoch in range(epochs + 1):
        e, J = kstep_jacobian(theta, *args)
        Jte = J.T @ e
        hist.append(mse)
        if epoch == epochs or np.linalg.norm(Jte) <= min_grad or mu >= mu_max:
            break
        JtJ = J.T @ J
        while mu <= mu_max:
            try:
                L = np.linalg.cholesky(JtJ + mu * np.eye(JtJ.shape[0]))
                d = np.linalg.solve(L.T, np.linalg.solve(L, Jte))
                mse2 = mse_of(theta + d)
            except np.linalg.LinAlgError:
                mse2 = np.inf
            if mse2 < mse:
                theta, mse = theta + d, mse2
                mu = max(mu * mu_dec, 1e-20)
                break
            mu *= mu_inc
    return theta, np.array(hist)
