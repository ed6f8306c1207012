"""Where the firmware sources and the cross tools are."""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path


def _firmware_dir() -> Path:
    """firmware_stubs/: $CDAM_FIRMWARE_DIR, else beside the source tree, else above the cwd."""
    env = os.environ.get("CDAM_FIRMWARE_DIR")
    if env:
        return Path(env).resolve()
    here = Path(__file__).resolve().parents[3] / "firmware_stubs"
    if (here / "CMakeLists.txt").is_file():
        return here
    for d in [Path.cwd(), *Path.cwd().parents]:
        if (d / "firmware_stubs" / "CMakeLists.txt").is_file():
            return d / "firmware_stubs"
    return here


FIRMWARE_DIR = _firmware_dir()


QEMU = "qemu-system-arm"


ARM_GCC = "arm-none-eabi-gcc"


def toolchain_available() -> str | None:
    """None when arm-none-eabi-gcc, qemu-system-arm and cmake are on PATH, else what is missing."""
    missing = [t for t in (ARM_GCC, QEMU, "cmake") if shutil.which(t) is None]
    return ", ".join(missing) + " not found" if missing else None


def _run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, **kw)
