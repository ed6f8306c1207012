"""An effect estimated outside its physical bounds is not claimed, and an output-error
refinement whose start cannot be simulated says so (both found by a sweep of random flexible
joints from a generator of their own, session 19: a link-side Coulomb friction claimed at
-0.0019 N m, then 0 in the final bounded fit; a ``KeyError`` out of ``cdam residual``).

Records: the independent rigid-axis generator (tests/residual/joint_generator.py), with a dry
friction of either sign: -0.3 N m is a torque along the motion, which no dry friction is."""
import numpy as np
import pytest

from cdam_core.models.greybox.declared import DerivativeFilter
from cdam_core.models.greybox.effects import candidates
from cdam_core.models.greybox.estimation import fit
from cdam_core.models.greybox.registry import get_model
from cdam_core.residual.output_error import refine
from cdam_core.residual.selection import evaluate, infeasible

from joint_generator import rigid_axis


def _coulomb_candidate(fc):
    r = rigid_axis(fs=500, Fc=fc, counts=16384, seed=0)
    m = get_model("rigid_axis")
    sig = m.prepare(r["t"], {"tau": r["tau"], "q": r["q"]}, DerivativeFilter(20.0), None, "held")
    eff = next(e for e in candidates(m) if e.name == "coulomb_friction")
    return eff, evaluate(m, sig, fit(m, sig, (), 50), eff, 0.01, 50)


def test_a_dry_friction_along_the_motion_is_not_screened():
    eff, c = _coulomb_candidate(-0.3)
    # unconstrained, least squares finds the negative friction (measured -0.297) ...
    assert c.fit.unconstrained[eff.key + ".Fc"] == pytest.approx(-0.3, rel=0.05)
    assert infeasible(c.fit, eff) == [eff.key + ".Fc"]
    # ... which at its bound (0) is the current model: nothing to claim (p was 0 before)
    assert c.pvalue == 1.0 and not c.screened


def test_a_dry_friction_against_the_motion_is():
    eff, c = _coulomb_candidate(0.3)
    assert infeasible(c.fit, eff) == []
    assert c.screened and c.fit.theta[eff.key + ".Fc"] == pytest.approx(0.3, rel=0.05)


class _Stub:
    estimated_ = ["a", "b"]

    def __init__(self):
        self.theta_ = {"a": 1.0, "b": -2.0}

    def set_parameters(self, th):
        self.theta_.update(th)


def test_refinement_from_a_start_that_cannot_be_simulated_raises_a_value_error():
    def shooting(g, U, Y, starts, samples=False, thetas=None):
        raise ValueError("the windows diverge")
    with pytest.raises(ValueError, match="starting estimate's windows cannot be simulated"):
        refine(_Stub(), np.zeros((10, 1)), np.zeros((10, 1)), np.arange(3), shooting, {})


@pytest.mark.parametrize("mode", ["noise-free", "as drawn"])
def test_a_softening_remainder_is_not_claimed_as_a_hardening_spring(mode):
    """random_joints seed 5 (plain numpy: link PD at 500 Hz, a chirp to 8 Hz, no effect at all;
    as drawn its encoders have 65536 and 16384 counts): session 20 found hardening_stiffness
    claimed with K3 -1028 (noise-free) and -825 (as drawn), a softening term whose torque is
    0.06 % of the drive's. K3 >= 0 is the effect's physical bound: nothing is claimed, and the
    parameters are those of the effect-free truth."""
    import random_joints
    from cdam_core.residual.analyse import analyse
    p = random_joints.draw(5)
    if mode == "noise-free":
        p.update(motor_counts=0, link_counts=0, link_noise=0.0)
    rec, _, Fc = random_joints.record(p)
    assert rec is not None and Fc == 0.0
    sel = analyse("flexible_joint", rec["t"], {k: rec[k] for k in ("tau_m", "theta_m", "q")},
                  free_run=False, estimator="idim-ls")
    assert [s.candidate.effect.key for s in sel.steps] == []
    for k in ("Im", "I", "Ks", "Dl", "Dm", "Kd"):
        assert sel.final.theta[k] == pytest.approx(p[k], rel=0.05), k
