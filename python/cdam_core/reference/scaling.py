"""Min-max scaling to [-1, 1] per column (MATLAB ``mapminmax``), numpy reference.

x' = 2 (x - xmin) / (xmax - xmin) - 1 and back x = (x' + 1) (xmax - xmin) / 2 + xmin.
A constant column (xmax == xmin) maps to 0 and inverse-maps to its constant.
"""
from __future__ import annotations

import numpy as np

from cdam_core.reference._checks import float_array


class MinMaxScaler:
    """Per-column min-max scaler to [-1, 1], fitted on training data only.

    Arrays are 2-D samples x channels (N, C); 1-D input is rejected. float32 input gives
    float32 output; everything else works in float64.

    Attributes
    ----------
    data_min_, data_max_ : numpy.ndarray, shape (C,)
        Column minima and maxima seen by :meth:`fit`.
    n_features_in_ : int
        Number of columns C.
    """

    def __init__(self):
        self.data_min_ = None
        self.data_max_ = None
        self.n_features_in_ = None

    def fit(self, X) -> "MinMaxScaler":
        """Record the per-column minimum and maximum of ``X`` (N, C); returns ``self``."""
        arr = float_array(X, "X", 2)
        self.data_min_ = arr.min(axis=0)
        self.data_max_ = arr.max(axis=0)
        self.n_features_in_ = arr.shape[1]
        return self

    def _checked(self, X) -> np.ndarray:
        if self.data_min_ is None:
            raise ValueError("X: the scaler is not fitted; call fit first")
        arr = float_array(X, "X", 2)
        if arr.shape[1] != self.n_features_in_:
            raise ValueError(f"X: has {arr.shape[1]} columns, the scaler was fitted on "
                             f"{self.n_features_in_}")
        return arr

    def _params(self, dtype):
        lo = self.data_min_.astype(dtype)
        span = self.data_max_.astype(dtype) - lo
        constant = span == 0
        return lo, span, constant

    def transform(self, X) -> np.ndarray:
        """Map ``X`` to [-1, 1] per column (constant columns to 0)."""
        arr = self._checked(X)
        lo, span, constant = self._params(arr.dtype)
        safe = np.where(constant, 1, span)
        out = 2 * (arr - lo) / safe - 1
        out[:, constant] = 0
        return out

    def inverse_transform(self, X) -> np.ndarray:
        """Map scaled values back to data units (constant columns to their constant)."""
        arr = self._checked(X)
        lo, span, constant = self._params(arr.dtype)
        out = (arr + 1) * span / 2 + lo
        out[:, constant] = lo[constant]
        return out

    def fit_transform(self, X) -> np.ndarray:
        """:meth:`fit` then :meth:`transform` on the same ``X``."""
        return self.fit(X).transform(X)
