"""`cdam firmware check`: build for a model, run it under QEMU, compare with Python."""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from cdam_core.base.rng import Rng

from cdam_core.firmware.build import build, heap_guard_works
from cdam_core.firmware.model import FirmwareModel, load_firmware_model
from cdam_core.firmware.qemu import run_equivalence


def default_inputs(fm: FirmwareModel, n: int = 1000, seed: int = 0) -> np.ndarray:
    """n normalised input vectors, uniform in [-1, 1], from the shared generator."""
    return Rng(seed).uniform_array(n * fm.n_inputs, -1.0, 1.0).reshape(n, fm.n_inputs)


def check(model_path, *, build_dir=None, inputs=None, timeout: float = 60.0) -> dict:
    """``cdam firmware check``: build for the model, run checks (1) and (2) under QEMU.

    Args:
        model_path: the model file.
        build_dir: where to build (default: a temporary folder).
        inputs: (N, I) normalised network inputs (default: 1000 uniform vectors, seed 0).
    Returns {"text", "data", "bss" (of the loop image fw_loop.elf), "heap_free",
    "instructions_per_inference", "max_abs_error", ...} with the model-plus-inference image's
    sizes and the stack high-water mark too.
    """
    fm = load_firmware_model(model_path)
    X = default_inputs(fm) if inputs is None else np.asarray(inputs, dtype=np.float64)
    ctx = tempfile.TemporaryDirectory(prefix="cdam_fw_build_") if build_dir is None else None
    bdir = Path(ctx.name if ctx else build_dir)
    try:
        sizes = build(bdir, fm)
        eq = run_equivalence(bdir, fm, X, timeout=timeout)
        heap_free = heap_guard_works(bdir)
    finally:
        if ctx:
            ctx.cleanup()
    loop, infer = sizes["fw_loop"], sizes["fw_infer"]
    return {
        "text": loop["text"], "data": loop["data"], "bss": loop["bss"],
        "heap_free": bool(heap_free),
        "instructions_per_inference": eq["instructions_per_inference"],
        "max_abs_error": eq["max_abs_error"],
        "instructions_per_prediction": eq["instructions_per_prediction"],
        "inference_image": infer,
        "stack_bytes": eq["stack_bytes"],
        "vectors": eq["vectors"],
        "model_sha256": fm.sha256,
        "network": f"{fm.n_inputs}-{fm.hidden}-{fm.n_outputs}",
        "sandbox": eq["sandbox"],
    }
