"""Printing helper of the nano-drone effect measurements (nanodrone_lag.py,
nanodrone_battery.py): one line per output group, RMSE without / with an effect."""
import json

import numpy as np


def print_groups(names, r0, r1, show, what: str, indent: str = "   ") -> None:
    """Per group: RMSE without / with at the horizons ``show`` (r0, r1: (H, groups), rows
    h = 1..H) and at how many horizons ``with`` is lower."""
    for g, name in enumerate(names):
        row = " ".join(f"h{h} {r0[h - 1, g]:.4f}/{r1[h - 1, g]:.4f}" for h in show)
        print(f"{indent}{name:9s} RMSE {what} {row}  lower at "
              f"{int(np.sum(r1[:, g] < r0[:, g]))}/{r0.shape[0]}")


def fold_means(out, types, rates, k0: str, k1: str):
    """The mean over the folds ``out[type][rates]`` of the RMSE tables ``k0`` and ``k1``."""
    return tuple(np.mean([out[k][rates][key] for k in types], axis=0) for key in (k0, k1))


def write_json(path, names, out) -> None:
    """Every fold's figures, with the group names, to ``path`` (nothing when None)."""
    if path:
        with open(path, "w") as fh:
            json.dump({"groups": names, "folds": out}, fh, indent=1)
