"""cdam_core: identify, check and fly the dynamics of a cable-driven aerial manipulator.

Public names are loaded lazily (PEP 562) so that ``import cdam_core`` and the CLI start fast and
pure-Python parts work without pulling in plotting or the compiled core.
"""
from __future__ import annotations

import importlib
import os

__version__ = "0.1.0"

# Developers building with plain CMake point this at their build's cdam_core folder (DESIGN.md).
_ext_dir = os.environ.get("CDAM_CORE_EXT_DIR")
if _ext_dir:
    __path__.insert(0, _ext_dir)  # type: ignore[name-defined]

# public name -> submodule that defines it
_LAZY = {
    "five_point_cubic_smooth": "preprocess",
    "MinMaxScaler": "preprocess",
    "Model": "models",
    "BPNetwork": "models",
    "ArxModel": "models",
    "HybridNarx": "models",
    "hidden_node_candidates": "models",
    "Rng": "base.rng",
    "load_model": "models",
    "save_model": "models",
    "read_dataset": "record.dataset",
    "write_dataset": "record.dataset",
    "simulate_flight": "sim",
    "write_flight": "sim",
    "identify": "identify",
    "IdentifyConfig": "identify",
    "evaluate": "evaluate",
    "analyse_residual": "residual",
}

__all__ = sorted(_LAZY) + ["__version__"]


def __getattr__(name: str):
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'cdam_core' has no attribute {name!r}")
    attr = "analyse" if name == "analyse_residual" else name
    value = getattr(importlib.import_module(f"cdam_core.{mod}"), attr)
    globals()[name] = value
    return value


def __dir__():
    return __all__
