"""The C++ simulator against its numpy twin: f(x, u) to 1e-12, a 1 s closed-loop trajectory to
1e-9, the hover equilibrium, the sub-step rule, and bad input."""
import math

import numpy as np
import pytest

core = pytest.importorskip("cdam_core._core")
from cdam_core.reference import simulator as ref  # noqa: E402
from cdam_core.sim.flight import substeps_for  # noqa: E402
from cdam_core.sim.parameters import (control_vector, hover_rotor_speed, plant_dict,  # noqa: E402
                                      plant_vector, total_mass)

EFFECTS_ON = dict(Fc1=0.03, Fc2=0.02, backlash1=0.01, backlash2=0.02, K3_1=5000, K3_2=3000,
                  payload=0.1, ground_k=1.0, thrust_loss=0.003)


def _random_state(rng):
    x = np.zeros(21)
    x[0:3] = rng.normal(size=3)
    x[2] = abs(x[2]) + 0.3
    q = rng.normal(size=4)
    x[3:7] = q / np.linalg.norm(q)
    x[7:9] = rng.normal(scale=0.5, size=2)
    x[9:11] = x[7:9] + rng.normal(scale=0.05, size=2)    # cable deflections of a few degrees
    x[11:21] = rng.normal(size=10)
    return x


@pytest.mark.parametrize("overrides", [{}, EFFECTS_ON])
def test_rhs_matches_numpy_to_1e12(overrides):
    P = plant_vector(**overrides)
    rng = np.random.default_rng(7)
    for _ in range(25):
        x = _random_state(rng)
        u = np.concatenate([rng.uniform(150, 1000, 4), rng.normal(scale=0.5, size=2)])
        t = rng.uniform(0, 20)
        a = core.sim_rhs(P, t, x, u)
        b = ref.rhs(P, t, x, u)
        # 1e-12 relative to the largest derivative (the motor-side accelerations dominate)
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.max(np.abs(b)))


def _setpoints(n, dt=1e-3):
    t = np.arange(n) * dt
    sp = np.zeros((n, 8))
    sp[:, 0] = 0.3 * np.sin(2.1 * t)
    sp[:, 2] = 1.0 + 0.2 * np.sin(3.0 * t)
    sp[:, 3] = 0.1 * np.sin(5.0 * t)
    sp[:, 4] = 0.1 * np.cos(4.0 * t) - 0.1
    sp[:, 5] = 0.4 * np.sin(2.0 * t)
    sp[:, 6] = 0.5 * np.sin(6.0 * t)
    sp[:, 7] = -0.4 * np.sin(8.0 * t)
    return sp


def test_one_second_closed_loop_matches_numpy_to_1e9():
    P = plant_vector(**EFFECTS_ON)
    C = control_vector(delay_rotor=4, delay_joint=3)
    n = 1000
    sp = _setpoints(n)
    x0 = ref.hover_state(P)
    X, LOG = core.sim_closed_loop(P, C, x0, sp, 1e-3, 1)
    Xr, LOGr = ref.simulate_closed_loop(P, C, x0, sp, 1e-3, 1)
    assert np.ptp(Xr[:, 7]) > 0.2 and np.ptp(Xr[:, 0]) > 0.01   # the flight really moves
    np.testing.assert_allclose(X, Xr, rtol=0, atol=1e-9)
    np.testing.assert_allclose(LOG, LOGr, rtol=1e-9, atol=1e-9)


def test_open_loop_matches_numpy_with_substeps():
    P = plant_vector(Ks1=4e4)
    x0 = ref.hover_state(P)
    x0[9] = 0.01
    U = np.tile([600.0, 610.0, 600.0, 590.0, 0.05, -0.02], (50, 1))
    n_sub = substeps_for(P, 1e-3)
    assert n_sub == core.sim_substeps(P, 1e-3) == math.ceil(1e-3 * math.sqrt(4e4 / 1e-3) / 2.5)
    X = core.sim_open_loop(P, x0, U, 1e-3, n_sub)
    Xr = ref.integrate_open_loop(P, x0, U, 1e-3, n_sub)
    np.testing.assert_allclose(X, Xr, rtol=0, atol=1e-9)


def test_hover_is_an_equilibrium():
    P = plant_vector()
    p = plant_dict(P)
    om = math.sqrt(total_mass(p) * p["g"] / (4 * p["CT"]))   # closed form, T = m g
    assert om == pytest.approx(hover_rotor_speed(p))
    x0 = ref.hover_state(P, Z=1.5)
    dx = core.sim_rhs(P, 0.0, x0, np.array([om] * 4 + [0.0, 0.0]))
    assert np.max(np.abs(dx)) < 1e-12
    sp = np.zeros((3000, 8))
    sp[:, 2] = 1.5
    X, LOG = core.sim_closed_loop(P, control_vector(), x0, sp, 1e-3, 1)
    assert np.max(np.abs(X[-1] - x0)) < 1e-9
    np.testing.assert_allclose(LOG[:, 0], total_mass(p) * p["g"], rtol=1e-12)


def test_bad_input_raises_value_error_naming_the_argument():
    P = plant_vector()
    x = ref.hover_state(P)
    u = np.zeros(6)
    with pytest.raises(ValueError, match="plant"):
        core.sim_rhs(P[:-1], 0.0, x, u)
    with pytest.raises(ValueError, match="x"):
        core.sim_rhs(P, 0.0, np.r_[x[:-1], np.nan], u)
    with pytest.raises(ValueError, match="plant"):
        core.sim_rhs(plant_vector(m_body=-1.0), 0.0, x, u)
    with pytest.raises(ValueError, match="setpoints"):
        core.sim_closed_loop(P, control_vector(), x, np.zeros((10, 7)), 1e-3, 1)
    with pytest.raises(ValueError, match="control"):
        core.sim_closed_loop(P, control_vector(delay_joint=1000), x, np.zeros((10, 8)), 1e-3, 1)
    with pytest.raises(ValueError, match="dt"):
        core.sim_open_loop(P, x, np.zeros((3, 6)), 0.0, 1)
    with pytest.raises(ValueError, match="unknown parameter"):
        plant_vector(nonsense=1.0)


def test_twin_writes_out_the_same_parameter_layout():
    from cdam_core.sim.parameters import CONTROL_NAMES, PLANT_NAMES
    assert ref.PLANT_NAMES == PLANT_NAMES
    assert ref.CONTROL_NAMES == CONTROL_NAMES
