"""`cdam firmware check`: build for a model, run it under QEMU, compare with Python."""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from cdam_core.base.rng import Rng

from cdam_core.firmware.build import build, heap_guard_works
from cdam_core.firmware.model import FirmwareModel, StepFirmwareModel, load_firmware_model
from cdam_core.firmware.qemu import MAX_K, run_equivalence, run_step_equivalence

CLOCK_HZ = 168e6   # the STM32F405's core clock: microseconds = instructions / 168 (one per cycle)
HOLD_ROWS = 20     # the synthetic record's input holds each random level this many rows


def default_inputs(fm: FirmwareModel, n: int = 1000, seed: int = 0) -> np.ndarray:
    """n normalised input vectors, uniform in [-1, 1], from the shared generator."""
    return Rng(seed).uniform_array(n * fm.n_inputs, -1.0, 1.0).reshape(n, fm.n_inputs)


def _input_range(fm: StepFirmwareModel):
    """(lo, hi) per input of the synthetic record, from the model's own numbers."""
    i, a = fm.ints, fm.arrays
    n = fm.n_inputs
    if fm.kind in ("quad_physics", "quad_hybrid"):
        # rotor speeds within 1 % of the hover speed sqrt(g / (4 kT/m)) (the model's own kT/m)
        hover = np.sqrt(fm.floats["kGravity"] / (4.0 * abs(float(a["kTrans"][0]))))
        return np.full(n, 0.99 * hover), np.full(n, 1.01 * hover)
    if fm.kind == "greybox" and fm.macros["CDAM_MODEL_DECLARED"] in (2, 3):
        # quadrotor: thrust within 10 % of the hover thrust m g, torques giving about 1 rad/s^2;
        # aerial_manipulator: the joint motors' torques up to the links' gravity torques
        # g1 + g2 (a swing of about a radian), then any external force column
        b = np.asarray(a["kBase"], np.float64)
        joints = np.full(2, abs(b[21]) + abs(b[22])) if fm.macros["CDAM_MODEL_DECLARED"] == 3 \
            else np.zeros(0)
        rest = n - 4 - joints.size
        hi = np.r_[1.1 * b[0] * 9.81, b[4:7], joints, np.ones(rest)]
        lo = np.r_[0.9 * b[0] * 9.81, -b[4:7], -joints, -np.ones(rest)]
        return lo, hi
    if fm.kind == "greybox":
        # a force beyond the static ones (offset or gravity, dry friction, a payload's weight),
        # so that the axis moves both ways
        par = np.asarray(a["kEffectParam"], np.float64).reshape(-1, 4)
        code = np.asarray(fm.int_arrays["kEffectCode"])[:len(par)]
        b = np.asarray(a["kBase"], np.float64)
        # rigid_axis: its offset and gravity (G, Gc); flexible_joint: gravity and the constants
        static = float(np.sum(np.abs(b[2:5]))) if fm.macros["CDAM_MODEL_DECLARED"] == 0 else \
            float(np.sum(np.abs(b[6:10])))
        static += np.sum(np.abs(par[code == 1, 0])) + np.sum(np.abs(par[code == 7, 0] *
                                                                    par[code == 7, 1]))
        amp = 4.0 * static + 1.0
        return np.full(n, -amp), np.full(n, amp)
    if fm.kind == "bp_network":   # the network's training range of the inputs (lag nk)
        a0 = i["kNa"] * fm.n_outputs
        return np.asarray(a["kNetXMin"][a0:a0 + n]), np.asarray(a["kNetXMax"][a0:a0 + n])
    if i["kPhysics"]:   # motor commands, 0 .. their training maximum
        return np.zeros(n), np.asarray(a["kFeatureScale"], np.float64)
    if "kNetXMin" in a:   # raw inputs: the residual network's training range of lag 0
        return np.asarray(a["kNetXMin"][:n]), np.asarray(a["kNetXMax"][:n])
    return -np.ones(n), np.ones(n)


def default_record(fm: StepFirmwareModel, n: int = 1000, seed: int = 0):
    """A synthetic record for a dynamic model: inputs that hold a uniform random level (shared
    generator, ``seed``) for HOLD_ROWS rows, in the range :func:`_input_range` gives; outputs:
    the Python model's free run from zero (so one-step and free run see the model's own
    trajectory; quad_physics, quad_hybrid: from its training mean position and attitude, at rest).
    Returns (U (n, I), Y (n, m)) float64."""
    lo, hi = _input_range(fm)
    levels = Rng(seed).uniform_array((n // HOLD_ROWS + 1) * fm.n_inputs, 0.0, 1.0)
    levels = levels.reshape(-1, fm.n_inputs)
    U = np.repeat(lo + (hi - lo) * levels, HOLD_ROWS, axis=0)[:n]
    Y = np.zeros((n, fm.n_outputs))
    if fm.kind in ("quad_physics", "quad_hybrid"):
        start = np.asarray(fm.model.y_start_, np.float64).copy()
        start[3:6] = start[10:13] = 0.0
        Y[:] = start
    Y[fm.history:] = fm.predict(U, Y, "free_run")
    return U, Y


K_STEP = 10   # the k-step horizon the check runs by default (0.1 s at 100 Hz, 10 ms at 1 kHz)


def check(model_path, *, build_dir=None, inputs=None, record=None, timeout: float = 60.0,
          k: int = K_STEP) -> dict:
    """``cdam firmware check``: build for the model, run it under QEMU, compare with Python.

    Args:
        model_path: the model file (any kind).
        build_dir: where to build (default: a temporary folder).
        inputs: bp_network: (N, I) normalised network inputs (default: 1000 uniform vectors,
            seed 0).
        record: the dynamic kinds: (U, Y) in physical units (default:
            :func:`default_record`).
        k: the dynamic kinds: the horizon of the k-step comparison (1..64).
    Returns a dict with "kind", "flash_bytes" (text + data) and "static_ram_bytes" (data +
    bss) of the smallest image holding the model (fw_infer / fw_step), "heap_free", the
    instructions per inference or step, "microseconds_168mhz" (instructions / 168: one
    instruction a cycle, a lower bound), "max_abs_error" (one-step for the dynamic kinds; their
    k-step and free run in "max_abs_error_k_step" and "max_abs_error_free_run"), and more per
    kind (see the README).
    """
    fm = load_firmware_model(model_path)
    if isinstance(fm, StepFirmwareModel) and (isinstance(k, bool) or not isinstance(
            k, (int, np.integer)) or not 1 <= k <= MAX_K):
        raise ValueError(f"k: expected an integer in 1..{MAX_K}, got {k!r}")
    ctx = tempfile.TemporaryDirectory(prefix="cdam_fw_build_") if build_dir is None else None
    bdir = Path(ctx.name if ctx else build_dir)
    try:
        sizes = build(bdir, fm)
        if isinstance(fm, StepFirmwareModel):
            U, Y = default_record(fm) if record is None else record
            runs = {mode: run_step_equivalence(bdir, fm, U, Y, mode, timeout=timeout, k=k)
                    for mode in ("one_step", "k_step", "free_run")}
        else:
            X = default_inputs(fm) if inputs is None else np.asarray(inputs, dtype=np.float64)
            eq = run_equivalence(bdir, fm, X, timeout=timeout)
        heap_free = heap_guard_works(bdir)
    finally:
        if ctx:
            ctx.cleanup()
    if isinstance(fm, StepFirmwareModel):
        return _step_report(fm, sizes, runs, heap_free)
    loop, infer = sizes["fw_loop"], sizes["fw_infer"]
    return {
        "kind": "bp_network",
        "text": loop["text"], "data": loop["data"], "bss": loop["bss"],
        "flash_bytes": infer["text"] + infer["data"],
        "static_ram_bytes": infer["data"] + infer["bss"],
        "heap_free": bool(heap_free),
        "instructions_per_inference": eq["instructions_per_inference"],
        "max_abs_error": eq["max_abs_error"],
        "instructions_per_prediction": eq["instructions_per_prediction"],
        "microseconds_168mhz": round(eq["instructions_per_prediction"] / (CLOCK_HZ / 1e6), 2),
        "inference_image": infer,
        "stack_bytes": eq["stack_bytes"],
        "vectors": eq["vectors"],
        "model_sha256": fm.sha256,
        "network": f"{fm.n_inputs}-{fm.hidden}-{fm.n_outputs}",
        "sandbox": eq["sandbox"],
    }


def _step_report(fm: StepFirmwareModel, sizes: dict, runs: dict, heap_free: bool) -> dict:
    img = sizes["fw_step"]
    one, kst, free = runs["one_step"], runs["k_step"], runs["free_run"]
    ips = max(one["instructions_per_step"], free["instructions_per_step"])
    mon = {k: one[k] for k in ("monitor_mismatches", "monitor_alarms", "monitor_alarms_python",
                               "alarm_frames_equal", "instructions_per_monitor") if k in one}
    return {
        **mon,
        "kind": fm.kind,
        "model": fm.describe(),
        "text": img["text"], "data": img["data"], "bss": img["bss"],
        "flash_bytes": img["text"] + img["data"],
        "static_ram_bytes": img["data"] + img["bss"],
        "heap_free": bool(heap_free),
        "instructions_per_step": ips,
        "instructions_per_observe": max(one.get("instructions_per_observe", 0.0),
                                        free.get("instructions_per_observe", 0.0)),
        "instructions_per_step_max": max(one["instructions_per_step_max"],
                                         free["instructions_per_step_max"]),
        "microseconds_168mhz": round(ips / (CLOCK_HZ / 1e6), 2),
        "max_abs_error": one["max_abs_error"],
        "max_abs_error_free_run": free["max_abs_error"],
        "k": kst["k"],
        "max_abs_error_k_step": kst["max_abs_error"],
        "max_rel_error_k_step": kst["max_rel_error"],
        "output_span": one["output_span"],
        "max_rel_error": one["max_rel_error"],
        "max_rel_error_free_run": free["max_rel_error"],
        "steps": one["steps"],
        "stack_bytes": max(one["stack_bytes"], free["stack_bytes"]),
        "check_image": sizes["fw_step_check"],
        "model_sha256": fm.sha256,
        "sandbox": one["sandbox"],
    }
