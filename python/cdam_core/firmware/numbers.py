"""Numbers as the generated headers write them: float32 literals, arrays, the FNV-1a checksum."""
from __future__ import annotations

import numpy as np


def theta_fnv1a(theta) -> int:
    """FNV-1a (32 bit) of the little-endian float32 bytes of theta (the firmware checks it)."""
    h = 0x811C9DC5
    for b in np.asarray(theta, dtype="<f4").tobytes():
        h = ((h ^ b) * 0x01000193) & 0xFFFFFFFF
    return h


def c_float(v: float) -> str:
    """A float32 C++ literal with nine significant digits (exact round trip)."""
    f = float(np.float32(v))
    if f == 0.0:
        return "0.0f"
    return f"{f:.9g}f" if ("e" in f"{f:.9g}" or "." in f"{f:.9g}") else f"{f:.9g}.0f"


def c_array(name: str, values) -> str:
    """``alignas(4) constexpr float name[n] = {...};`` six values a line."""
    vals = [c_float(v) for v in values]
    rows = [", ".join(vals[k:k + 6]) for k in range(0, len(vals), 6)]
    return (f"alignas(4) constexpr float {name}[{len(vals)}] = {{\n    "
            + ",\n    ".join(rows) + "};\n")


def c_int_array(name: str, values) -> str:
    """``constexpr int name[n] = {...};``."""
    return f"constexpr int {name}[{len(values)}] = {{{', '.join(str(int(v)) for v in values)}}};\n"


def finite32(name: str, values) -> None:
    """Refuse values that are not finite once rounded to float32 (ValueError naming them)."""
    v = np.asarray(values, dtype=np.float64)
    with np.errstate(over="ignore"):
        if not np.all(np.isfinite(v.astype(np.float32))):
            raise ValueError(f"MODEL: {name}: not finite in float32")
