"""The simulator's state layout: the hover state and attitude of quaternion states."""
from __future__ import annotations

import numpy as np

__all__ = ["NX", "hover_state", "quat_to_euler"]

NX = 21   # state size of cdam/sim/simulator.hpp (layout documented there)


def quat_to_euler(qt) -> np.ndarray:
    """Z-Y-X Euler angles (phi, theta, psi) of unit quaternions (..., 4) in (w, x, y, z) order."""
    qt = np.asarray(qt, dtype=float)
    w, x, y, z = qt[..., 0], qt[..., 1], qt[..., 2], qt[..., 3]
    phi = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    theta = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    psi = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([phi, theta, psi], axis=-1)


def hover_state(Z: float = 1.0) -> np.ndarray:
    """Level at (0, 0, Z), identity attitude, arm hanging, cables relaxed, at rest."""
    x = np.zeros(NX)
    x[2] = Z
    x[3] = 1.0
    return x
