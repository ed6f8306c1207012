"""The residual loop's per-record caches ([speed] 23.4) change no result.

A structure search fits the same record hundreds of times; `estimation.design` and `fit` keep
the model's equations, the effect columns, the low-passed columns, the Gram matrices and the
solved least-squares blocks in the prepared record's cache. Every fit below is compared with
the same fit computed without any cache (a plain dict of the same signals: nothing is kept)
and on a cold cache (a fresh copy of the record), after the warm record has seen fits with
other delays, backlash widths, friction widths and rows: estimates, residuals, standard
deviations and conditioning must be equal to the last bit.
"""
import numpy as np
import pytest

from cdam_core.models.greybox.declared import Signals
from cdam_core.models.greybox.effects import (ActuatorDelay, ArmCoupling, Backlash,
                                              CoulombFriction, ThrustLoss)
from cdam_core.models.greybox.estimation import _Columns, design, fit
from cdam_core.models.greybox.registry import get_model
from cdam_core.sim import simulate_flight

TRIM = 100


@pytest.fixture(scope="module")
def flight():
    m = get_model("aerial_manipulator")
    ds = simulate_flight("both", duration=4.0, seed=2, effects=["thrust_loss"])
    sig = m.prepare(ds.t, {k: ds.column(k) for k in m.signals})
    return m, sig


def _cases():
    rotors = ("T", "tau_phi", "tau_theta", "tau_psi")
    rows = np.ones(4000, dtype=bool)
    rows[1500:2300] = False
    return [
        ((), None),
        ((ArmCoupling("Z"),), None),
        ((ArmCoupling("Z"), ThrustLoss("Z")), None),
        ((ActuatorDelay("rotors", delay=0.004, channels=rotors),), None),
        ((ActuatorDelay("rotors", delay=0.007, channels=rotors), ThrustLoss("Z")), None),
        ((Backlash("tau_l1", width=0.01),), None),
        ((Backlash("tau_l1", width=0.02), ArmCoupling("X")), None),
        ((CoulombFriction("tau_m1", eps=0.05, smooth=True),), None),
        ((CoulombFriction("tau_m1", eps=0.08, smooth=True),), rows),
        ((ThrustLoss("Z"),), rows),
    ]


def _same(a, b):
    assert a.theta == b.theta
    assert a.std.keys() == b.std.keys()
    assert all(a.std[p] == b.std[p] or (np.isnan(a.std[p]) and np.isnan(b.std[p]))
               for p in a.std)
    assert a.cond == b.cond
    assert a.violations == b.violations and a.unconstrained == b.unconstrained
    assert list(a.residuals) == list(b.residuals)
    for eq in a.residuals:
        assert np.array_equal(a.residuals[eq], b.residuals[eq]), eq
        assert np.array_equal(a.references[eq], b.references[eq]), eq


def test_cached_fits_equal_uncached_fits(flight):
    m, sig = flight
    plain = dict(sig)   # a plain dict: no cache at all
    # unconstrained twice (the second round reuses everything), then with the bounds
    for bounded, (effects, rows) in ([(False, c) for c in _cases() * 2]
                                     + [(True, c) for c in _cases()]):
        warm = fit(m, sig, effects, TRIM, bounded=bounded, rows=rows)
        cold_sig = sig.copy()
        cold_sig.cache = {}
        _same(warm, fit(m, cold_sig, effects, TRIM, bounded=bounded, rows=rows))
        _same(warm, fit(m, plain, effects, TRIM, bounded=bounded, rows=rows))
    assert sig.cache["blocks"].items, "the warm record kept no solved block"


def test_fit_with_base_equals_fit_without(flight):
    m, sig = flight
    cur = fit(m, sig, (ArmCoupling("Z"),), TRIM)
    for eff in (ThrustLoss("Z"), Backlash("tau_l2", width=0.015),
                ActuatorDelay("tau_m1", delay=0.003)):
        with_base = fit(m, sig, cur.effects + (eff,), TRIM, base=cur)
        _same(with_base, fit(m, dict(sig), cur.effects + (eff,), TRIM))


def test_design_columns_equal_uncached(flight):
    m, sig = flight
    eff = (ActuatorDelay("rotors", delay=0.005, channels=("T", "tau_phi", "tau_theta",
                                                          "tau_psi")), ThrustLoss("Z"))
    for _ in range(2):
        _, warm = design(m, sig, eff)
        _, plain = design(m, dict(sig), eff)
        assert list(warm) == list(plain)
        for eq, (y, cols) in warm.items():
            assert np.array_equal(y, plain[eq][0])
            assert list(cols) == list(plain[eq][1])
            for p, c in cols.items():
                assert np.array_equal(c, plain[eq][1][p]), (eq, p)


def test_low_passed_columns_found_by_content_only():
    cache = _Columns()
    x = np.sin(np.linspace(0.0, 20.0, 1001))
    first = cache.add(("eq", "col", "f"), x, 2.0 * x)
    assert cache.find(("eq", "col", "f"), x.copy()) is first          # equal content
    assert cache.find(("eq", "other", "f"), x) is None                # another slot
    y = x.copy()
    y[123] += 1e-12   # not one of the probed samples: the full comparison must see it
    assert cache.find(("eq", "col", "f"), y) is None
    second = cache.add(("eq", "col", "f"), y, 3.0 * y)
    assert second[2] != first[2]                                      # distinct content ids
    for k in range(_Columns.PER_SLOT):   # the least recently used entry leaves first
        cache.find(("eq", "col", "f"), x)
        cache.add(("eq", "col", "f"), x + k + 1.0, x)
    assert cache.find(("eq", "col", "f"), x) is first
    assert cache.find(("eq", "col", "f"), y) is None


def test_plain_dict_signals_keep_nothing(flight):
    m, sig = flight
    plain = dict(sig)
    fit(m, plain, (ThrustLoss("Z"),), TRIM)
    assert not isinstance(plain, Signals) and not hasattr(plain, "cache")
