"""Write the demo model that the checked-in generated/model.hpp is exported from.

A 6-20-8 tansig network on the loop's features [q1, w1, i1, q2, w2, i2] (joint angles rad,
speeds rad/s, currents A) with weights drawn from the shared generator (seed 6): a stand-in
with the identified model's sizes until `cdam identify` produces the real one. Run from the
repository root:
    PYTHONPATH=python python3 firmware_stubs/scripts/make_demo_model.py
    PYTHONPATH=python python3 -m cdam_core export-firmware \
        firmware_stubs/generated/demo_model.json -o firmware_stubs/generated/model.hpp
"""
from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np


def demo_model(seed: int = 6, hidden: int = 20):
    """A fitted-looking BPNetwork stand-in (attributes save_model reads)."""
    from cdam_core.reference.rng import Rng

    i, m = 6, 8
    d = i * hidden + hidden + hidden * m + m
    theta = Rng(seed).uniform_array(d, -1.0, 1.0) * 0.8
    lim_x = np.array([3.0, 40.0, 10.0, 3.0, 40.0, 10.0])
    lim_y = np.array([3.0, 40.0, 10.0, 3.0, 40.0, 10.0, 2.0, 2.0])
    return SimpleNamespace(
        theta_=theta, n_inputs_=i, n_outputs_=m, hidden_=hidden, activation="tansig", narx=None,
        scaler_x_=SimpleNamespace(data_min_=-lim_x, data_max_=lim_x),
        scaler_y_=SimpleNamespace(data_min_=-lim_y, data_max_=1.5 * lim_y))


def main() -> int:
    from cdam_core.models.file import save_model

    out = Path(__file__).resolve().parents[1] / "generated" / "demo_model.json"
    save_model(out, demo_model(), inputs=["q1", "w1", "i1", "q2", "w2", "i2"],
               outputs=["q1_next", "w1_next", "i1_next", "q2_next", "w2_next", "i2_next",
                        "tau1", "tau2"], meta={"note": "demo weights, shared Rng seed 6"})
    print(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
