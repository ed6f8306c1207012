"""Running images under qemu-system-arm (netduinoplus2): equivalence, kernels, the on-board optimiser."""
from __future__ import annotations

import struct
import tempfile
from pathlib import Path

import numpy as np

from cdam_core.firmware.model import FirmwareModel, load_firmware_model, theta_fnv1a
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
