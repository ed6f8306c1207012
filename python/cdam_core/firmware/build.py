"""Cross build of the STM32F405 images (CMake + arm-none-eabi) and the heap guard check."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from cdam_core.firmware.export import export_header
from cdam_core.firmware.model import FirmwareModel, StepFirmwareModel, load_firmware_model
from cdam_core.firmware.paths import FIRMWARE_DIR, _run, toolchain_available


def _sizes(elf: Path) -> dict:
    out = _run(["arm-none-eabi-size", "--format=berkeley", str(elf)], check=True).stdout
    text, data, bss = (int(v) for v in out.splitlines()[1].split()[:3])
    return {"text": text, "data": data, "bss": bss}


IMAGES = ("fw_infer", "fw_check", "fw_loop", "fw_kernels", "fw_optim", "fw_check_exact")


STEP_IMAGES = ("fw_step", "fw_step_check")   # the dynamic kinds (arx, hybrid, greybox)


MONITOR_PIL_IMAGE = "fw_monitor_pil"   # a model file with a monitor section: the PIL image


def build(build_dir, model=None, *, jobs: int = 2, timeout: float = 600.0) -> dict:
    """Cross-build the firmware images into ``build_dir``.

    Args:
        build_dir: CMake build folder (created).
        model: a model file, a FirmwareModel, a StepFirmwareModel, or None for the checked-in
            generated/model.hpp.
    Returns ``{image: {"text", "data", "bss"}}``: for a network fw_infer, fw_check, fw_loop,
    fw_kernels, fw_optim (check 3's IBOA-BP run) and fw_check_exact (fw_check with std::tanh,
    the benchmark's reference); for arx, hybrid and greybox (:data:`STEP_IMAGES`) fw_step
    (model + one step) and fw_step_check, with fw_monitor_pil (the monitor in the loop over
    SLCAN) when the model file has a monitor section.
    Raises RuntimeError with the compiler output when the build fails (also when something
    uses the heap: the link then fails on ``__wrap_malloc``).
    """
    why = toolchain_available()
    if why:
        raise RuntimeError(f"cannot build the firmware: {why}")
    build_dir = Path(build_dir).resolve()
    build_dir.mkdir(parents=True, exist_ok=True)
    model_dir = FIRMWARE_DIR / "generated"
    if model is not None and not isinstance(model, (FirmwareModel, StepFirmwareModel)):
        model = load_firmware_model(model)
    images = STEP_IMAGES if isinstance(model, StepFirmwareModel) else IMAGES
    if isinstance(model, StepFirmwareModel) and model.monitor is not None:
        images = images + (MONITOR_PIL_IMAGE,)
    if model is not None:
        model_dir = build_dir / "generated"
        model_dir.mkdir(exist_ok=True)
        target = model_dir / "model.hpp"
        tmp = model_dir / "model.hpp.new"
        export_header(model, tmp)
        if not target.exists() or target.read_text() != tmp.read_text():
            os.replace(tmp, target)
        else:
            tmp.unlink()
    cfg = ["cmake", "-S", str(FIRMWARE_DIR), "-B", str(build_dir),
           f"-DCMAKE_TOOLCHAIN_FILE={FIRMWARE_DIR / 'cmake' / 'arm-none-eabi.cmake'}",
           f"-DCDAM_FW_MODEL_DIR={model_dir}"]
    if shutil.which("ninja"):
        cfg += ["-G", "Ninja"] if not (build_dir / "CMakeCache.txt").exists() else []
    for cmd in (cfg, ["cmake", "--build", str(build_dir), f"-j{int(jobs)}"]):
        r = _run(cmd, timeout=timeout)
        if r.returncode != 0:
            raise RuntimeError(f"firmware build failed ({' '.join(cmd[:2])}):\n"
                               f"{r.stdout[-4000:]}\n{r.stderr[-4000:]}")
    return {name: _sizes(build_dir / f"{name}.elf") for name in images}


def heap_guard_works(build_dir, timeout: float = 120.0) -> bool:
    """True when an image that calls malloc fails to link on the undefined ``__wrap_malloc``."""
    r = _run(["cmake", "--build", str(build_dir), "--target", "fw_heap_probe.elf"],
             timeout=timeout)
    return r.returncode != 0 and "__wrap_malloc" in (r.stdout + r.stderr)
