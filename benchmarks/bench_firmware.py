"""Firmware figures (needs arm-none-eabi-gcc and qemu-system-arm; returns {} without them).

"ratio": instructions per 6-20-8 float32 inference of the same check image built with
std::tanh / std::exp from newlib (cdam::ExactActivation, fw_check_exact.elf) over the firmware's
with the fast rational tanh (fw_check.elf); both measured in this run under QEMU -icount on the
same 1,000 input vectors. Also printed: instructions of each, flash (text + data) of the model
plus inference image, static RAM (data + bss) of the loop image, and the stack high-water mark.

The instruction count against its bound (issue 23, item 6): a 6-20-8 inference has 280
multiply-adds (120 hidden, 160 output) and 20 tanh. fast_tanh is compiled here alone with the
firmware's flags and its unsaturated path counted from the disassembly: its arithmetic (x^2,
9 FMAs, x p, the division), its test (compare, flag transfer, branch) and its coefficient loads.
Two instruction bounds (6 input loads and 8 output stores included in both):
- "vldr": each weight and bias one VLDR, each multiply-add one VFMA, the tanh coefficients kept
  in registers (tanh = arithmetic + test);
- "vldm": the same with the weights loaded 16 to a VLDM (the fewest instructions the M4F's 32
  single registers allow).
The firmware's kernel (firmware_stubs/include/fw/packed_mlp.hpp) is one pass over the weights
packed per hidden unit, each block one VLDM, so "vldm" is the bound it is measured against.
Cycles: QEMU counts instructions, and a VLDM of n registers is one instruction but 1 + n cycles
on the M4, a VFMA 3 cycles, a VDIV 14 (ARM Cortex-M4 TRM, table "FPU instruction set"); the
kernel's cycles are estimated from its disassembly with those timings ("kernel_cycles_estimate",
a taken branch 2 cycles, the saturated tanh path not taken) for the comparison below.
Beside them, for scale, the nano-drone benchmark's networks on an STM32F469 (Cortex-M4F,
180 MHz) with ST Edge AI, from its repository's out/export/benchmark-results.csv as quoted in
issue 23: cycles (measured on the board), not instructions (ours: QEMU -icount, a lower bound on
the cycles), so the comparison is of scale only.
"""
from __future__ import annotations

import re
import subprocess
import tempfile
import time
from pathlib import Path

from cdam_core import firmware as fw


MACS, TANH = 6 * 20 + 20 * 8, 20
WEIGHTS = 6 * 20 + 20 + 20 * 8 + 8
ST_EDGE_AI = {"residual_mlp": {"cycles": 173_155, "macs": 18_840},   # 5 ReLU layers of 64
              "lstm_step": {"cycles": 328_382, "macs": 23_946}}
_FLAGS = ["-std=c++17", "-O3", "-funroll-loops", "-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard",
          "-mfpu=fpv4-sp-d16", "-fno-exceptions", "-fno-rtti"]


def tanh_instructions(tmp) -> dict:
    """Instructions on fast_tanh's unsaturated path, split into coefficient loads, the test and
    the arithmetic (return not counted), from its disassembly compiled with the firmware's flags."""
    inc = Path(__file__).resolve().parents[1] / "cpp" / "include"
    src = Path(tmp) / "tanh_count.cpp"
    src.write_text('#include "cdam/fast_math.hpp"\n'
                   'float tanh_count(float x) { return cdam::fast_tanh(x); }\n')
    obj = src.with_suffix(".o")
    subprocess.run(["arm-none-eabi-g++", *_FLAGS, f"-I{inc}", "-c", str(src), "-o", str(obj)],
                   check=True, capture_output=True)
    dis = subprocess.run(["arm-none-eabi-objdump", "-d", "--no-show-raw-insn", str(obj)],
                         check=True, capture_output=True, text=True).stdout
    ops = re.findall(r"^\s+[0-9a-f]+:\s+([a-z][a-z0-9.]*)\s*(.*)$", dis, re.M)
    path = []
    for op, args in ops:               # the fall-through path up to the first return
        if op == "bx":
            break
        path.append((op, args))
    loads = sum(op == "vldr" and "[pc" in a for op, a in path)
    test = sum(op.startswith(("vcmp", "vmrs", "b")) for op, _ in path)
    return {"loads": loads, "test": test, "arithmetic": len(path) - loads - test,
            "total": len(path)}


# Cortex-M4 cycles per instruction (TRM, "FPU instruction set" and "Cortex-M4 instruction set
# summary"); VLDM/VSTM/VPUSH/VPOP: 1 + registers, counted separately.
_M4_CYCLES = {"vfma.f32": 3, "vfms.f32": 3, "vmla.f32": 3, "vdiv.f32": 14, "vsqrt.f32": 14}


def _reg_count(args: str) -> int:
    n = 0
    for part in re.search(r"\{(.*)\}", args).group(1).split(","):
        lo, _, hi = part.strip().partition("-")
        n += 1 if not hi else int(hi.strip()[1:]) - int(lo[1:]) + 1
    return n


def kernel_cycles(elf) -> dict:
    """Instructions and estimated M4 cycles of the packed-MLP kernel's path with no saturated
    tanh, from the disassembly of forward_packed_m4f in ``elf`` (the call's own instructions)."""
    dis = subprocess.run(["arm-none-eabi-objdump", "-d", "-C", "--no-show-raw-insn", str(elf)],
                         check=True, capture_output=True, text=True).stdout
    body = re.search(r"<[^\n]*fw::forward_packed_m4f[^\n]*>:\n(.*?)\n\n", dis + "\n\n", re.S)
    if body is None:
        return {}
    ops = re.findall(r"^\s*([0-9a-f]+):\s+([a-z][a-z0-9.]*)\s*(.*)$", body.group(1), re.M)
    n = cycles = 0
    skip_to = None
    for addr, op, args in ops:
        if skip_to is not None and int(addr, 16) != skip_to:
            continue
        skip_to = None
        n += 1
        if op.startswith(("vldm", "vstm", "vpush", "vpop")):
            cycles += 1 + _reg_count(args)
        elif op.startswith("ble"):   # the unsaturated path takes it
            cycles += 2
            skip_to = int(args.split()[0], 16)
        elif op == "bx":
            cycles += 2
            break
        else:
            cycles += _M4_CYCLES.get(op, 1)
    return {"kernel_instructions": n, "kernel_cycles_estimate": cycles}


def instruction_bounds(tanh: dict) -> dict:
    tanh_regs = tanh["arithmetic"] + tanh["test"]
    io = 6 + 8
    vldr = MACS + WEIGHTS + TANH * tanh_regs + io
    vldm = MACS + -(-WEIGHTS // 16) + TANH * tanh_regs + io
    return {"bound_vldr": vldr, "bound_vldm": vldm}


def bench_inference() -> dict:
    if fw.toolchain_available():
        return {}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        model = fw.FIRMWARE_DIR / "generated" / "demo_model.json"
        rep = fw.check(model, build_dir=tmp)
        fm = fw.load_firmware_model(model)
        exact = fw.run_equivalence(tmp, fm, fw.default_inputs(fm), image="fw_check_exact")
        tanh = tanh_instructions(tmp)
        kernel = kernel_cycles(Path(tmp) / "fw_check.elf")
    secs = time.perf_counter() - t0
    fast_ipi = rep["instructions_per_inference"]
    infer = rep["inference_image"]
    out = {
        "ratio": exact["instructions_per_inference"] / fast_ipi,
        # one instruction a cycle at 168 MHz (a lower bound on the time); building took secs
        "seconds": fast_ipi / 168e6,
        "reference_seconds": exact["instructions_per_inference"] / 168e6,
        "build_seconds": secs,
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
        "multiply_adds": MACS, "tanh_calls": TANH,
        "instructions_per_multiply_add": fast_ipi / MACS,
        "tanh_path_instructions": tanh["total"], "tanh_coefficient_loads": tanh["loads"],
        "tanh_test_instructions": tanh["test"], "tanh_arithmetic_instructions": tanh["arithmetic"],
        **instruction_bounds(tanh),
        **kernel,
        **{f"st_edge_ai_{k}_cycles_per_multiply_add": v["cycles"] / v["macs"]
           for k, v in ST_EDGE_AI.items()},
        "us_168mhz_one_instruction_a_cycle": fast_ipi / 168.0,
    }
    if kernel:
        out["kernel_cycles_per_multiply_add"] = kernel["kernel_cycles_estimate"] / MACS
    out["over_bound"] = fast_ipi / out["bound_vldm"]
    out["bound_seconds"] = out["bound_vldm"] / 168e6
    out["reference"] = "same image with newlib tanhf (instructions)"
    print("firmware: " + ", ".join(f"{k}={v}" for k, v in out.items()))
    return out


BENCHMARKS = {"firmware_inference": bench_inference}
