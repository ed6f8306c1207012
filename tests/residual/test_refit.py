"""selection.refit: the final model's structure re-estimated as the loop estimated it (used by
``cdam residual --save F --firmware`` for arm_coupling's causal columns; it refitted with
GreyBox's own IDIM fit before: its own trim, no IDIM-WLS weights, no two stages, no chosen
estimator)."""
import pytest

from cdam_core.models.greybox.effects import CoulombFriction
from cdam_core.models.greybox.estimation import fit
from cdam_core.residual.selection import refit, select

from test_no_gain_gate import _prepared
from test_zoh_timing import _axis_dry


def test_refit_runs_the_chosen_output_error_estimator():
    """Exact-ZOH axis with dry friction 0.05: the loop chooses the output-error refinement;
    refit with the same effects gives the final parameters again, and they are not IDIM-LS's
    (Fv differs by more than refit's own agreement)."""
    t, u, q = _axis_dry(500.0, 10.0, 0, 0.05)
    m, sig = _prepared(t, u, q, None, 50.0)
    sel = select(m, sig, [CoulombFriction(channel="tau")], free_run=False)
    assert sel.settings["estimator"]["chosen"] == "output error (multiple shooting)"
    again = refit(sel, sel.final.effects)
    for k, v in sel.final.theta.items():
        assert again.theta[k] == pytest.approx(v, rel=1e-9, abs=1e-12)
    ls = fit(sel.final.model, sig, sel.final.effects, sel.settings["trim"])
    assert abs(ls.theta["Fv"] - sel.final.theta["Fv"]) > 1e-6


def test_refit_needs_the_prepared_record():
    import dataclasses
    t, u, q = _axis_dry(500.0, 4.0, 0, 0.0)
    m, sig = _prepared(t, u, q, None, 50.0)
    sel = select(m, sig, [], free_run=False, estimator="idim-ls")
    with pytest.raises(ValueError, match="^sel: holds no prepared record"):
        refit(dataclasses.replace(sel, signals=None), ())
