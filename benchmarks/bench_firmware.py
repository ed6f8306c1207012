"""Firmware figures (needs arm-none-eabi-gcc and qemu-system-arm; returns {} without them).

"ratio": instructions per 6-20-8 inference of the plain core (exact tanh from newlib, the
measured figure in TARGET.md: 2158 at -O2 with lazyProduct) over the fast-activation firmware's,
measured in this run under QEMU -icount.
"""
from __future__ import annotations

import tempfile
import time

from cdam_core import firmware as fw

PLAIN_CORE_INSTRUCTIONS = 2158.0  # docs/TARGET.md, Eigen + expf-based tanh, -O2 lazyProduct


def bench_inference() -> dict:
    if fw.toolchain_available():
        return {}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        model = fw.FIRMWARE_DIR / "generated" / "demo_model.json"
        rep = fw.check(model, build_dir=tmp)
    secs = time.perf_counter() - t0
    return {"ratio": PLAIN_CORE_INSTRUCTIONS / rep["instructions_per_inference"],
            "seconds": secs, **{k: v for k, v in rep.items() if k != "inference_image"},
            "inference_flash": rep["inference_image"]["text"] + rep["inference_image"]["data"]}


BENCHMARKS = {"firmware_inference": bench_inference}
