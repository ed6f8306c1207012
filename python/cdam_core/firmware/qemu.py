"""Running images under qemu-system-arm (netduinoplus2): equivalence, kernels, the on-board optimiser."""
from __future__ import annotations

import struct
import tempfile
from pathlib import Path

import numpy as np

from cdam_core.firmware.model import (FirmwareModel, StepFirmwareModel, load_firmware_model,
                                      theta_fnv1a)
from cdam_core.firmware import sandbox
from cdam_core.firmware.paths import QEMU, _run


def run_qemu(elf, cwd, *, timeout: float = 30.0, icount: int | None = 4,
             extra: list | None = None) -> tuple[int, dict, str]:
    """Run an ELF on ``-M netduinoplus2`` with semihosting under ``timeout``, in the private
    root of :mod:`.sandbox` (the image and ``cwd`` are all it sees of the host files).

    Returns (exit status, the ``key=value`` lines printed as a dict, the whole console text).
    Exit status 124 means the timeout hit.
    """
    args = ["-M", "netduinoplus2", "-display", "none", "-monitor", "none", "-serial", "null",
            "-chardev", "stdio,id=s0",
            "-semihosting-config", "enable=on,target=native,chardev=s0",
            "-kernel", sandbox.IMAGE]
    if icount is not None:
        args[2:2] = ["-icount", f"shift={int(icount)}"]
    args += list(extra or [])
    inner, where = sandbox.sandboxed(QEMU, args, elf, cwd)
    cmd = ["timeout", "--kill-after=5", str(float(timeout))] + inner
    r = _run(cmd, cwd=str(cwd), timeout=timeout + 10)
    kv = {"sandbox": where}
    for line in r.stdout.splitlines():
        if "=" in line:
            k, v = line.split("=", 1)
            kv[k.strip()] = v.strip()
    return r.returncode, kv, r.stdout + r.stderr


def run_equivalence(build_dir, model, X_normalised, *, timeout: float = 60.0,
                    image: str = "fw_check") -> dict:
    """Checks (1) and (2): the firmware's normalised outputs for the rows of ``X_normalised``
    (N, I) against the Python model (float64), and instructions per inference.
    ``image``: "fw_check" (the fast activation) or "fw_check_exact" (std::tanh / std::exp).

    Returns max_abs_error, instructions_per_inference (network alone, normalised in/out),
    instructions_per_prediction (with scaling and back-scaling), stack_bytes, vectors.
    """
    fm = model if isinstance(model, FirmwareModel) else load_firmware_model(model)
    X = np.asarray(X_normalised, dtype=np.float64)
    if X.ndim != 2 or X.shape[1] != fm.n_inputs or X.shape[0] < 1:
        raise ValueError(f"X_normalised: expected shape (N, {fm.n_inputs}), got {X.shape}")
    if not np.all(np.isfinite(X)):
        raise ValueError("X_normalised: contains NaN or Inf")
    with tempfile.TemporaryDirectory(prefix="cdam_fw_") as tmp:
        X.astype("<f4").tofile(Path(tmp) / "fw_in.bin")
        if image not in ("fw_check", "fw_check_exact"):
            raise ValueError(f"image: expected 'fw_check' or 'fw_check_exact', got {image!r}")
        rc, kv, text = run_qemu(Path(build_dir).resolve() / f"{image}.elf", tmp, timeout=timeout)
        if rc != 0:
            raise RuntimeError(f"{image}.elf exited with {rc} under QEMU:\n{text[-2000:]}")
        Y = np.fromfile(Path(tmp) / "fw_out.bin", dtype="<f4").reshape(-1, fm.n_outputs)
    if Y.shape[0] != X.shape[0] or int(kv["vectors"]) != X.shape[0]:
        raise RuntimeError(f"firmware answered {Y.shape[0]} of {X.shape[0]} vectors")
    if int(kv["theta_fnv1a"], 16) != theta_fnv1a(fm.theta):
        raise RuntimeError("the firmware's weights differ from the model's (FNV-1a mismatch)")
    want = fm.forward_normalised(X.astype(np.float32).astype(np.float64))
    tpi = int(kv["cal_ticks"]) / int(kv["cal_instructions"])
    reps, empty = int(kv["reps"]), int(kv["empty_ticks"])
    return {
        "max_abs_error": float(np.max(np.abs(Y.astype(np.float64) - want))),
        "instructions_per_inference": round((int(kv["infer_ticks"]) - empty) / reps / tpi, 1),
        "instructions_per_prediction": round((int(kv["predict_ticks"]) - empty) / reps / tpi, 1),
        "stack_bytes": int(kv["stack_bytes"]),
        "sandbox": kv["sandbox"],
        "vectors": int(Y.shape[0]),
        "outputs": Y,
    }


MODES = {"one_step": 0, "free_run": 1, "k_step": None}   # k_step: the header carries k
MAX_K = 64    # the longest k-step horizon of fw_step_check (kMaxK there)


def step_record(fm: StepFirmwareModel, U, Y) -> tuple[np.ndarray, np.ndarray]:
    """(U, Y) as float64 arrays after the checks a record for a dynamic kind needs: shapes
    (N, inputs) and (N, outputs), finite, the same N and more than the model's t0 rows."""
    U = np.asarray(U, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    for name, a, w in (("U", U, fm.n_inputs), ("Y", Y, fm.n_outputs)):
        if a.ndim != 2 or a.shape[1] != w:
            raise ValueError(f"{name}: expected shape (N, {w}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: contains NaN or Inf")
    if U.shape[0] != Y.shape[0] or U.shape[0] <= fm.history:
        raise ValueError(f"U, Y: need the same number of rows, more than {fm.history}; got "
                         f"{U.shape[0]} and {Y.shape[0]}")
    return U, Y


def run_step_equivalence(build_dir, model, U, Y, mode: str = "one_step", *,
                         timeout: float = 60.0, k: int | None = None) -> dict:
    """The dynamic kinds (arx, hybrid, greybox): fw_step_check.elf runs the record (U (N, I),
    Y (N, m), physical units, rounded to float32) through ``fw::StepModel`` in ``mode``
    ("one_step": every row's prediction from the measured history; "k_step": from the measured
    rows up to t - k, ``k`` in 1..MAX_K, and its own predictions after; "free_run": from the
    first t0 measured rows only) and is compared with the Python model (float64) on the same
    float32-rounded record.

    Returns max_abs_error (over rows t0.. and outputs), output_span (the largest max - min of
    an output of Y), max_rel_error (the largest of each output's error over its span),
    instructions_per_step (mean, the measured row's observe included), instructions_per_observe
    (mean; 0 for the kinds that ignore the measured row) and instructions_per_step_max (the step
    alone), stack_bytes, steps, sandbox
    and the firmware's predictions ``outputs`` (N - t0, m) float32.
    """
    fm = model if isinstance(model, StepFirmwareModel) else load_firmware_model(model)
    if not isinstance(fm, StepFirmwareModel):
        raise ValueError("model: a bp_network model: use run_equivalence")
    if mode not in MODES:
        raise ValueError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
    if mode == "k_step":
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= MAX_K:
            raise ValueError(f"k: expected an integer in 1..{MAX_K} for mode 'k_step', got {k!r}")
        code = int(k) if k > 1 else MODES["one_step"]
    else:
        code = MODES[mode]
    U, Y = step_record(fm, U, Y)
    U32, Y32 = U.astype(np.float32), Y.astype(np.float32)
    with tempfile.TemporaryDirectory(prefix="cdam_fw_") as tmp:
        with open(Path(tmp) / "fw_step_in.bin", "wb") as f:
            f.write(struct.pack("<ii", U.shape[0], code))
            f.write(np.hstack([U32, Y32]).astype("<f4").tobytes())
        rc, kv, text = run_qemu(Path(build_dir).resolve() / "fw_step_check.elf", tmp,
                                timeout=timeout)
        if rc != 0:
            raise RuntimeError(f"fw_step_check.elf exited with {rc} under QEMU:\n{text[-2000:]}")
        P = np.fromfile(Path(tmp) / "fw_step_out.bin", dtype="<f4").reshape(-1, fm.n_outputs)
        monitored = fm.monitor is not None and mode == "one_step"
        if monitored:
            flags = np.fromfile(Path(tmp) / "fw_alarm_out.bin", dtype=np.uint8)
            frames = np.fromfile(Path(tmp) / "fw_alarm_frames.bin", dtype=np.uint8)
    steps = U.shape[0] - fm.history
    if P.shape[0] != steps or int(kv["steps"]) != steps:
        raise RuntimeError(f"firmware answered {P.shape[0]} of {steps} steps")
    if int(kv["params_fnv1a"], 16) != fm.params_fnv1a():
        raise RuntimeError("the firmware's parameters differ from the model's (FNV-1a mismatch)")
    want = fm.predict(U32.astype(np.float64), Y32.astype(np.float64), mode, k=k or 1)
    timed = int(kv.get("timed", steps))
    tpi = int(kv["cal_ticks"]) / int(kv["cal_instructions"])
    total = (int(kv["step_ticks_hi"]) << 32) + int(kv["step_ticks_lo"])
    empty = int(kv["empty_ticks"])
    # the measured row into the model after every row (fw::StepModel::observe; arm_coupling's
    # columns, nothing in the other kinds): its instructions count as the step's
    observed = int(kv.get("observed", 0))
    obs = ((int(kv["observe_ticks_hi"]) << 32) + int(kv["observe_ticks_lo"]) - empty * observed) \
        / max(observed, 1) / tpi if observed else 0.0
    err = np.max(np.abs(P.astype(np.float64) - want), axis=0)
    span = np.ptp(Y32.astype(np.float64), axis=0)
    extra = _monitor_report(fm, kv, Y32[fm.history:], want, flags, frames, tpi, steps) \
        if monitored else {}
    return {**extra,
        "mode": mode,
        "k": int(k) if mode == "k_step" else None,
        "max_abs_error": float(np.max(err)),
        "output_span": float(np.max(span)),
        "max_rel_error": float(np.max(np.where(span > 0, err / np.where(span > 0, span, 1),
                                               np.where(err > 0, np.inf, 0.0)))),
        "instructions_per_step": round((total - empty * timed) / max(timed, 1) / tpi + obs, 1),
        "instructions_per_observe": round(obs, 1),
        "instructions_per_step_max": round((int(kv["step_ticks_max"]) - empty) / tpi, 1),
        "stack_bytes": int(kv["stack_bytes"]),
        "sandbox": kv["sandbox"],
        "steps": steps,
        "outputs": P,
    }


def _monitor_report(fm, kv, Y32, want, flags, frames, tpi, steps) -> dict:
    """The firmware monitor's decisions (fw/monitor.hpp) beside Python's
    (cdam_core.evaluate.monitor) on the same float32 record, from Python's own prediction."""
    from cdam_core.evaluate.monitor import run_monitor
    from cdam_core.firmware.alarm import decode_alarm_frames
    if int(kv["monitor_fnv1a"], 16) != fm.monitor_fnv1a():
        raise RuntimeError("the firmware's monitor numbers differ from the model's (FNV-1a)")
    if flags.size != steps * fm.n_outputs or int(kv["monitored"]) != steps:
        raise RuntimeError(f"firmware monitored {flags.size // max(fm.n_outputs, 1)} of "
                           f"{steps} steps")
    flags = flags.reshape(steps, fm.n_outputs)
    R = Y32 - np.asarray(want, np.float64).astype(np.float32)
    py = run_monitor(fm.monitor, R)
    got = decode_alarm_frames(frames.tobytes())
    want_frames = [(c, f, min(k + 1, 0xFFFF), t + fm.history)
                   for k, (t, c, f) in enumerate(py.alarms)]
    total = (int(kv["monitor_ticks_hi"]) << 32) + int(kv["monitor_ticks_lo"])
    return {
        "monitor_flags": flags,
        "monitor_flags_python": py.flags,
        "monitor_mismatches": int(np.count_nonzero(flags != py.flags)),
        "monitor_alarms": int(np.count_nonzero(flags)),
        "monitor_alarms_python": len(py.alarms),
        "alarm_frames": got,
        "alarm_frames_equal": [(c, f, n, t) for _, c, f, n, t in got] == want_frames,
        "instructions_per_monitor": round((total - int(kv["empty_ticks"]) * steps)
                                          / steps / tpi, 1),
    }


def run_kernels(build_dir, window, passes: int = 1, *, timeout: float = 30.0) -> np.ndarray:
    """Check (3): five-point cubic smoothing of ``window`` (float32, 5..1024 samples) on the
    emulated board; returns the smoothed window (float32)."""
    w = np.asarray(window, dtype=np.float32)
    if w.ndim != 1 or not 5 <= w.size <= 1024:
        raise ValueError(f"window: expected 5..1024 samples (1-D), got shape {w.shape}")
    if not np.all(np.isfinite(w)):
        raise ValueError("window: contains NaN or Inf")
    if int(passes) < 0:
        raise ValueError(f"passes: must be >= 0, got {passes}")
    with tempfile.TemporaryDirectory(prefix="cdam_fw_") as tmp:
        with open(Path(tmp) / "fw_smooth_in.bin", "wb") as f:
            f.write(struct.pack("<ii", w.size, int(passes)))
            f.write(w.astype("<f4").tobytes())
        rc, kv, text = run_qemu(Path(build_dir).resolve() / "fw_kernels.elf", tmp, timeout=timeout,
                                icount=None)
        if rc != 0:
            raise RuntimeError(f"fw_kernels.elf exited with {rc}:\n{text[-2000:]}")
        return np.fromfile(Path(tmp) / "fw_smooth_out.bin", dtype="<f4")


def _read_curve(text: str) -> dict:
    kv, curve = {}, []
    for line in text.splitlines():
        if line.startswith("curve="):
            curve.append(float(line.split("=", 1)[1]))
        elif "=" in line:
            k, v = line.split("=", 1)
            kv[k.strip()] = v.strip()
    return {"curve": np.asarray(curve), **kv}


def run_optim_target(build_dir, *, timeout: float = 120.0) -> dict:
    """fw_optim.elf under QEMU: IBOA (20 butterflies) seeding a 4-8-2 network on the 200
    samples in flash, then LM epochs, heap-free (the link proves it).

    Returns {"curve": IBOA best MSE after init and each iteration, then the LM MSE of each
    recorded epoch (float64 array), "theta": the trained weights (58 float32), "iterations",
    "lm_epochs", "evaluations", "status", "stack_bytes", "seconds" (wall time of the QEMU run)}.
    """
    import time
    elf = Path(build_dir).resolve() / "fw_optim.elf"
    if not elf.is_file():
        raise FileNotFoundError(f"build_dir: no fw_optim.elf in {build_dir}")
    with tempfile.TemporaryDirectory(prefix="cdam_fw_") as tmp:
        t0 = time.perf_counter()
        rc, _, text = run_qemu(elf, tmp, timeout=timeout, icount=None)
        secs = time.perf_counter() - t0
        if rc != 0:
            raise RuntimeError(f"fw_optim.elf exited with {rc} under QEMU:\n{text[-2000:]}")
        curve = np.fromfile(Path(tmp) / "fw_optim_curve.bin", dtype="<f8")
        theta = np.fromfile(Path(tmp) / "fw_optim_theta.bin", dtype="<f4")
    res = _read_curve(text)
    res["curve"] = curve
    res["theta"] = theta
    res["seconds"] = secs
    return res


def run_optim_host(host_build_dir, *, timeout: float = 120.0) -> dict:
    """The same run compiled for the host in float32 (fw_optim_host of the host build of
    firmware_stubs); returns curve, iterations, lm_epochs, evaluations and status."""
    exe = Path(host_build_dir).resolve() / "fw_optim_host"
    if not exe.is_file():
        raise FileNotFoundError(f"host_build_dir: no fw_optim_host in {host_build_dir}")
    r = _run([str(exe)], timeout=timeout)
    if r.returncode != 0:
        raise RuntimeError(f"fw_optim_host exited with {r.returncode}:\n{r.stderr[-2000:]}")
    return _read_curve(r.stdout)
