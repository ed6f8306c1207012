"""Preprocessing: five-point cubic smoothing and min-max scaling to [-1, 1] (C++ core)."""
from __future__ import annotations

import numpy as np

from cdam_core import _core
from cdam_core.base.checks import as_float_array, positive_int
from cdam_core.base.estimator import EstimatorParams

__all__ = ["five_point_cubic_smooth", "smooth_pair", "MinMaxScaler"]


def five_point_cubic_smooth(y, passes: int = 1) -> np.ndarray:
    """Five-point cubic smoothing of each column, repeated ``passes`` times.

    ``y`` is (N,) or (N, C) with N >= 5; float32 stays float32. Equals
    ``scipy.signal.savgol_filter(y, 5, 3, mode="interp", axis=0)`` per pass. ``passes=0``
    returns a copy.
    """
    passes = positive_int(passes, "passes", minimum=0)
    arr = as_float_array(y, "y", ndim=(1, 2))
    if arr.shape[0] < 5:
        raise ValueError(f"y: five-point smoothing needs at least 5 samples, got {arr.shape[0]}")
    return _core.five_point_cubic_smooth(arr, passes)


def smooth_pair(U, Y, passes: int):
    """Smooth inputs and outputs alike (``passes`` five-point passes; 0 = unchanged copies)."""
    U = np.asarray(U, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    if passes == 0:
        return U.copy(), Y.copy()
    return five_point_cubic_smooth(U, passes), five_point_cubic_smooth(Y, passes)


class MinMaxScaler(EstimatorParams):
    """Per-column min-max scaling to [-1, 1] (MATLAB mapminmax), fitted on training data only.

    A constant column (max == min) transforms to 0 and inverse-transforms to its constant.
    A scikit-learn transformer (``fit(X, y=None)``, ``transform``, ``fit_transform``,
    ``inverse_transform``; usable in a ``Pipeline``); it has no parameters.
    """

    _estimator_type = "transformer"

    def __init__(self):
        pass

    def fit(self, X, y=None) -> "MinMaxScaler":
        arr = as_float_array(X, "X", ndim=(2,))
        self.data_min_, self.data_max_ = _core.minmax_fit(arr)
        return self

    def is_fitted(self) -> bool:
        return getattr(self, "data_min_", None) is not None

    def _n_features(self) -> int:
        return self.data_min_.shape[0]

    def _check(self, X, name):
        if not self.is_fitted():
            raise ValueError("MinMaxScaler: not fitted; call fit(X) first")
        arr = as_float_array(X, name, ndim=(2,), dtype=self.data_min_.dtype)
        if arr.shape[1] != self.data_min_.shape[0]:
            raise ValueError(f"{name}: expected {self.data_min_.shape[0]} columns, "
                             f"got {arr.shape[1]}")
        return arr

    def transform(self, X) -> np.ndarray:
        return _core.minmax_apply(self._check(X, "X"), self.data_min_, self.data_max_, False)

    def inverse_transform(self, X) -> np.ndarray:
        return _core.minmax_apply(self._check(X, "X"), self.data_min_, self.data_max_, True)

    def fit_transform(self, X, y=None) -> np.ndarray:
        return self.fit(X).transform(X)
