"""Loaders that turn the real measured records in ../shared/data into the dataset format."""
import os
from pathlib import Path


def shared_data_dir() -> Path:
    """The folder holding the real records.

    $CDAM_SHARED_DATA if set; otherwise ``shared/data`` beside the checkout (found from this
    file for an editable or in-tree run, or from the current directory for an installed package).
    """
    env = os.environ.get("CDAM_SHARED_DATA")
    if env:
        return Path(env)
    candidates = [
        Path(__file__).resolve().parents[4].parent / "shared" / "data",
        Path.cwd().resolve().parent / "shared" / "data",
    ]
    for c in candidates:
        if c.is_dir():
            return c
    return candidates[-1]
