"""One-hidden-layer BP network (MATLAB feedforwardnet layout), numpy reference.

Parameters are one flat vector theta = [W1(:); b1; W2(:); b2] in MATLAB column-major order,
W1 h x i, W2 m x h, D = i*h + h + h*m + m. Hidden activation tansig (tanh) or logsig
(1 / (1 + exp(-x))), linear output. Data are sample-major: X (N, i), T and Y (N, m).
Provides the batch forward pass, the MSE and its gradient by backpropagation, the Jacobian of
the outputs with respect to theta, and the Gauss-Newton pieces J'J, J'e formed plainly with BLAS.
"""
from __future__ import annotations

import numpy as np

from cdam_core.reference._checks import activation as check_activation
from cdam_core.reference._checks import common_dtype, float_array, integer, same_rows


def mlp_num_params(i: int, h: int, m: int) -> int:
    """Length D = i*h + h + h*m + m of theta for i inputs, h hidden nodes and m outputs."""
    i = integer(i, "i", minimum=1)
    h = integer(h, "hidden", minimum=1)
    m = integer(m, "outputs", minimum=1)
    return i * h + h + h * m + m


def mlp_unpack(theta, i: int, h: int, m: int):
    """Split theta into (W1 (h, i), b1 (h,), W2 (m, h), b2 (m,)), MATLAB column-major order.

    The returned arrays are copies in theta's float dtype.
    """
    d = mlp_num_params(i, h, m)
    th = float_array(theta, "theta", 1)
    if th.shape[0] != d:
        raise ValueError(f"theta: has length {th.shape[0]}, expected {d} for "
                         f"i={i}, hidden={h}, outputs={m}")
    return _unpack(th, i, h, m)


def _unpack(th, i, h, m):
    k = 0
    W1 = th[k:k + i * h].reshape(h, i, order="F").copy()
    k += i * h
    b1 = th[k:k + h].copy()
    k += h
    W2 = th[k:k + h * m].reshape(m, h, order="F").copy()
    k += h * m
    b2 = th[k:k + m].copy()
    return W1, b1, W2, b2


def _pack(W1, b1, W2, b2):
    return np.concatenate([W1.ravel(order="F"), b1, W2.ravel(order="F"), b2])


def _act(z, activation):
    """Activation and its derivative expressed through the activation value."""
    if activation == "tansig":
        a = np.tanh(z)
        return a, 1 - a * a
    with np.errstate(over="ignore", under="ignore"):
        a = 1 / (1 + np.exp(-z))
    return a, a * (1 - a)


def _prepare(theta, X, hidden, outputs, activation, T=None):
    """Validate and return (theta, X, T, h, m, dtype) with a common float dtype."""
    check_activation(activation)
    h = integer(hidden, "hidden", minimum=1)
    th = float_array(theta, "theta", 1)
    x = float_array(X, "X", 2)
    arrays = [th, x]
    t = None
    if T is not None:
        t = float_array(T, "T", 2)
        same_rows(x, t, "X", "T")
        arrays.append(t)
        m = t.shape[1]
    else:
        m = integer(outputs, "outputs", minimum=1)
    d = x.shape[1] * h + h + h * m + m
    if th.shape[0] != d:
        raise ValueError(f"theta: has length {th.shape[0]}, expected {d} for "
                         f"i={x.shape[1]}, hidden={h}, outputs={m}")
    dtype = common_dtype(*arrays)
    th, x = th.astype(dtype, copy=False), x.astype(dtype, copy=False)
    if t is not None:
        t = t.astype(dtype, copy=False)
    return th, x, t, h, m


def _forward(th, x, h, m, activation):
    """Forward pass on validated arrays: returns (Y, A, dA) with dA the activation slope."""
    W1, b1, W2, b2 = _unpack(th, x.shape[1], h, m)
    A, dA = _act(x @ W1.T + b1, activation)
    return A @ W2.T + b2, A, dA, W2


def mlp_forward(theta, X, hidden: int, outputs: int, activation: str = "tansig") -> np.ndarray:
    """Network outputs Y (N, outputs) for inputs X (N, i).

    float32 theta and X compute in float32; any float64 argument makes the result float64.
    """
    th, x, _, h, m = _prepare(theta, X, hidden, outputs, activation)
    return _forward(th, x, h, m, activation)[0]


def mlp_mse_gradient(theta, X, T, hidden: int, activation: str = "tansig"):
    """MSE = sum(e^2) / (N m), e = T - Y, and its gradient d MSE / d theta (shape (D,)).

    Backpropagation: G = -2 e / (N m); dW2 = G' A, db2 = sum G; dZ = (G W2) .* act'(Z);
    dW1 = dZ' X, db1 = sum dZ; packed as [dW1(:); db1; dW2(:); db2].
    """
    th, x, t, h, m = _prepare(theta, X, hidden, None, activation, T=T)
    Y, A, dA, W2 = _forward(th, x, h, m, activation)
    e = t - Y
    nm = e.size
    mse = float(np.sum(e * e) / nm)
    G = (-2 / nm) * e                    # N x m, d mse / d Y
    dZ = (G @ W2) * dA                   # N x h
    grad = _pack(dZ.T @ x, dZ.sum(axis=0), G.T @ A, G.sum(axis=0))
    return mse, grad.astype(th.dtype, copy=False)


def _jacobian(th, x, h, m, activation):
    Y, A, dA, W2 = _forward(th, x, h, m, activation)
    n, i = x.shape
    S = W2[None, :, :] * dA[:, None, :]                        # N x m x h: dY[n,k]/dZ[n,j]
    jw1 = (x[:, None, :, None] * S[:, :, None, :]).reshape(n, m, i * h)   # index j + l*h
    eye = np.eye(m, dtype=th.dtype)
    jw2 = (A[:, None, :, None] * eye[None, :, None, :]).reshape(n, m, h * m)  # index k' + j*m
    jb2 = np.broadcast_to(eye, (n, m, m))
    J = np.concatenate([jw1, S, jw2, jb2], axis=2).reshape(n * m, -1)
    return J, Y


def mlp_jacobian(theta, X, hidden: int, outputs: int, activation: str = "tansig") -> np.ndarray:
    """Jacobian J (N*m, D) of the outputs: row n*m + k is d Y[n, k] / d theta."""
    th, x, _, h, m = _prepare(theta, X, hidden, outputs, activation)
    return _jacobian(th, x, h, m, activation)[0]


def mlp_jtj(theta, X, T, hidden: int, activation: str = "tansig"):
    """Gauss-Newton pieces (J'J (D, D), J'e (D,), sse) with e = T - Y, formed from J with BLAS.

    e is flattened sample-major (entry n*m + k), matching the rows of :func:`mlp_jacobian`;
    the MSE gradient is -2 / (N m) * J'e.
    """
    th, x, t, h, m = _prepare(theta, X, hidden, None, activation, T=T)
    J, Y = _jacobian(th, x, h, m, activation)
    e = (t - Y).reshape(-1)
    return J.T @ J, J.T @ e, float(e @ e)
