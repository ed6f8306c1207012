"""PX4 ULog flight logs (pyulog) into the dataset format.

Frames. PX4 logs in NED (world: x north, y east, z down) with an FRD body (x forward, y right,
z down). The dataset follows the paper's model (PAPER.md, eq. (1)): Z up and thrust along +z
body. We rotate both frames by 180 degrees about the north/forward axis: world NWU (X north,
Y west, Z up) and body FLU (x forward, y left, z up). That is the same rotation on both sides,
so with R = Rz(psi) Ry(theta) Rx(phi):

    phi = phi_px4,  theta = -theta_px4,  psi = -psi_px4
    X = x_ned,      Y = -y_ned,          Z = -z_ned
    tau_phi = tau_x,  tau_theta = -tau_y,  tau_psi = -tau_z,  T = -thrust_z (>= 0 hovering)

Units. Thrust and torque setpoints are PX4's normalised values (thrust 0..1 of full thrust,
torques -1..1 of the mixer's authority), not newtons: the sidecar says so per column. Motor
outputs are ``actuator_motors`` (0..1) or, on older PX4, ``actuator_outputs`` (PWM, us).
Setpoints before PX4 1.14 come from ``actuator_controls_0`` (control[0..3] = roll, pitch, yaw
torque, thrust).

Resampling (cdam_core.record.resample): attitude as angles (unwrapped, then linear), position linear,
setpoints and motor outputs zero-order hold; onto one grid at ``rate`` Hz over the span where
every present topic has data. Intervals longer than ``gap_factor`` times a topic's median
interval are reported as gaps, as are the logger's dropouts.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from cdam_core.record.dataset import Dataset
from cdam_core.record.resample import find_gaps, resample_signals

__all__ = ["load_ulog", "quaternion_to_euler_zyx", "ulog_platform"]

GROUPS = ("attitude", "position", "setpoints", "motors")


def quaternion_to_euler_zyx(q) -> np.ndarray:
    """(N, 4) quaternions [w, x, y, z] (PX4 order) -> (N, 3) Z-Y-X Euler [phi, theta, psi] rad."""
    q = np.asarray(q, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 4 or q.shape[0] == 0:
        raise ValueError(f"q: expected shape (N, 4), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError("q: contains NaN or Inf")
    norm = np.linalg.norm(q, axis=1)
    if np.any(norm < 1e-6):
        raise ValueError("q: zero quaternion")
    psi_theta_phi = Rotation.from_quat(q[:, [1, 2, 3, 0]] / norm[:, None]).as_euler("ZYX")
    return psi_theta_phi[:, ::-1].copy()


def ulog_platform(ulog) -> dict:
    """SITL or hardware, from the log's info messages (``ver_hw``, ``sys_name``)."""
    info = ulog.msg_info_dict
    hw = str(info.get("ver_hw", ""))
    sitl = "SITL" in hw.upper() or "SIM" in hw.upper()
    return {"platform": "SITL" if sitl else ("hardware" if hw else "unknown"),
            "sys_name": str(info.get("sys_name", "")), "ver_hw": hw,
            "ver_sw": str(info.get("ver_sw", ""))}


def _topic(ulog, name):
    for d in ulog.data_list:
        if d.name == name and d.multi_id == 0:
            return d
    return None


def _finite_rows(t, x):
    """Drop samples with a NaN/Inf value (PX4 logs NaN for invalid estimates) or repeated time."""
    x2 = x if x.ndim == 2 else x[:, None]
    ok = np.all(np.isfinite(x2), axis=1)
    t, x = t[ok], x[ok]
    keep = np.r_[True, np.diff(t) > 0]
    return t[keep], x[keep], int((~ok).sum()) + int((~keep).sum())


def load_ulog(path: str | Path, rate: float = 1000.0, gap_factor: float = 5.0) -> Dataset:
    """Read a PX4 ULog and return the flight in the dataset format.

    Columns (those whose topics are in the log): ``phi, theta, psi`` (rad), ``X, Y, Z`` (m),
    ``T, tau_phi, tau_theta, tau_psi`` (normalised), ``motor1..`` (normalised or PWM us).
    ``meta`` holds the platform (SITL/hardware), the topics used, ``missing`` groups, gaps,
    dropouts, units, interpolation per column and ``t0_us`` (log time of t = 0).

    Raises:
        ValueError: unreadable file, no usable topic, bad rate; FileNotFoundError.
    """
    from pyulog import ULog

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if not (np.isfinite(rate) and rate > 0):
        raise ValueError(f"rate: expected a positive rate in Hz, got {rate!r}")
    if not (np.isfinite(gap_factor) and gap_factor > 1):
        raise ValueError(f"gap_factor: expected a number > 1, got {gap_factor!r}")
    try:
        ulog = ULog(str(path))
    except Exception as exc:  # pyulog raises assorted errors on corrupt files
        raise ValueError(f"{path}: not a readable ULog file ({type(exc).__name__}: {exc})") \
            from None
    t0_us = int(ulog.start_timestamp)
    signals: dict[str, tuple] = {}
    units: dict[str, str] = {}
    topics: dict[str, str] = {}
    dropped: dict[str, int] = {}
    missing: list[str] = []

    def add(group, topic, cols, kind, unit):
        d = _topic(ulog, topic)
        if d is None or len(d.data["timestamp"]) < 2:
            return False
        t = (d.data["timestamp"].astype(np.float64) - t0_us) * 1e-6
        x = np.column_stack([f(d.data) for f in cols.values()])
        t, x, nbad = _finite_rows(t, x)
        if t.size < 2:
            return False
        names = list(cols)
        if group == "attitude":
            x = quaternion_to_euler_zyx(x) * np.array([1.0, -1.0, -1.0])  # FRD/NED -> FLU/NWU
            names = ["phi", "theta", "psi"]
        for j, name in enumerate(names):
            signals[name] = (t, x[:, j], kind)
            units[name] = unit
        topics[group] = topic
        dropped[topic] = nbad
        return True

    q = lambda k: (lambda d: d[f"q[{k}]"])                  # noqa: E731
    if not add("attitude", "vehicle_attitude",
               {"qw": q(0), "qx": q(1), "qy": q(2), "qz": q(3)}, "angle", "rad"):
        missing.append("attitude (vehicle_attitude)")
    if not add("position", "vehicle_local_position",
               {"X": lambda d: d["x"], "Y": lambda d: -d["y"], "Z": lambda d: -d["z"]},
               "linear", "m"):
        missing.append("position (vehicle_local_position)")
    ok_t = add("setpoints", "vehicle_thrust_setpoint", {"T": lambda d: -d["xyz[2]"]}, "hold",
               "normalised thrust (0..1 of full thrust)")
    ok_tau = add("setpoints_torque", "vehicle_torque_setpoint",
                 {"tau_phi": lambda d: d["xyz[0]"], "tau_theta": lambda d: -d["xyz[1]"],
                  "tau_psi": lambda d: -d["xyz[2]"]}, "hold", "normalised torque (-1..1)")
    if not (ok_t and ok_tau):
        if add("setpoints", "actuator_controls_0",
               {"T": lambda d: d["control[3]"], "tau_phi": lambda d: d["control[0]"],
                "tau_theta": lambda d: -d["control[1]"], "tau_psi": lambda d: -d["control[2]"]},
               "hold", "normalised (actuator_controls_0: thrust 0..1, torques -1..1)"):
            topics.pop("setpoints_torque", None)
        elif not (ok_t or ok_tau):
            missing.append("setpoints (vehicle_thrust_setpoint/vehicle_torque_setpoint or "
                           "actuator_controls_0)")
    _add_motors(ulog, add, missing)
    if not signals:
        raise ValueError(f"{path}: no usable topic (missing: {'; '.join(missing)})")
    grid, out = resample_signals(signals, rate)
    order = [c for c in ("T", "tau_phi", "tau_theta", "tau_psi", "phi", "theta", "psi", "X",
                         "Y", "Z") if c in out]
    order += sorted((c for c in out if c.startswith("motor")), key=lambda c: int(c[5:]))
    gaps = {}
    for name in order:
        t, _, _ = signals[name]
        med = float(np.median(np.diff(t)))
        g = find_gaps(t, gap_factor * med)
        if g:
            gaps[name] = g
    meta = {
        "source": f"PX4 ULog {path.name}",
        "rate": float(rate),
        **ulog_platform(ulog),
        "frame": "world NWU (X north, Y west, Z up), body FLU; converted from PX4 NED/FRD",
        "t0_us": t0_us,
        "topics": topics,
        "missing": missing,
        "nonfinite_or_repeated_samples_dropped": dropped,
        "gaps": gaps,
        "gap_rule": f"interval > {gap_factor:g} x the topic's median interval",
        "dropouts": [{"start": (int(d.timestamp) - t0_us) * 1e-6, "duration": d.duration * 1e-3}
                     for d in getattr(ulog, "dropouts", [])],
        "units": {c: units[c] for c in order},
        "interpolation": {c: signals[c][2] for c in order},
        "topic_rates_hz": {c: float(1.0 / np.median(np.diff(signals[c][0]))) for c in order},
    }
    meta["inputs"] = [c for c in ("T", "tau_phi", "tau_theta", "tau_psi") if c in order]
    meta["outputs"] = [c for c in ("phi", "theta", "psi", "X", "Y", "Z") if c in order]
    return Dataset(t=grid, columns=order, data=np.column_stack([out[c] for c in order]),
                   meta=meta)


def _add_motors(ulog, add, missing) -> None:
    d = _topic(ulog, "actuator_motors")
    if d is not None:
        n = [k for k in range(16) if f"control[{k}]" in d.data
             and np.all(np.isfinite(d.data[f"control[{k}]"]))]
        if n and add("motors", "actuator_motors",
                     {f"motor{k + 1}": (lambda d, k=k: d[f"control[{k}]"]) for k in n},
                     "hold", "normalised motor command (0..1)"):
            return
    d = _topic(ulog, "actuator_outputs")
    if d is not None and "noutputs" in d.data:
        n = int(min(np.max(d.data["noutputs"]), 8))
        if n and add("motors", "actuator_outputs",
                     {f"motor{k + 1}": (lambda d, k=k: d[f"output[{k}]"]) for k in range(n)},
                     "hold", "PWM (us)"):
            return
    missing.append("motors (actuator_motors or actuator_outputs)")
