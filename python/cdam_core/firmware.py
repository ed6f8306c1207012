"""Firmware side: export an identified model to a C++ header, cross-build the STM32F405 images,
run them under QEMU (netduinoplus2) and talk to the 1 kHz loop over SLCAN.

The firmware (``firmware_stubs/``) runs the core's own ``cdam::Mlp`` (cpp/include/cdam/mlp.hpp)
with the fast activation of cdam/fast_math.hpp on the weights of ``generated/model.hpp``. This
module:

- ``export_header(model_path, out)``: the header (constexpr float weights, sizes, scaling
  constants per network input, sha256 of the source model, FNV-1a of the float32 weights).
- ``build(...)``: CMake cross build (toolchain file firmware_stubs/cmake/arm-none-eabi.cmake),
  text/data/bss of every image, heap guard by ``--wrap`` at link time.
- ``run_equivalence(...)`` / ``check(...)``: checks (1) and (2) under ``timeout qemu-system-arm``.
- ``run_kernels(...)``, ``run_optim_target(...)`` / ``run_optim_host(...)``: check (3), the
  smoothing kernel and a fixed-size IBOA-BP + LM run (data: ``optim_data`` /
  ``export_optim_data``) on the board and on the host.
- ``closed_loop_pil(...)`` / ``closed_loop_python(...)``: check (4), processor in the loop.

NARX models: the firmware works in the network's input space (the regressor). The exporter
writes one pair of scaling constants per regressor element (the output scaler's for past
outputs, the input scaler's for past inputs), so the firmware scales a raw regressor exactly as
``BPNetwork`` does.
"""
from __future__ import annotations

import hashlib
import math
import os
import re
import shutil
import struct
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = [
    "FIRMWARE_DIR", "FirmwareModel", "load_firmware_model", "export_header", "theta_fnv1a",
    "toolchain_available", "build", "run_qemu", "run_equivalence", "run_kernels", "check",
    "JointPlant", "closed_loop_python", "closed_loop_pil", "pid_config",
    "optim_data", "export_optim_data", "run_optim_target", "run_optim_host", "OPTIM_SHAPE",
]

def _firmware_dir() -> Path:
    """firmware_stubs/: $CDAM_FIRMWARE_DIR, else beside the source tree, else above the cwd."""
    env = os.environ.get("CDAM_FIRMWARE_DIR")
    if env:
        return Path(env).resolve()
    here = Path(__file__).resolve().parents[2] / "firmware_stubs"
    if (here / "CMakeLists.txt").is_file():
        return here
    for d in [Path.cwd(), *Path.cwd().parents]:
        if (d / "firmware_stubs" / "CMakeLists.txt").is_file():
            return d / "firmware_stubs"
    return here


FIRMWARE_DIR = _firmware_dir()
QEMU = "qemu-system-arm"
ARM_GCC = "arm-none-eabi-gcc"


@dataclass
class FirmwareModel:
    """What the firmware needs of a model file, in the network's input space."""

    inputs: list            # names of the network inputs (regressor elements for NARX)
    outputs: list
    hidden: int
    activation: str         # "tansig" or "logsig"
    theta: np.ndarray       # (D,) float64, [W1(:); b1; W2(:); b2]
    x_min: np.ndarray       # (I,) per network input
    x_max: np.ndarray
    y_min: np.ndarray       # (O,)
    y_max: np.ndarray
    sha256: str             # checksum of the source model file's model section
    narx: tuple | None = None
    source: str = ""

    @property
    def n_inputs(self) -> int:
        return len(self.x_min)

    @property
    def n_outputs(self) -> int:
        return len(self.y_min)

    def scale_inputs(self, X) -> np.ndarray:
        """Min-max to [-1, 1] per network input (a constant column maps to 0)."""
        return _minmax(np.asarray(X, dtype=np.float64), self.x_min, self.x_max)

    def forward_normalised(self, Xn) -> np.ndarray:
        """The Python model's normalised outputs (float64, numpy reference forward pass)."""
        from cdam_core.reference.mlp import mlp_forward
        return mlp_forward(np.asarray(self.theta, np.float64), np.asarray(Xn, np.float64),
                           self.hidden, self.n_outputs, self.activation)

    def predict(self, X) -> np.ndarray:
        """Physical outputs for physical network inputs (float64)."""
        yn = self.forward_normalised(self.scale_inputs(X))
        span = self.y_max - self.y_min
        return np.where(span > 0, (yn + 1) * span / 2 + self.y_min, self.y_min)


def _minmax(X, lo, hi):
    span = hi - lo
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(span > 0, 2 * (X - lo) / np.where(span > 0, span, 1) - 1, 0.0)


def _read_payload(path):
    """The checked model dictionary and its sha256 (model_io's reader)."""
    from cdam_core.model_io import read_model_payload
    return read_model_payload(path)


def load_firmware_model(path) -> FirmwareModel:
    """Read a model file (``cdam_core.save_model`` format) into a FirmwareModel.

    Raises FileNotFoundError for a missing file and ValueError for a corrupt or inconsistent one.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MODEL: no such file: {path}")
    p, digest = _read_payload(path)
    try:
        ins, outs = list(p["inputs"]), list(p["outputs"])
        h = int(p["hidden"])
        act = str(p["activation"])
        theta = np.asarray(p["theta"], dtype=np.float64)
        xmin, xmax = np.asarray(p["x_min"], float), np.asarray(p["x_max"], float)
        ymin, ymax = np.asarray(p["y_min"], float), np.asarray(p["y_max"], float)
        narx = tuple(int(v) for v in p["narx"]) if p.get("narx") is not None else None
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"MODEL: {path}: model section incomplete ({exc})") from None
    if act not in ("tansig", "logsig"):
        raise ValueError(f"MODEL: activation {act!r} is not supported (tansig or logsig)")
    i, m = len(ins), len(outs)
    if h < 1 or xmin.shape != (i,) or xmax.shape != (i,) or ymin.shape != (m,) or ymax.shape != (m,):
        raise ValueError(f"MODEL: {path}: sizes and scaling constants disagree")
    names = ins
    if narx is not None:
        na, nb, _ = narx
        names = [f"{outs[c]}[t-{a}]" for a in range(1, na + 1) for c in range(m)]
        names += [f"{ins[c]}[t-nk-{b}]" for b in range(nb) for c in range(i)]
        xmin = np.concatenate([ymin] * na + [xmin] * nb)
        xmax = np.concatenate([ymax] * na + [xmax] * nb)
    n_in = len(names)
    if theta.shape != (n_in * h + h + h * m + m,):
        raise ValueError(f"MODEL: theta has length {theta.shape[0]}, expected "
                         f"{n_in * h + h + h * m + m} for {n_in}-{h}-{m}")
    for name, arr in (("theta", theta), ("x_min", xmin), ("x_max", xmax), ("y_min", ymin),
                      ("y_max", ymax)):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"MODEL: {name} contains NaN or Inf")
    return FirmwareModel(names, outs, h, act, theta, xmin, xmax, ymin, ymax, digest, narx,
                         str(path))


def theta_fnv1a(theta) -> int:
    """FNV-1a (32 bit) of the little-endian float32 bytes of theta (the firmware checks it)."""
    h = 0x811C9DC5
    for b in np.asarray(theta, dtype="<f4").tobytes():
        h = ((h ^ b) * 0x01000193) & 0xFFFFFFFF
    return h


def _c_float(v: float) -> str:
    f = float(np.float32(v))
    if f == 0.0:
        return "0.0f"
    return f"{f:.9g}f" if ("e" in f"{f:.9g}" or "." in f"{f:.9g}") else f"{f:.9g}.0f"


def _c_array(name: str, values) -> str:
    vals = [_c_float(v) for v in values]
    rows = [", ".join(vals[k:k + 6]) for k in range(0, len(vals), 6)]
    return (f"alignas(4) constexpr float {name}[{len(vals)}] = {{\n    "
            + ",\n    ".join(rows) + "};\n")


def export_header(model, out) -> Path:
    """Write ``firmware_stubs/generated/model.hpp``-style header for ``model`` (a path or a
    FirmwareModel) to ``out``; returns the path. Weights are float32 with nine significant
    digits (exact round trip)."""
    fm = model if isinstance(model, FirmwareModel) else load_firmware_model(model)
    out = Path(out)
    if not out.parent.is_dir():
        raise ValueError(f"-o: folder {str(out.parent)!r} does not exist")
    i, h, m = fm.n_inputs, fm.hidden, fm.n_outputs
    text = [
        "// Generated by `cdam export-firmware` -- do not edit.",
        f"// Source: {Path(fm.source).name} (sha256 of its model section below).",
        f"// Network {i}-{h}-{m}, {fm.activation} hidden layer, linear output.",
        "// Inputs:  " + ", ".join(fm.inputs),
        "// Outputs: " + ", ".join(fm.outputs),
        "#pragma once",
        "#include <cstdint>",
        "",
        "namespace cdam_model {",
        "",
        f"constexpr int kInputs = {i};",
        f"constexpr int kHidden = {h};",
        f"constexpr int kOutputs = {m};",
        f"constexpr int kParams = {fm.theta.size};",
        f"constexpr bool kTansig = {'true' if fm.activation == 'tansig' else 'false'};",
        f'constexpr char kSourceSha256[] = "{fm.sha256}";',
        f"constexpr std::uint32_t kThetaFnv1a = 0x{theta_fnv1a(fm.theta):08X}u;",
        "",
        "// theta = [W1(:); b1; W2(:); b2], MATLAB column-major (W1 h x i, W2 m x h)",
        _c_array("kTheta", fm.theta),
        "// min-max scaling to [-1, 1] per network input and per output (lo == hi: constant)",
        _c_array("kXMin", fm.x_min),
        _c_array("kXMax", fm.x_max),
        _c_array("kYMin", fm.y_min),
        _c_array("kYMax", fm.y_max),
        "}  // namespace cdam_model",
        "",
    ]
    out.write_text("\n".join(text))
    return out


# ---------------------------------------------------------------------------------------------
# building and running


def toolchain_available() -> str | None:
    """None when arm-none-eabi-gcc, qemu-system-arm and cmake are on PATH, else what is missing."""
    missing = [t for t in (ARM_GCC, QEMU, "cmake") if shutil.which(t) is None]
    return ", ".join(missing) + " not found" if missing else None


def _run(cmd, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, **kw)


def _sizes(elf: Path) -> dict:
    out = _run(["arm-none-eabi-size", "--format=berkeley", str(elf)], check=True).stdout
    text, data, bss = (int(v) for v in out.splitlines()[1].split()[:3])
    return {"text": text, "data": data, "bss": bss}


IMAGES = ("fw_infer", "fw_check", "fw_loop", "fw_kernels", "fw_optim", "fw_check_exact")


def build(build_dir, model=None, *, jobs: int = 2, timeout: float = 600.0) -> dict:
    """Cross-build the firmware images into ``build_dir``.

    Args:
        build_dir: CMake build folder (created).
        model: a model file, a FirmwareModel, or None for the checked-in generated/model.hpp.
    Returns ``{image: {"text", "data", "bss"}}`` for fw_infer, fw_check, fw_loop, fw_kernels,
    fw_optim (check 3's IBOA-BP run) and fw_check_exact (fw_check with std::tanh, the
    benchmark's reference).
    Raises RuntimeError with the compiler output when the build fails (also when something
    uses the heap: the link then fails on ``__wrap_malloc``).
    """
    why = toolchain_available()
    if why:
        raise RuntimeError(f"cannot build the firmware: {why}")
    build_dir = Path(build_dir).resolve()
    build_dir.mkdir(parents=True, exist_ok=True)
    model_dir = FIRMWARE_DIR / "generated"
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
    return {name: _sizes(build_dir / f"{name}.elf") for name in IMAGES}


def heap_guard_works(build_dir, timeout: float = 120.0) -> bool:
    """True when an image that calls malloc fails to link on the undefined ``__wrap_malloc``."""
    r = _run(["cmake", "--build", str(build_dir), "--target", "fw_heap_probe.elf"],
             timeout=timeout)
    return r.returncode != 0 and "__wrap_malloc" in (r.stdout + r.stderr)


def run_qemu(elf, cwd, *, timeout: float = 30.0, icount: int | None = 4,
             extra: list | None = None) -> tuple[int, dict, str]:
    """Run an ELF on ``-M netduinoplus2`` with semihosting under ``timeout``.

    Returns (exit status, the ``key=value`` lines printed as a dict, the whole console text).
    Exit status 124 means the timeout hit.
    """
    cmd = ["timeout", "--kill-after=5", str(float(timeout)), QEMU, "-M", "netduinoplus2",
           "-display", "none", "-monitor", "none", "-serial", "null",
           "-chardev", "stdio,id=s0",
           "-semihosting-config", "enable=on,target=native,chardev=s0",
           "-kernel", str(Path(elf).resolve())]
    if icount is not None:
        cmd[6:6] = ["-icount", f"shift={int(icount)}"]
    cmd += list(extra or [])
    r = _run(cmd, cwd=str(cwd), timeout=timeout + 10)
    kv = {}
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


def default_inputs(fm: FirmwareModel, n: int = 1000, seed: int = 0) -> np.ndarray:
    """n normalised input vectors, uniform in [-1, 1], from the shared generator."""
    from cdam_core.reference.rng import Rng
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
    }


# ---------------------------------------------------------------------------------------------
# check (3), second half: IBOA-BP + LM on the board against the host's float32 run

OPTIM_SHAPE = (4, 8, 2)   # the network of the on-board run (fw/optim_run.hpp)
OPTIM_SAMPLES = 200
OPTIM_DATA_SEED = 42


def optim_data(seed: int = OPTIM_DATA_SEED, n: int = OPTIM_SAMPLES):
    """The training set of the on-board IBOA-BP run: a known 4-8-2 tansig teacher on uniform
    inputs, from the shared generator (cdam_core.reference.rng.Rng(seed)): first the teacher's
    58 weights uniform in [-1.5, 1.5], then n x 4 inputs uniform in [-1, 1] (sample by sample).
    Returns (X (n, 4) float32, T (n, 2) float32, teacher theta (58,) float64); T is the
    teacher's float64 output rounded to float32."""
    from cdam_core.reference.mlp import mlp_forward
    from cdam_core.reference.rng import Rng
    if int(n) < 1:
        raise ValueError(f"n: must be >= 1, got {n}")
    i, h, m = OPTIM_SHAPE
    rng = Rng(int(seed))
    teacher = np.array([rng.uniform(-1.5, 1.5) for _ in range(i * h + h + h * m + m)])
    X = np.array([rng.uniform(-1.0, 1.0) for _ in range(int(n) * i)]).reshape(int(n), i)
    X = X.astype(np.float32)
    T = mlp_forward(teacher, X.astype(np.float64), h, m, "tansig").astype(np.float32)
    return X, T, teacher


def export_optim_data(out, seed: int = OPTIM_DATA_SEED, n: int = OPTIM_SAMPLES) -> Path:
    """Write the header with optim_data(seed, n) as constexpr float arrays (kX: n x 4,
    kT: n x 2, sample-major), held in flash by the firmware; returns the path."""
    out = Path(out)
    if not out.parent.is_dir():
        raise ValueError(f"out: folder {str(out.parent)!r} does not exist")
    X, T, _ = optim_data(seed, n)
    i, h, m = OPTIM_SHAPE
    text = [
        "// Generated by firmware_stubs/scripts/make_optim_data.py "
        "(cdam_core.firmware.export_optim_data) -- do not edit.",
        f"// {n} samples of a {i}-{h}-{m} tansig teacher (weights uniform in [-1.5, 1.5]) on",
        f"// inputs uniform in [-1, 1], shared generator seed {seed}; targets rounded to float32.",
        "#pragma once",
        "",
        "namespace cdam_optim_data {",
        "",
        f"constexpr int kSamples = {n};",
        f"constexpr int kInputs = {i};",
        f"constexpr int kOutputs = {m};",
        f"constexpr unsigned kDataSeed = {seed}u;",
        "",
        "// one sample per row: x (kInputs values), t (kOutputs values)",
        _c_array("kX", X.ravel()),
        _c_array("kT", T.ravel()),
        "}  // namespace cdam_optim_data",
        "",
    ]
    out.write_text("\n".join(text))
    return out


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


# ---------------------------------------------------------------------------------------------
# check (4): processor in the loop over SLCAN

REFERENCE_ID, DIAGNOSTIC_ID = 0x300, 0x3F0


def pid_config() -> dict:
    """The loop constants of firmware_stubs/include/fw/config.hpp (kDt, kKp, kKi, kKd, ...)."""
    text = (FIRMWARE_DIR / "include" / "fw" / "config.hpp").read_text()
    vals = dict(re.findall(r"constexpr float (k\w+) = ([-+0-9.eE]+)f;", text))
    need = {"kDt", "kKp", "kKi", "kKd", "kIntegralLimit", "kCurrentLimitA"}
    if not need <= vals.keys():
        raise ValueError(f"config.hpp: missing constants {sorted(need - vals.keys())}")
    return {k: float(v) for k, v in vals.items()}


@dataclass
class JointPlant:
    """Two independent geared joints driven by C610/M2006 currents: J dw/dt = kt I - b w.

    State per joint: output angle q (rad) and speed w (rad/s); integrated exactly over one
    period for constant current (first-order speed response). The C610 is taken to track its
    current command within the period and reports it as the feedback current.
    """

    inertia: float = 0.01      # kg m^2 at the output
    damping: float = 0.05      # N m s/rad
    kt: float = 0.18           # N m/A (cdam_core.can.codec.DEFAULT_KT_OUTPUT)
    q: np.ndarray = field(default_factory=lambda: np.zeros(2))
    w: np.ndarray = field(default_factory=lambda: np.zeros(2))
    counts: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=int))

    def step(self, current_counts, dt: float) -> None:
        """Advance by dt with the currents (C610 counts) held."""
        self.counts = np.asarray(current_counts, dtype=int)[:2].copy()
        tau = self.kt * self.counts * 1e-3
        a = self.damping / self.inertia
        w_inf = tau / self.damping
        e = math.exp(-a * dt)
        self.q = self.q + w_inf * dt + (self.w - w_inf) * (1 - e) / a
        self.w = w_inf + (self.w - w_inf) * e

    def feedback_frames(self):
        """The two C610 feedback frames (0x201, 0x202) of the present state."""
        from cdam_core.can.codec import COUNTS_PER_REV, GEAR_RATIO, encode_feedback
        frames = []
        for j in range(2):
            rotor = self.q[j] * GEAR_RATIO / (2 * math.pi) * COUNTS_PER_REV
            angle = int(math.floor(rotor)) % COUNTS_PER_REV
            rpm = int(round(self.w[j] * GEAR_RATIO * 60 / (2 * math.pi)))
            frames.append(encode_feedback(j + 1, angle, rpm, int(self.counts[j])))
        return frames


def default_reference(t: float) -> tuple[float, float]:
    """Joint references (rad): 0.5 rad from 0.01 s and -0.3 rad from 0.05 s (steps; the PIL
    loop sends a 0x300 frame only when the reference changes, which saves 22 bytes a cycle on
    the emulated UART)."""
    return (0.5 if t >= 0.01 else 0.0), (-0.3 if t >= 0.05 else 0.0)


def _reference_frame(r):
    import can
    return can.Message(arbitration_id=REFERENCE_ID, is_extended_id=False,
                       data=struct.pack("<2f", float(r[0]), float(r[1])))


def closed_loop_python(duration: float = 2.0, reference=default_reference,
                       plant: JointPlant | None = None, model=None) -> dict:
    """The loop of fw/controller.hpp in plain Python (float64) on the same plant and frames.

    Returns t, r (N, 2), q (N, 2) plant angles before each step, u (N, 2) current counts and,
    with ``model``, y0 (N,) the model's first output on the features.
    """
    from cdam_core.can.codec import (MotorState, decode_current_command, decode_feedback,
                                     encode_current_command)
    cfg = pid_config()
    dt, n = cfg["kDt"], int(round(float(duration) / cfg["kDt"]))
    if n < 1:
        raise ValueError(f"duration: must be at least one period, got {duration}")
    plant = plant or JointPlant()
    fm = None if model is None else (model if isinstance(model, FirmwareModel)
                                     else load_firmware_model(model))
    motors, integ = [MotorState(), MotorState()], np.zeros(2)
    out = {k: [] for k in ("t", "r", "q", "u", "y0")}
    for k in range(n):
        t = k * dt
        r = np.asarray(reference(t), dtype=float)
        feats = []
        for j, msg in enumerate(plant.feedback_frames()):
            fb = decode_feedback(msg)
            th, om, amps, _ = motors[j].update(fb.angle, fb.speed_rpm, fb.current, t=t)
            feats += [th, om, amps]
        f = np.asarray(feats)
        e = r - f[[0, 3]]
        integ = np.clip(integ + e * dt, -cfg["kIntegralLimit"], cfg["kIntegralLimit"])
        u = np.clip(cfg["kKp"] * e + cfg["kKi"] * integ - cfg["kKd"] * f[[1, 4]],
                    -cfg["kCurrentLimitA"], cfg["kCurrentLimitA"])
        counts = np.clip(np.round(u * 1000), -10000, 10000).astype(int)
        cmd = decode_current_command(encode_current_command(counts[:2] * 1e-3))
        out["t"].append(t)
        out["r"].append(r)
        out["q"].append(plant.q.copy())
        out["u"].append(counts)
        if fm is not None:
            x = np.resize(f, fm.n_inputs)
            out["y0"].append(float(fm.predict(x[None, :])[0, 0]))
        plant.step([round(cmd[1] * 1000), round(cmd[2] * 1000)], dt)
    return {k: np.asarray(v) for k, v in out.items()}


def _free_port() -> int:
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _set_nodelay(bus) -> None:
    """TCP_NODELAY on python-can's slcan socket (pyserial's ``socket://`` keeps it in
    ``_socket``); without it every frame written waits for the previous one's delayed ACK."""
    import socket
    sock = getattr(getattr(bus, "serialPortOrig", None), "_socket", None)
    if sock is not None:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


def closed_loop_pil(build_dir, duration: float = 2.0, reference=default_reference,
                    plant: JointPlant | None = None, *, timeout: float | None = None) -> dict:
    """Check (4): fw_loop.elf under QEMU, the plant in Python, python-can over SLCAN on the
    emulated USART1 (``-serial tcp:127.0.0.1:PORT,server=on,wait=on``).

    ``timeout`` (seconds of wall time for QEMU) defaults to 60 + 0.1 s per cycle.
    Both ends of the TCP link run with TCP_NODELAY (QEMU's ``nodelay=on`` and the client
    socket): with Nagle's algorithm each of the many small writes of a cycle waited for a
    delayed ACK, about 40 ms a write, which made a cycle take about 0.1 s of wall time instead
    of about 5 ms.
    Lock-step: each period sends the reference (0x300) and both feedback frames, waits for the
    0x200 command and the 0x3F0 diagnostic, then advances the plant one period. Returns the
    same arrays as closed_loop_python plus frames_sent, frames_received, cycles (the
    firmware's counter) and rejected (frames the firmware refused).
    """
    import can
    from cdam_core.can.codec import decode_current_command
    cfg = pid_config()
    dt, n = cfg["kDt"], int(round(float(duration) / cfg["kDt"]))
    if n < 1:
        raise ValueError(f"duration: must be at least one period, got {duration}")
    plant = plant or JointPlant()
    if timeout is None:  # about 5 ms of wall time per cycle with TCP_NODELAY
        timeout = 60.0 + 0.1 * n
    port = _free_port()
    elf = Path(build_dir).resolve() / "fw_loop.elf"
    if not elf.is_file():
        raise FileNotFoundError(f"build_dir: no fw_loop.elf in {build_dir}")
    proc = subprocess.Popen(
        ["timeout", "--kill-after=5", str(float(timeout)), QEMU, "-M", "netduinoplus2",
         "-display", "none", "-monitor", "none",
         "-serial", f"tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on", "-kernel", str(elf)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out = {k: [] for k in ("t", "r", "q", "u", "y0")}
    sent = received = 0
    cycles = rejected = 0
    last_ref = None
    bus = None
    try:
        import time
        deadline = time.monotonic() + 10
        while True:
            try:
                bus = can.Bus(interface="slcan", channel=f"socket://127.0.0.1:{port}",
                              bitrate=1000000, sleep_after_open=0)
                break
            except Exception:
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise
                time.sleep(0.05)
        _set_nodelay(bus)
        # The emulated USART drops bytes that arrive before the firmware enables it, so the
        # open sequence python-can sent may be lost: wait for an answer to "V", then open.
        while bus.get_version(0.5)[0] is None:
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError("the firmware does not answer on the SLCAN port")
        bus.open()
        for k in range(n):
            t = k * dt
            r = np.asarray(reference(t), dtype=float)
            q_before = plant.q.copy()
            changed = last_ref is None or not np.array_equal(r, last_ref)
            last_ref = r
            for msg in ([_reference_frame(r)] if changed else []) + plant.feedback_frames():
                bus.send(msg)
                sent += 1
            cmd = diag = None
            while cmd is None or diag is None:
                msg = bus.recv(timeout=5.0)
                if msg is None:
                    raise RuntimeError(f"no answer from the firmware at cycle {k}")
                received += 1
                if msg.arbitration_id == 0x200:
                    cmd = decode_current_command(msg)
                elif msg.arbitration_id == DIAGNOSTIC_ID:
                    diag = bytes(msg.data)
            y0, cyc, rej = struct.unpack("<fHH", diag)
            if cyc != (k + 1) & 0xFFFF:
                raise RuntimeError(f"cycle counter {cyc} at step {k}: a frame was lost")
            cycles, rejected = k + 1, rej
            counts = [int(round(cmd[1] * 1000)), int(round(cmd[2] * 1000))]
            out["t"].append(t)
            out["r"].append(r)
            out["q"].append(q_before)
            out["u"].append(counts)
            out["y0"].append(y0)
            plant.step(counts, dt)
    finally:
        if bus is not None:
            bus.shutdown()
        if proc.poll() is None:
            proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
    res = {k: np.asarray(v) for k, v in out.items()}
    res.update(frames_sent=sent, frames_received=received, cycles=cycles, rejected=rejected)
    return res
