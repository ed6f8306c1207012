"""Independent numpy twins of every ``cdam_core`` core kernel (never calls the C++ ``_core``).

Tests compare the compiled core against these functions; they are written for clarity and
checked against independent references (scipy, finite differences, closed forms), not speed.

Conventions
-----------
- Data are samples x channels: 2-D (N, C) arrays (smoothing also takes 1-D (N,)).
- dtype: float32 input is computed and returned in float32; float64 (or integer) input in
  float64; mixing float32 with float64 computes in float64. Bool, complex and object input is
  rejected. Training histories are float64 whatever the data dtype.
- Bad input raises ``ValueError("<argument>: <problem>")``: NaN/Inf, wrong rank, empty, sample
  counts that differ, a theta of the wrong length, zero hidden nodes, negative passes.
- Network: theta = [W1(:); b1; W2(:); b2], MATLAB column-major, W1 h x i, W2 m x h,
  D = i*h + h + h*m + m; hidden "tansig" (tanh) or "logsig" (1 / (1 + exp(-x))); linear output.
  e = T - Y; MSE = sum(e^2) / (N m); Jacobian rows are sample-major (row n*m + k is
  d Y[n, k] / d theta), and J'e uses e flattened the same way, so grad = -2 / (N m) J'e.
- Scaling: per column to [-1, 1] (mapminmax); a constant column maps to 0 and back to its
  constant.
- Levenberg-Marquardt follows trainlm; the exact epoch loop shared with C++ is in
  :mod:`cdam_core.reference.levenberg_marquardt`. mu is kept in double precision.
- NARX: t0 = max(na, nk + nb - 1); regressor [Y[t-1..t-na], U[t-nk..t-nk-nb+1]], channels
  fastest.
- Randomness: :class:`Rng` (xoshiro128**), the same stream as C++ ``cdam::Rng``.
- Trainers take ``callback(epoch, mse)``, called after the stop tests of each recorded epoch;
  returning False stops with "cancelled" (as the core). They take no ``threads``.
- ``BPNetwork`` and ``hidden_node_candidates`` (:mod:`cdam_core.reference.network`): a small
  estimator written on these kernels alone; it shares no code with the package's estimator.
- :mod:`cdam_core.reference.simulator`: the numpy integrator of the coupled simulator and
  :mod:`cdam_core.reference.optimisers`: BOA, IBOA, CABC (imported by name, not with ``*``).

Example
-------
>>> import numpy as np
>>> from cdam_core import reference as ref
>>> ref.five_point_cubic_smooth(np.arange(6.0)).tolist()
[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
"""
from cdam_core.reference.gradient_descent import train_gd
from cdam_core.reference.levenberg_marquardt import train_lm
from cdam_core.reference.mlp import (mlp_forward, mlp_jacobian, mlp_jtj, mlp_mse_gradient, mlp_num_params,
                  mlp_unpack)
from cdam_core.reference.narx import narx_regressors, narx_simulate, narx_start
from cdam_core.reference.network import BPNetwork, hidden_node_candidates
from cdam_core.reference.rng import Rng
from cdam_core.reference.scaling import MinMaxScaler
from cdam_core.reference.smoothing import five_point_cubic_smooth

__all__ = [
    "BPNetwork",
    "MinMaxScaler",
    "Rng",
    "five_point_cubic_smooth",
    "hidden_node_candidates",
    "mlp_forward",
    "mlp_jacobian",
    "mlp_jtj",
    "mlp_mse_gradient",
    "mlp_num_params",
    "mlp_unpack",
    "narx_regressors",
    "narx_simulate",
    "narx_start",
    "train_gd",
    "train_lm",
]

