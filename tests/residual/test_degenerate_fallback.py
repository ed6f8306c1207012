"""A flexible-joint fit that collapses (an inertia or the cable's stiffness at its physical
bound 0) is not reported as the flexible model: the record does not separate the link from the
motor, and the analysis falls back to the rigid axis on the motor side ([greybox] item 4),
keeping the flexible estimates beside it.

Records: random_joints (plain numpy, not cdam_core.sim), open-loop chirps whose cable
deflection is 1.2-1.4 times the link encoder's count (16384 counts). Before session 20 the
analysis reported the collapsed fit: seed 14 Im 0 (-100 %), seed 16 I 0 and Ks 0 (-100 %), Im
+476 %. The rigid axis's truth is the joint's sum: M = Im + I, Fv = Dm + Dl (the cable is stiff
against the motion: resonance 40 and 26 Hz, the chirps end at 15 and 6.5 Hz), and the motor's
dry friction Fc.
"""
import os
import sys

import numpy as np
import pytest

from cdam_core.residual.analyse import analyse

sys.path.insert(0, os.path.dirname(__file__))
import random_joints  # noqa: E402


@pytest.mark.parametrize("seed", [14, 16])
def test_a_collapsed_flexible_fit_falls_back_to_the_rigid_axis(seed):
    p, rec, amp, Fc = random_joints.stable_record(seed)
    assert p["control"] == "open" and Fc > 0
    clean = random_joints.simulate({**p, "motor_counts": 0, "link_counts": 0,
                                    "link_noise": 0.0}, amp, Fc, seed)
    defl = np.std(clean["theta_m"] - clean["q"])
    assert defl < 3 * 2 * np.pi / p["link_counts"]      # near the link encoder's count
    sel = analyse("flexible_joint", rec["t"], {k: rec[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False)
    assert sel.final.model.name == "rigid_axis"
    why = sel.settings["identifiability"]
    assert "degenerate" in why["fallback"] and why["declared"] == "flexible_joint"
    assert set(why["degenerate"]) <= {"Im", "I", "Ks"} and why["degenerate"]
    assert all(why["flexible_estimates"][k] == 0.0 for k in why["degenerate"])
    th = sel.final.theta
    assert th["M"] == pytest.approx(p["Im"] + p["I"], rel=0.05)
    assert th["Fv"] == pytest.approx(p["Dm"] + p["Dl"], rel=0.05)
    fc = [s for s in sel.steps if s.candidate.effect.key == "coulomb_friction@tau"]
    assert fc, "the motor's dry friction is found on the rigid axis"
    assert th["coulomb_friction@tau.Fc"] == pytest.approx(Fc, rel=0.05)

