"""Firmware figures (needs arm-none-eabi-gcc and qemu-system-arm; returns {} without them).

"ratio": instructions per 6-20-8 float32 inference of the same check image built with
std::tanh / std::exp from newlib (cdam::ExactActivation, fw_check_exact.elf) over the firmware's
with the fast rational tanh (fw_check.elf); both measured in this run under QEMU -icount on the
same 1,000 input vectors. Also printed: instructions of each, flash (text + data) of the model
plus inference image, static RAM (data + bss) of the loop image, and the stack high-water mark.
"""
from __future__ import annotations

import tempfile
import time

from cdam_core import firmware as fw


def bench_inference() -> dict:
    if fw.toolchain_available():
        return {}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        model = fw.FIRMWARE_DIR / "generated" / "demo_model.json"
        rep = fw.check(model, build_dir=tmp)
        fm = fw.load_firmware_model(model)
        exact = fw.run_equivalence(tmp, fm, fw.default_inputs(fm), image="fw_check_exact")
    secs = time.perf_counter() - t0
    fast_ipi = rep["instructions_per_inference"]
    infer = rep["inference_image"]
    out = {
        "ratio": exact["instructions_per_inference"] / fast_ipi,
        "seconds": secs,
        "instructions_per_inference": fast_ipi,
        "instructions_per_inference_exact_tanh": exact["instructions_per_inference"],
        "instructions_per_prediction": rep["instructions_per_prediction"],
        "max_abs_error": rep["max_abs_error"],
        "max_abs_error_exact_tanh": exact["max_abs_error"],
        "inference_flash": infer["text"] + infer["data"],
        "loop_static_ram": rep["data"] + rep["bss"],
        "loop_text": rep["text"],
        "stack_bytes": rep["stack_bytes"],
        "heap_free": rep["heap_free"],
    }
    print("firmware: " + ", ".join(f"{k}={v}" for k, v in out.items()))
    return out


BENCHMARKS = {"firmware_inference": bench_inference}
