"""QEMU runs in a private file system: the emulated board's semihosting can open host files, so
the check images run where the host shows only ``/usr`` (read-only: QEMU and its libraries), the
image (read-only) and the one work folder the run reads and writes, with no network.

Built from what util-linux gives every Linux: ``unshare`` (user, mount and network namespaces:
no root needed) and ``chroot`` inside them. Where user namespaces are not allowed (some
containers) or QEMU lives outside ``/usr``, the run is not sandboxed and says so (the reason is
returned with the command and reported by ``cdam firmware check``). The images are built from
this repository's sources and a generated header of numbers only (no text from a model file
reaches them); the sandbox is the second line of defence.
"""
from __future__ import annotations

import functools
import shutil
import subprocess
from pathlib import Path

__all__ = ["sandboxed", "available"]

IMAGE = "/img/image.elf"    # where the image appears inside
WORK = "/work"               # where the work folder appears inside

_SCRIPT = r"""
set -e
elf=$1; work=$2; shift 2
R=/mnt
mount -t tmpfs -o size=4m tmpfs "$R"
mkdir -p "$R/usr" "$R/work" "$R/img" "$R/dev"
mount --rbind /usr "$R/usr"
mount -o remount,bind,ro "$R/usr"
ln -s usr/lib "$R/lib"; ln -s usr/lib64 "$R/lib64"; ln -s usr/bin "$R/bin"
mount --bind "$work" "$R/work"
: > "$R/img/image.elf"; mount --bind "$elf" "$R/img/image.elf"
mount -o remount,bind,ro "$R/img/image.elf"
: > "$R/dev/null"; mount --bind /dev/null "$R/dev/null"
exec chroot "$R" /usr/bin/env -C /work "$@"
"""

_UNSHARE = ["unshare", "--user", "--map-root-user", "--mount", "--net", "--fork"]


@functools.lru_cache(maxsize=1)
def available() -> str | None:
    """None when runs can be sandboxed here, else the reason they cannot."""
    if shutil.which("unshare") is None or shutil.which("chroot") is None:
        return "unshare or chroot not found"
    if not Path("/mnt").is_dir():
        return "no /mnt to build the private root on"
    try:
        r = subprocess.run(_UNSHARE + ["sh", "-c", "mount -t tmpfs tmpfs /mnt"],
                           capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"unshare failed ({exc})"
    if r.returncode != 0:
        return f"user namespaces not available here ({r.stderr.strip()[:120]})"
    return None


def sandboxed(qemu: str, args: list, elf, work) -> tuple[list, str]:
    """(command, description): QEMU with ``args`` (the image given as :data:`IMAGE`, the work
    folder as the current directory) in the private root, or unsandboxed with the reason."""
    exe = shutil.which(qemu)
    why = available()
    if why is None and (exe is None or not Path(exe).resolve().is_relative_to("/usr")):
        why = f"{qemu} is not under /usr"
    if why is None:
        return (_UNSHARE + ["sh", "-c", _SCRIPT, "sh", str(Path(elf).resolve()),
                            str(Path(work).resolve()), qemu] + list(args),
                "private root: /usr and the image read-only, the work folder, no network")
    plain = [qemu] + [str(Path(elf).resolve()) if a == IMAGE else a for a in args]
    return plain, f"none: {why}"
