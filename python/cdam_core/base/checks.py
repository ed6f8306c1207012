"""Input checks shared by the public API: every error names the argument and the problem."""
from __future__ import annotations

import numbers

import numpy as np


def as_float_array(x, name: str, ndim: tuple[int, ...] = (2,), min_rows: int = 1,
                   dtype=None) -> np.ndarray:
    """Return ``x`` as a float32/float64 ndarray after checking it.

    float32 stays float32 and float64 stays float64 (unless ``dtype`` forces one); integer and
    boolean arrays become float64. Raises ValueError for other dtypes, the wrong number of
    dimensions, empty arrays, too few rows, NaN or Inf.
    """
    if x is None:
        raise ValueError(f"{name}: missing (got None)")
    if type(x).__module__.startswith("scipy.sparse"):
        raise ValueError(f"{name}: sparse input is not supported; pass a dense array "
                         "(x.toarray())")
    try:
        arr = np.asarray(x)
    except Exception as exc:  # ragged lists and the like
        raise ValueError(f"{name}: cannot be read as an array ({exc})") from None
    if arr.dtype.kind in "iub":
        arr = arr.astype(np.float64)
    elif arr.dtype.kind != "f" or arr.dtype.itemsize not in (4, 8):
        raise ValueError(f"{name}: dtype {arr.dtype} is not supported; pass float32 or float64")
    if dtype is not None:
        arr = arr.astype(dtype, copy=False)
    if not arr.dtype.isnative:
        arr = arr.astype(arr.dtype.newbyteorder("="))
    if arr.ndim not in ndim:
        want = " or ".join(f"{d}-D" for d in ndim)
        raise ValueError(f"{name}: expected a {want} array, got {arr.ndim}-D with shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name}: empty array (shape {arr.shape})")
    if arr.shape[0] < min_rows:
        raise ValueError(f"{name}: needs at least {min_rows} samples, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name}: contains NaN or Inf (first at index {tuple(int(i) for i in bad)})")
    return arr


def as_2d(x, name: str, min_rows: int = 1, dtype=None) -> np.ndarray:
    """Like as_float_array; a 1-D array is taken as one channel (N, 1)."""
    arr = as_float_array(x, name, ndim=(1, 2), min_rows=min_rows, dtype=dtype)
    return arr[:, None] if arr.ndim == 1 else arr


def same_rows(a: np.ndarray, b: np.ndarray, names: str) -> None:
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"{names}: mismatched sample counts ({a.shape[0]} and {b.shape[0]})")


def positive_int(v, name: str, minimum: int = 1) -> int:
    if isinstance(v, bool) or not isinstance(v, numbers.Integral):
        raise ValueError(f"{name}: must be an integer, got {v!r}")
    if v < minimum:
        raise ValueError(f"{name}: must be >= {minimum}, got {v}")
    return int(v)


def finite_float(v, name: str, minimum: float | None = None, strict: bool = False) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: must be a number, got {v!r}") from None
    if not np.isfinite(f):
        raise ValueError(f"{name}: must be finite, got {v!r}")
    if minimum is not None and (f <= minimum if strict else f < minimum):
        raise ValueError(f"{name}: must be {'>' if strict else '>='} {minimum}, got {v!r}")
    return f
