"""Errors per group of outputs: the nano-drone benchmark's metrics.

A group is a vector (position, velocity, body rates: its error is the Euclidean norm of the
error vector) or a unit quaternion (attitude, components in the order given, scalar last or
first as named: its error is the geodesic angle 2 atan2(|v|, |w|) of the relative rotation
q_true^-1 q_pred, both normalised, in rad; q and -q are the same attitude). Per group and
horizon:

- MAE = mean of the error over the scored rows (the benchmark's metric: "mean Euclidean norm
  of the error per group, attitude as the quaternion geodesic angle"), and its sum over the
  horizons 1..50;
- RMSE = square root of the mean squared error (the RMS of the same norm or angle).

Group text (``--groups``): ``"position=x,y,z;attitude=quat:qx,qy,qz,qw;rates=wx,wy,wz"``; a
quaternion group lists x, y, z, w (``quat:``) or w, x, y, z (``quat_wxyz:``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Group", "parse_groups", "group_errors", "quaternion_angle", "NANODRONE_GROUPS"]

KINDS = ("vector", "quat", "quat_wxyz")


@dataclass(frozen=True)
class Group:
    """A named set of outputs scored together (``kind`` in vector, quat, quat_wxyz)."""

    name: str
    columns: tuple
    kind: str = "vector"

    def to_json(self) -> dict:
        return {"kind": self.kind, "columns": list(self.columns)}


NANODRONE_GROUPS = (Group("position", ("x", "y", "z")), Group("velocity", ("vx", "vy", "vz")),
                    Group("attitude", ("qx", "qy", "qz", "qw"), "quat"),
                    Group("rates", ("wx", "wy", "wz")))


def parse_groups(text, outputs) -> list[Group]:
    """Groups from text (module doc) checked against the ``outputs`` names."""
    groups, seen = [], set()
    for item in (s.strip() for s in str(text).split(";")):
        if not item:
            continue
        if "=" not in item:
            raise ValueError(f"groups: expected name=columns, got {item!r}")
        name, spec = (s.strip() for s in item.split("=", 1))
        kind = "vector"
        for k in KINDS[1:]:
            if spec.startswith(k + ":"):
                kind, spec = k, spec[len(k) + 1:]
        cols = tuple(c.strip() for c in spec.split(",") if c.strip())
        if not name or not cols:
            raise ValueError(f"groups: empty name or no column in {item!r}")
        if name in seen:
            raise ValueError(f"groups: {name!r} given twice")
        if kind != "vector" and len(cols) != 4:
            raise ValueError(f"groups: {name}: a quaternion has 4 columns, got {len(cols)}")
        for c in cols:
            if c not in outputs:
                raise ValueError(f"groups: {name}: {c!r} is not an output "
                                 f"(outputs: {', '.join(outputs)})")
        seen.add(name)
        groups.append(Group(name, cols, kind))
    if not groups:
        raise ValueError("groups: no group given")
    return groups


def quaternion_angle(q_true, q_pred, scalar_last: bool = True) -> np.ndarray:
    """Geodesic angle (rad, in [0, pi]) between rows of two (N, 4) quaternion arrays."""
    a = np.asarray(q_true, dtype=np.float64)
    b = np.asarray(q_pred, dtype=np.float64)
    if a.shape != b.shape or a.ndim != 2 or a.shape[1] != 4:
        raise ValueError(f"q_true, q_pred: expected two (N, 4) arrays, got {a.shape}, {b.shape}")
    if not scalar_last:
        a, b = a[:, [1, 2, 3, 0]], b[:, [1, 2, 3, 0]]
    na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    if np.any(na == 0) or np.any(nb == 0):
        raise ValueError("q_true, q_pred: a zero quaternion has no attitude")
    a, b = a / na[:, None], b / nb[:, None]
    av, aw, bv, bw = a[:, :3], a[:, 3], b[:, :3], b[:, 3]
    # relative rotation conj(a) * b (Hamilton product): w and vector part
    w = aw * bw + np.sum(av * bv, axis=1)
    v = aw[:, None] * bv - bw[:, None] * av - np.cross(av, bv)
    return 2.0 * np.arctan2(np.linalg.norm(v, axis=1), np.abs(w))


def group_errors(Y, P, outputs, groups) -> np.ndarray:
    """(N, G) error of each row per group: Euclidean norm or geodesic angle (module doc)."""
    idx = {o: j for j, o in enumerate(outputs)}
    out = np.empty((len(Y), len(groups)))
    for g, grp in enumerate(groups):
        cols = [idx[c] for c in grp.columns]
        if grp.kind == "vector":
            out[:, g] = np.linalg.norm(P[:, cols] - Y[:, cols], axis=1)
        else:
            out[:, g] = quaternion_angle(Y[:, cols], P[:, cols], grp.kind == "quat")
    return out
