"""Output folders: exist (or are created) and are writable, checked before any computation."""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["FolderError", "writable_folder"]


class FolderError(OSError):
    """An output folder that is missing, not a folder, cannot be created or is not writable."""


def writable_folder(d, create: bool = True, what: str = "folder") -> Path:
    """``d`` as a Path after checking it is a writable folder (created with its parents when
    ``create``); FolderError naming ``what`` otherwise."""
    d = Path(d)
    if d.exists() and not d.is_dir():
        raise FolderError(f"{what}: {d} exists and is not a folder")
    if not d.exists():
        if not create:
            raise FolderError(f"{what}: folder {d} does not exist")
        try:
            d.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FolderError(f"{what}: cannot create {d}: {exc.strerror or exc}") from None
    if not os.access(d, os.W_OK | os.X_OK):
        raise FolderError(f"{what}: {d} is not writable")
    return d
