"""Checks of a model file's fields: every error names the field (``model.theta[3]``).

The envelope and each kind's section are described by the JSON schema in
``cdam_core/models/model-file.schema.json`` (validated with the ``jsonschema`` package); the
shape relations a schema cannot state (a weight vector's length for the stated sizes, a
coefficient matrix's rows) are checked here as the sections are read.
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["field_array", "validate_document", "SCHEMA_PATH"]

SCHEMA_PATH = Path(__file__).with_name("model-file.schema.json")


@lru_cache(maxsize=1)
def _validator():
    import jsonschema
    schema = json.loads(SCHEMA_PATH.read_text())
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def _path(error) -> str:
    out = ""
    for p in error.absolute_path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else str(p))
    return out or "(document)"


def validate_document(doc) -> None:
    """ValueError naming the first offending field of a model-file document."""
    from jsonschema.exceptions import best_match
    e = best_match(_validator().iter_errors(doc))
    if e is None:
        return
    while e.context:                       # oneOf/anyOf: the branch that came closest
        e = best_match(e.context)
    msg = e.message if len(e.message) <= 200 else e.message[:200] + "..."
    raise ValueError(f"{_path(e)}: {msg}")


def field_array(value, name: str, shape: tuple) -> np.ndarray:
    """A float64 array of ``shape`` from nested lists of finite numbers, or ValueError(name)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected numbers of shape {shape}") from None
    if arr.shape != tuple(shape):
        raise ValueError(f"{name}: expected shape {tuple(shape)}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ValueError(f"{name}{list(bad)}: not a finite number")
    return arr

