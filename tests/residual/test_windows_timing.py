"""The input timing the equations choose, checked on output error's windows
(residual.timing.windows_timing). Random joint seed 9 (tests/residual/random_joints.py, plain
numpy: open loop, 1 kHz, a link encoder with 3e-4 rad of noise, a chirp to 4.1 Hz under a
15.6 Hz cable resonance, the torque held over each sample): IDIM-LS is far off (errors-in-
variables: Im +190 %), its held-out equations chose "sampled" (p 0.0036) and output error then
ended at Im +15 %, Ks -7.8 %, I -6.4 %, Dl -11 % (about 5 of its sigmas). The windows prefer
the generator's hold (p 8e-7); with it Im +3.2 %, Ks -1.6 %, I -1.4 %, Dl -0.8 %, Dm +0.9 %."""
import os
import sys

import pytest

from cdam_core.cli.residual import _summary

sys.path.insert(0, os.path.dirname(__file__))
import random_joints  # noqa: E402


@pytest.fixture(scope="module")
def seed9():
    from cdam_core.residual.analyse import analyse
    p, rec, _, _ = random_joints.stable_record(9)
    assert p["control"] == "open" and p["fs"] == 1000.0
    return p, analyse("flexible_joint", rec["t"],
                      {k: rec[k] for k in ("tau_m", "theta_m", "q")}, free_run=False)


def test_the_windows_overrule_the_biased_equations_and_the_hold_is_kept(seed9):
    p, sel = seed9
    tm = sel.settings["timing"]
    assert sel.settings["estimator"]["chosen"] == "output error (multiple shooting)"
    assert tm["windows_check"]["equations_chose"] == "sampled"
    assert tm["chosen"] == "held" and tm["windows_check"]["p_value_held"] < 0.005
    for k in ("Im", "I", "Ks", "Dl", "Dm"):
        assert sel.final.theta[k] == pytest.approx(p[k], rel=0.05), k


def test_the_summary_says_who_chose_the_timing(seed9):
    _, sel = seed9
    line = next(x for x in _summary({"model": "flexible_joint", "settings": sel.settings,
                                     "findings": [], "final_parameters": {}, "unexplained": []})
                if x.startswith("input timing"))
    assert line.startswith("input timing: held (output error's windows, p ")
    assert "the equations chose sampled, p 0.0036" in line
