"""Loaders that turn the real measured records into the dataset format, and where they are.

A real record is looked up by its path relative to a data folder (``"emps/DATA_EMPS.mat"``):
the repository's ``data/`` first (the records whose licence allows shipping them, see
``data/README.md``), then the shared folder (``$CDAM_SHARED_DATA``, else ``../shared/data``).
"""
import os
from pathlib import Path

__all__ = ["repo_data_dir", "shared_data_dir", "real_record", "BUNDLED"]

# records the repository ships under data/ (a test needing one fails, not skips, without it)
BUNDLED = ("emps/DATA_EMPS.mat", "emps/DATA_EMPS_PULSES.mat", "ardrone2/expData10_29_25.mat")

_CHECKOUT = Path(__file__).resolve().parents[4]   # python/cdam_core/record/realdata -> root


def repo_data_dir() -> Path:
    """The checkout's ``data/`` (found from this file for an in-tree or editable run, or as
    ``./data`` for an installed package run from the checkout)."""
    for c in (_CHECKOUT / "data", Path.cwd().resolve() / "data"):
        if (c / "README.md").is_file():
            return c
    return _CHECKOUT / "data"


def shared_data_dir() -> Path:
    """The shared folder of real records.

    $CDAM_SHARED_DATA if set; otherwise ``shared/data`` beside the checkout (found from this
    file for an editable or in-tree run, or from the current directory for an installed package).
    """
    env = os.environ.get("CDAM_SHARED_DATA")
    if env:
        return Path(env)
    candidates = [
        _CHECKOUT.parent / "shared" / "data",
        Path.cwd().resolve().parent / "shared" / "data",
    ]
    for c in candidates:
        if c.is_dir():
            return c
    return candidates[-1]


def real_record(relpath: str) -> Path:
    """Path of the real record ``relpath`` (e.g. ``"emps/DATA_EMPS.mat"``): in ``data/`` if
    there, else in the shared folder. When it is in neither, the path where it should be
    (``data/`` for a bundled record), so that the caller's error names it."""
    rel = Path(relpath)
    if rel.is_absolute() or ".." in rel.parts:
        raise ValueError(f"relpath: expected a path inside a data folder, got {relpath!r}")
    here, shared = repo_data_dir() / rel, shared_data_dir() / rel
    if here.is_file() or (not shared.is_file() and relpath in BUNDLED):
        return here
    return shared
