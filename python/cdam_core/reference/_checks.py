"""Input checks shared by the numpy reference kernels.

Every public reference function validates its arguments here first and raises
``ValueError("<arg>: <problem>")``. This module is deliberately independent of
``cdam_core.base.checks`` so that the reference never depends on code it is compared with.
"""
from __future__ import annotations

import numbers

import numpy as np

ACTIVATIONS = ("tansig", "logsig")


def float_array(x, name: str, ndim: int | tuple[int, ...], *, allow_empty: bool = False,
                dtype=None) -> np.ndarray:
    """Return ``x`` as a float32/float64 array after checking dtype, rank, size and finiteness.

    float32 stays float32, float64 stays float64; integer input becomes float64; bool, complex,
    object and string input is rejected. ``dtype`` forces the result type.
    """
    try:
        arr = np.asarray(x)
    except Exception as exc:  # ragged lists and the like
        raise ValueError(f"{name}: cannot be read as an array ({exc})") from None
    kind = arr.dtype.kind
    if kind == "b" or kind not in "iuf":
        raise ValueError(f"{name}: must hold real numbers, got dtype {arr.dtype}")
    if dtype is not None:
        arr = arr.astype(dtype, copy=False)
    elif arr.dtype not in (np.float32, np.float64):
        arr = arr.astype(np.float64)
    ndims = (ndim,) if isinstance(ndim, int) else tuple(ndim)
    if arr.ndim not in ndims:
        want = " or ".join(f"{d}-D" for d in ndims)
        raise ValueError(f"{name}: must be {want}, got shape {arr.shape}")
    if arr.size == 0 and not allow_empty:
        raise ValueError(f"{name}: is empty (shape {arr.shape})")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or Inf")
    return arr


def common_dtype(*arrays: np.ndarray):
    """float32 when every array is float32, else float64."""
    return np.float32 if all(a.dtype == np.float32 for a in arrays) else np.float64


def integer(value, name: str, minimum: int | None = None, maximum: int | None = None) -> int:
    """Check that ``value`` is an integer (not bool) inside [minimum, maximum]."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name}: must be an integer, got {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise ValueError(f"{name}: must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise ValueError(f"{name}: must be <= {maximum}, got {value}")
    return value


def real(value, name: str, *, minimum: float | None = None, maximum: float | None = None,
         strict_min: bool = False, strict_max: bool = False) -> float:
    """Check that ``value`` is a finite real number inside the given bounds."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name}: must be a real number, got {value!r}")
    value = float(value)
    if not np.isfinite(value):
        raise ValueError(f"{name}: must be finite, got {value}")
    if minimum is not None and (value < minimum or (strict_min and value == minimum)):
        op = ">" if strict_min else ">="
        raise ValueError(f"{name}: must be {op} {minimum}, got {value}")
    if maximum is not None and (value > maximum or (strict_max and value == maximum)):
        op = "<" if strict_max else "<="
        raise ValueError(f"{name}: must be {op} {maximum}, got {value}")
    return value


def activation(name) -> str:
    """Check the hidden-layer activation name."""
    if name not in ACTIVATIONS:
        raise ValueError(f"activation: must be one of {ACTIVATIONS}, got {name!r}")
    return name


def same_rows(a: np.ndarray, b: np.ndarray, name_a: str, name_b: str) -> None:
    """Check that two sample-major arrays have the same number of samples."""
    if a.shape[0] != b.shape[0]:
        raise ValueError(f"{name_b}: has {b.shape[0]} samples but {name_a} has {a.shape[0]}")
