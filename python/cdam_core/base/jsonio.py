"""JSON out: plain data from numpy results, and atomic writes (no half-written file is left).

``plain`` is the one JSON cleaning every report and model file uses: numpy scalars and arrays
become numbers and lists, NaN and Inf become null (JSON has neither).
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = ["plain", "write_text_atomic", "write_json_atomic", "atomic_target"]


def plain(x):
    """JSON-able plain data: numpy scalars and arrays to numbers and lists, non-finite to None,
    paths to strings."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        v = float(x)
        return v if math.isfinite(v) else None
    if isinstance(x, Path):
        return str(x)
    return x



def _umask_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


_FILE_MODE = _umask_mode()


def write_text_atomic(path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file in the same folder (flushed to disk,
    given the usual umask mode) and a rename: a reader sees the old file or the new, never half."""
    path = Path(path)
    with atomic_target(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    return path


def write_json_atomic(path, obj, indent: int | None = 1) -> Path:
    """``plain(obj)`` as strict JSON (no NaN), written atomically."""
    return write_text_atomic(path, json.dumps(plain(obj), indent=indent, allow_nan=False) + "\n")


@contextmanager
def atomic_target(path):
    """A temporary path beside ``path`` with the same suffix (for writers that take a file name:
    figures, numpy archives); renamed over ``path`` when the block ends, removed on error."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, _FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
