"""Input timing ([greybox] item 1): the half-sample advance against closed forms, and the
choice's inputs checked (the choice itself on generator records: test_independent_joint)."""
import numpy as np
import pytest

from cdam_core.models.greybox.declared import half_sample_advance
from cdam_core.models.greybox.registry import get_model
from cdam_core.residual.analyse import analyse


def test_half_sample_advance_of_a_sine():
    # four-point cubic interpolation of sin(w t) at t + dt/2: the error is bounded by
    # 3/128 (w dt)^4 (Lagrange remainder of a cubic on [-1, 2] at 1/2: |(1.5)(0.5)(-0.5)(-1.5)|
    # / 4! = 0.5625 / 24 = 3/128), away from the ends
    dt, w = 1e-3, 2 * np.pi * 40.0
    t = np.arange(2000) * dt
    got = half_sample_advance(np.sin(w * t))
    want = np.sin(w * (t + dt / 2))
    assert np.max(np.abs(got[1:-2] - want[1:-2])) <= 3 / 128 * (w * dt) ** 4 * 1.001
    # a cubic polynomial is reproduced exactly
    x = 0.3 * t ** 3 - t ** 2 + 2 * t - 1
    y = 0.3 * (t + dt / 2) ** 3 - (t + dt / 2) ** 2 + 2 * (t + dt / 2) - 1
    assert np.allclose(half_sample_advance(x)[1:-2], y[1:-2], rtol=0, atol=1e-12)
    assert half_sample_advance(np.array([1.0]))[0] == 1.0


def test_prepare_held_advances_the_filtered_state_only():
    m = get_model("rigid_axis")
    t = np.arange(3000) * 1e-3
    raw = {"tau": np.sin(3 * t), "q": np.sin(2 * t)}
    s0 = m.prepare(t, raw, timing="sampled")
    s1 = m.prepare(t, raw, timing="held")
    assert s1["timing"] == "held" and s0["timing"] == "sampled"
    assert np.array_equal(s0["tau"], s1["tau"]) and np.array_equal(s0["q_raw"], s1["q_raw"])
    for k in ("q", "q_d", "q_dd"):
        assert np.allclose(s1[k][1:-2], half_sample_advance(s0[k])[1:-2])
    with pytest.raises(ValueError, match="timing"):
        m.prepare(t, raw, timing="zoh")


def test_analyse_rejects_an_unknown_timing():
    t = np.arange(3000) * 1e-3
    with pytest.raises(ValueError, match="timing: expected auto, sampled or held"):
        analyse("rigid_axis", t, {"tau": np.sin(t), "q": np.sin(t)}, timing="late")
