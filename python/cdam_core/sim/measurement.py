"""Realistic measurement of a simulated flight: Pixhawk-like sensor noise, the C610 encoder's
8192 counts per rotor revolution (before the 36:1 gearbox) on the motor angle, a 14-bit link
encoder, and the C610 current step on the motor torque (applied in the control loop).

Noise levels (standard deviations at ``noise_scale`` = 1), chosen from typical PX4 EKF2 output
with an indoor position source and magnetic joint encoders; white Gaussian, independent per
channel.
"""
from __future__ import annotations

import numpy as np

from cdam_core.sim.parameters import ENCODER_COUNTS, GEAR_RATIO
from cdam_core.sim.state import quat_to_euler

__all__ = ["NOISE_STD", "LINK_ENCODER_COUNTS", "quantise_motor_angle", "quantise_angle", "measure"]

NOISE_STD = {
    "phi": 0.002, "theta": 0.002, "psi": 0.004,   # rad: EKF attitude (about 0.1-0.2 deg)
    "X": 0.005, "Y": 0.005, "Z": 0.008,           # m: indoor position (mocap/UWB via EKF)
    "q1": 0.0005, "q2": 0.0005,                   # rad: link encoder electrical noise
}
LINK_ENCODER_COUNTS = 16384  # 14-bit magnetic encoder (AS5047-class) on each joint


def quantise_angle(angle, counts: int) -> np.ndarray:
    """Round an angle (rad) to a ``counts``-per-revolution encoder."""
    lsb = 2 * np.pi / counts
    return np.round(np.asarray(angle, dtype=float) / lsb) * lsb


def quantise_motor_angle(theta_m) -> np.ndarray:
    """Motor angle after the gearbox as the C610 sees it: the rotor angle (36 x theta_m) in
    8192 counts per revolution (multi-turn counted), divided back by the gear ratio."""
    rotor = quantise_angle(GEAR_RATIO * np.asarray(theta_m, dtype=float), ENCODER_COUNTS)
    return rotor / GEAR_RATIO


def measure(states, log, rng: np.random.Generator, noise_scale: float = 1.0) -> dict:
    """Columns of the logged record from true states (N, 21) and the controller log (N, 10).

    Draw order: one normal array per channel in the order of :data:`NOISE_STD`.
    """
    if not np.isfinite(noise_scale) or noise_scale < 0:
        raise ValueError(f"noise_scale: must be finite and >= 0, got {noise_scale}")
    states = np.asarray(states, dtype=float)
    log = np.asarray(log, dtype=float)
    if states.ndim != 2 or states.shape[1] != 21 or log.shape != (states.shape[0], 10):
        raise ValueError("states: expected (N, 21) states and an (N, 10) log")
    eta = quat_to_euler(states[:, 3:7])
    true = {"phi": eta[:, 0], "theta": eta[:, 1], "psi": eta[:, 2], "X": states[:, 0],
            "Y": states[:, 1], "Z": states[:, 2], "q1": states[:, 7], "q2": states[:, 8]}
    out = {"T": log[:, 0], "tau_phi": log[:, 1], "tau_theta": log[:, 2], "tau_psi": log[:, 3],
           "tau_m1": log[:, 4], "tau_m2": log[:, 5]}
    n = states.shape[0]
    for name, std in NOISE_STD.items():
        out[name] = true[name] + noise_scale * std * rng.standard_normal(n)
    out["psi"] = np.angle(np.exp(1j * out["psi"]))
    for k in ("q1", "q2"):
        out[k] = quantise_angle(out[k], LINK_ENCODER_COUNTS)
    out["theta_m1"] = quantise_motor_angle(states[:, 9])
    out["theta_m2"] = quantise_motor_angle(states[:, 10])
    for i in range(4):
        out[f"omega{i + 1}"] = log[:, 6 + i]
    return out
