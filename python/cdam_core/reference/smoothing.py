"""Five-point cubic smoothing (five-spot triple smoothing), numpy reference.

The least-squares cubic over a sliding 5-point window, with the two one-sided formulas at
each end (ALGORITHMS.md, "Five-point cubic smoothing"). Equals
``scipy.signal.savgol_filter(y, 5, 3, mode="interp", axis=0)``.
"""
from __future__ import annotations

import numpy as np

from cdam_core.reference._checks import float_array, integer


def _one_pass(y: np.ndarray) -> np.ndarray:
    """One smoothing pass along axis 0 of a 2-D (N, C) array, N >= 5."""
    out = np.empty_like(y)
    n = y.shape[0]
    out[0] = (69 * y[0] + 4 * y[1] - 6 * y[2] + 4 * y[3] - y[4]) / 70
    out[1] = (2 * y[0] + 27 * y[1] + 12 * y[2] - 8 * y[3] + 2 * y[4]) / 35
    out[2:n - 2] = (-3 * y[0:n - 4] + 12 * y[1:n - 3] + 17 * y[2:n - 2]
                    + 12 * y[3:n - 1] - 3 * y[4:n]) / 35
    out[n - 2] = (2 * y[n - 5] - 8 * y[n - 4] + 12 * y[n - 3] + 27 * y[n - 2]
                  + 2 * y[n - 1]) / 35
    out[n - 1] = (-y[n - 5] + 4 * y[n - 4] - 6 * y[n - 3] + 4 * y[n - 2] + 69 * y[n - 1]) / 70
    return out


def five_point_cubic_smooth(y, passes: int = 1) -> np.ndarray:
    """Smooth each column of ``y`` with the five-point cubic formulas, ``passes`` times.

    Parameters
    ----------
    y : array_like, shape (N,) or (N, C)
        Samples x channels; N >= 5; finite. float32 stays float32, other input becomes float64.
    passes : int, >= 0
        Number of passes; 0 returns a copy.

    Returns
    -------
    numpy.ndarray with the shape and float dtype of ``y``.
    """
    arr = float_array(y, "y", (1, 2))
    passes = integer(passes, "passes", minimum=0)
    if arr.shape[0] < 5:
        raise ValueError(f"y: needs at least 5 samples, got {arr.shape[0]}")
    work = arr.reshape(arr.shape[0], -1).copy()
    for _ in range(passes):
        work = _one_pass(work)
    return work.reshape(arr.shape)
