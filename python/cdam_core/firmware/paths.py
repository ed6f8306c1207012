"""Where the firmware sources and the cross tools are, and what is missing when they are not."""
from __future__ import annotations

import functools
import os
import shutil
import subprocess
from pathlib import Path

PACKAGE_DATA = Path(__file__).resolve().parents[1] / "firmware_src" / "firmware_stubs"


def _firmware_dir() -> Path:
    """firmware_stubs/: $CDAM_FIRMWARE_DIR, else beside the source tree (a checkout or an
    editable install), else the package data a wheel ships (``cdam_core/firmware_src/``, with
    the core headers beside it in ``firmware_src/cpp/include``), else above the cwd."""
    env = os.environ.get("CDAM_FIRMWARE_DIR")
    if env:
        return Path(env).resolve()
    here = Path(__file__).resolve().parents[3] / "firmware_stubs"
    for d in (here, PACKAGE_DATA):
        if (d / "CMakeLists.txt").is_file():
            return d
    for d in [Path.cwd(), *Path.cwd().parents]:
        if (d / "firmware_stubs" / "CMakeLists.txt").is_file():
            return d / "firmware_stubs"
    return here


FIRMWARE_DIR = _firmware_dir()


QEMU = "qemu-system-arm"


ARM_GCC = "arm-none-eabi-gcc"


ARM_GXX = "arm-none-eabi-g++"


# Debian / Ubuntu packages (docs TARGET.md); the hint names only those missing
APT = {ARM_GCC: "gcc-arm-none-eabi", ARM_GXX: "gcc-arm-none-eabi", QEMU: "qemu-system-arm",
       "cmake": "cmake", "arm-none-eabi-size": "binutils-arm-none-eabi",
       "newlib": "libnewlib-arm-none-eabi", "c++ headers": "libstdc++-arm-none-eabi-newlib",
       "eigen": "libeigen3-dev"}

EIGEN_DIRS = ("/usr/include/eigen3", "/usr/local/include/eigen3")


def _run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


def missing_tools() -> list[tuple[str, str]]:
    """What the firmware check needs and cannot find: ``[(what, Debian package)]`` (empty when
    everything is there). Looks for the executables on PATH, then asks the cross compiler for
    newlib (libc_nano.a) and the C++ headers, and looks for Eigen's headers."""
    return list(_missing_tools(os.environ.get("PATH", ""), os.environ.get("EIGEN3_ROOT", "")))


@functools.lru_cache(maxsize=4)
def _missing_tools(path: str, eigen_root: str) -> tuple:
    out = [(t, APT[t]) for t in (ARM_GCC, ARM_GXX, "arm-none-eabi-size", QEMU, "cmake")
           if shutil.which(t) is None]
    if shutil.which(ARM_GCC):
        r = _run([ARM_GCC, "-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard",
                  "-mfpu=fpv4-sp-d16", "-print-file-name=libc_nano.a"], timeout=30)
        if r.returncode != 0 or not os.path.isabs(r.stdout.strip()):
            out.append(("newlib for arm-none-eabi (libc_nano.a)", APT["newlib"]))
    if shutil.which(ARM_GXX):
        r = _run([ARM_GXX, "-std=c++17", "-x", "c++", "-E", "-o", os.devnull, "-"],
                 input="#include <cstdint>\n#include <cmath>\n", timeout=30)
        if r.returncode != 0:
            out.append(("C++ headers for arm-none-eabi (<cmath>)", APT["c++ headers"]))
    dirs = ([eigen_root, os.path.join(eigen_root, "include", "eigen3")] if eigen_root else []) \
        + list(EIGEN_DIRS)
    if not any(os.path.isfile(os.path.join(d, "Eigen", "Core")) for d in dirs):
        out.append(("Eigen 3 headers", APT["eigen"]))
    return tuple(out)


def install_hint(missing) -> str:
    """``apt-get install ...`` for the packages of ``missing`` (each once, in order)."""
    pkgs = []
    for _, p in missing:
        pkgs.append(p)
        if p == APT[ARM_GCC]:   # the compiler's C and C++ libraries come in packages of their own
            pkgs += [APT["newlib"], APT["c++ headers"]]
    return ("install with: bash scripts/setup.sh --firmware (from a checkout), or apt-get "
            "install " + " ".join(dict.fromkeys(pkgs)) + " (Debian/Ubuntu)")


def toolchain_available() -> str | None:
    """None when everything the firmware check needs is there, else one line naming what is
    missing and how to install it."""
    missing = missing_tools()
    if not missing:
        return None
    return (", ".join(what for what, _ in missing) + " not found; " + install_hint(missing))


def firmware_sources() -> str | None:
    """None when the firmware sources are there, else what is missing."""
    if not (FIRMWARE_DIR / "CMakeLists.txt").is_file():
        return (f"firmware sources not found at {FIRMWARE_DIR} (a package built without "
                f"them?); set CDAM_FIRMWARE_DIR to a checkout's firmware_stubs/")
    if not (FIRMWARE_DIR.parent / "cpp" / "include" / "cdam").is_dir():
        return (f"core headers not found at {FIRMWARE_DIR.parent / 'cpp' / 'include'} "
                f"(firmware_stubs/ compiles them)")
    return None
