"""Structures holding a dry friction are compared on two rollouts of the held-out windows (the
friction's sign held over each RK4 step, and its stick-slip), each at half the level
(selection.compare_structures). The logic against scipy's Wilcoxon on made-up window errors;
the windows' own pieces (which structures stick, the stick-slip view's scores) on a record of
the independent generator (tests/residual/random_joints.py, plain numpy)."""
import os
import sys

import numpy as np
import pytest
from scipy import stats

sys.path.insert(0, os.path.dirname(__file__))

from cdam_core.residual.selection import compare_structures   # noqa: E402
from cdam_core.residual.validation import paired               # noqa: E402

ALPHA = 0.01


class _Windows:
    """A stand-in for BlockedCV: per-window errors per structure (keyed by its effects), one
    table per rollout; ``sticky``: the effects a dry friction can stop the motion with."""

    integrator, criterion = "rk4", "simulation"

    def __init__(self, errors, sticky=(), view=None):
        self.errors, self.sticky, self.view, self.calls = errors, set(sticky), view, []

    def stick_slip_view(self):
        return self.view

    def sticks(self, effects=(), model=None):
        return bool(self.sticky & set(effects))

    def compare(self, simple, rich, tested, alpha):
        self.calls.append((simple[0], rich[0], tested))
        return paired(self.errors[simple[0]], self.errors[rich[0]], tested, alpha)


def _errors(rng, n=60, better=0.0):
    e0 = rng.gamma(2.0, 1.0, n)
    return e0, e0 * np.exp(rng.normal(-better, 0.3, n))


def _p(e0, e1):
    return float(stats.wilcoxon(e0 - e1, alternative="greater").pvalue)


def test_structures_that_cannot_stick_are_compared_once_at_the_full_level():
    rng = np.random.default_rng(1)
    e0, e1 = _errors(rng, better=0.12)
    view = _Windows({(): e0, ("viscous",): e0})
    cv = _Windows({(): e0, ("viscous",): e1}, view=view)
    v = compare_structures(cv, ((), None), (("viscous",), None), "idim", 3, ALPHA)
    assert cv.calls == [((), ("viscous",), 3)] and view.calls == []
    assert v.p_value == pytest.approx(_p(e0, e1), rel=1e-12)
    assert v.to_json()["level"] == pytest.approx(ALPHA / 3)
    assert "rollout" not in v.to_json()


def test_a_dry_friction_that_wins_only_where_the_motion_sticks_is_kept():
    rng = np.random.default_rng(2)
    e0, e_held = _errors(rng, better=-0.2)          # held: the friction's windows worse
    e_stick = e0 * np.exp(rng.normal(-0.5, 0.3, e0.size))
    view = _Windows({(): e0, ("coulomb",): e_stick}, sticky=("coulomb",))
    cv = _Windows({(): e0, ("coulomb",): e_held}, sticky=("coulomb",), view=view)
    v = compare_structures(cv, ((), None), (("coulomb",), None), "idim", 2, ALPHA)
    assert cv.calls == [((), ("coulomb",), 4)] and view.calls == [((), ("coulomb",), 4)]
    assert v.better and v.rollout == "stick-slip"
    assert v.p_value == pytest.approx(_p(e0, e_stick), rel=1e-12)
    assert v.to_json()["level"] == pytest.approx(ALPHA / 4)
    other = v.to_json()["other_rollout"]
    assert other["rollout"] == "held" and not other["better"]
    assert other["p_value"] == pytest.approx(_p(e0, e_held), rel=1e-12)


def test_each_rollout_pays_for_the_other():
    """A p-value between alpha / (2 m) and alpha / m on the held rollout alone: not kept."""
    rng = np.random.default_rng(3)
    for _ in range(2000):
        e0, e1 = _errors(rng, n=40, better=0.1)
        p = _p(e0, e1)
        if ALPHA / 4 < p < ALPHA / 2:
            break
    else:
        pytest.fail("no draw in the band")
    view = _Windows({(): e0, ("coulomb",): e0 * 1.01}, sticky=("coulomb",))
    cv = _Windows({(): e0, ("coulomb",): e1}, sticky=("coulomb",), view=view)
    v = compare_structures(cv, ((), None), (("coulomb",), None), "idim", 2, ALPHA)
    assert v.rollout == "held" and v.p_value == pytest.approx(p, rel=1e-12)
    assert not v.better
    plain = _Windows({(): e0, ("coulomb",): e1})     # the same errors, nothing that sticks
    assert compare_structures(plain, ((), None), (("coulomb",), None), "idim", 2, ALPHA).better


@pytest.fixture(scope="module")
def joint_windows():
    """Random joint seed 0 (open loop, 250 Hz, the motor's dry friction), its held-out
    windows as the analysis builds them."""
    from random_joints import stable_record
    from cdam_core.models.greybox.effects import candidates
    from cdam_core.models.greybox.estimation import fit
    from cdam_core.models.greybox.registry import get_model
    from cdam_core.residual.cutoff import choose_cutoff
    from cdam_core.residual.validation import BlockedCV
    p, rec, _, Fc = stable_record(0)
    assert Fc > 0
    m = get_model("flexible_joint")
    signals = {k: rec[k] for k in ("tau_m", "theta_m", "q")}
    filt, choice = choose_cutoff(m, rec["t"], signals, None)
    sig = m.prepare(rec["t"], signals, filt, None, "held")
    trim = choice["trim_samples"]
    cv = BlockedCV(m, sig, trim, declared=fit(m, sig, (), trim))
    coulomb = next(c for c in candidates(m, [], None) if c.key == "coulomb_friction@tau_m")
    return cv, (coulomb,)


def test_the_stick_slip_view_simulates_only_what_can_stick(joint_windows):
    cv, coulomb = joint_windows
    assert not cv.sticks(()) and cv.sticks(coulomb)
    view = cv.stick_slip_view()
    assert view is cv.stick_slip_view() and view.integrator == "rk4-stickslip"
    assert view.stick_slip_view() is None          # a view of a view: not RK4 held
    held0, _ = cv.scores(())
    np.testing.assert_array_equal(view.scores(())[0], held0)   # nothing to stop: the same
    h1, s1 = cv.scores(coulomb)[0], view.scores(coulomb)[0]
    assert np.all(np.isfinite(h1)) and np.all(np.isfinite(s1))
    assert not np.array_equal(h1, s1)


def test_a_bound_the_joint_fit_leaves_is_not_reported_as_hit(joint_windows):
    """output_error.joint_refine: a parameter the nested fit ended on a bound keeps no sigma
    only while the joint estimate is within the nested fit's tolerance of it (random joint
    seed 22 under stick-slip: Kd 0 in the nested fit, 0.37 in the joint one, had no sigma)."""
    from cdam_core.models.greybox.estimation import fit
    from cdam_core.residual.benchmark import greybox_of
    from cdam_core.residual.output_error import joint_refine
    cv, coulomb = joint_windows
    f = fit(cv.model, cv.sig, coulomb, cv.trim, bounded=True)
    bounds = dict(getattr(f.model, "bounds", {}) or {})
    for e in f.effects:
        bounds.update(e.bounds())
    U = cv.inputs(coulomb)
    starts = cv.training_starts(np.ones(cv.Y.shape[0], dtype=bool))[::2]
    out = {}
    for tol in (1e-9, 1e9):
        g = greybox_of(f, cv.dt)
        out[tol] = joint_refine(g, U, cv.Y, starts, bounds, cv.norm, cv.horizon, cv.dt,
                                cv.integrator, at_bound={"Kd": tol})
        assert g.theta_["Kd"] > 1e-3       # well off its bound 0
    assert "Kd" not in out[1e-9]["at_bound"] and np.isfinite(out[1e-9]["std"]["Kd"])
    assert out[1e9]["at_bound"] == ["Kd"] and np.isnan(out[1e9]["std"]["Kd"])
    assert np.isfinite(out[1e9]["std"]["Im"])
