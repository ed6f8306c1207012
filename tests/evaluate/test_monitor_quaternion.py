"""The monitor of a flight model on the independent quad generator (tests/models/quad_generator.py):
the unit quaternion's largest component is not watched (evaluate.monitor's module doc), clean
flights raise no alarm, and three different effects switched on at t = 10 s alarm within 0.5 s.

Before the quaternion was handled as one (session 6), the quad_physics monitor raised false
alarms on qw on 3 to 8 of 11 clean 60 s records: qw's one-step residual is second order in the
attitude error near hover and its spread follows the tilt (std of z 0.18 below 0.05 rad of
tilt, 1.14 above 0.2 on the training flight), which no stationary threshold fits.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core.evaluate.monitor import calibrate, one_step_residuals, run_monitor
from cdam_core.models.flight.physics import QuadPhysics

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "models"))
from quad_generator import TRUTH, flight  # noqa: E402

SWITCH = 10.0
EFFECTS = {"thrust loss 10 %": dict(TRUTH, kT=0.9 * TRUTH["kT"]),
           "payload +25 %": dict(TRUTH, mass=1.25 * TRUTH["mass"]),
           "drag x3": dict(TRUTH, drag_xy=3 * TRUTH["drag_xy"], drag_z=3 * TRUTH["drag_z"])}


@pytest.fixture(scope="module")
def monitored():
    U, Y, _ = flight(seconds=20.0, seed=3)
    m = QuadPhysics().fit(U, Y)
    return m, calibrate(m, U, Y, 0.01, paths=200, seed=0), Y


def _alarms(m, sec, U, Y):
    R, valid = one_step_residuals(m, U, Y)
    return run_monitor(sec, R, valid).alarms


def test_the_quaternions_largest_component_is_not_watched(monitored):
    m, sec, Y = monitored
    # qw is the largest component over the training flight (near hover): mean |q| per column
    assert np.argmax(np.mean(np.abs(Y[:, 6:10]), axis=0)) == 3
    assert sec["watched"] == [1] * 9 + [0] + [1] * 3
    # an unwatched output never alarms, however large its residual; a section without the
    # field (version 1 files) watches every output
    R = np.zeros((50, 13), np.float32)
    R[:, 9] = 1e3
    assert run_monitor(sec, R).alarms == []
    old = {k: v for k, v in sec.items() if k != "watched"}
    assert {c for _, c, _ in run_monitor(old, R).alarms} == {9}


def _check_clean(monitored, seeds):
    m, sec, _ = monitored
    counts = {s: len(_alarms(m, sec, *flight(seconds=60.0, seed=s)[:2])) for s in seeds}
    print("false alarms per clean 60 s record", counts)
    assert all(v == 0 for v in counts.values())


def test_clean_flights_raise_no_alarm(monitored):
    _check_clean(monitored, (10, 11))


@pytest.mark.fuzz
def test_eleven_clean_flights_raise_no_alarm(monitored):
    """The campaign of session 6's finding (seeds 10..20, 60 s each; about 80 s)."""
    _check_clean(monitored, range(10, 21))


@pytest.mark.parametrize("name", list(EFFECTS))
def test_effects_alarm_within_half_a_second(monitored, name):
    m, sec, _ = monitored
    U, Y, _ = flight(seconds=SWITCH + 5.0, seed=21, effect=(SWITCH, EFFECTS[name]))
    rows = [t for t, _, _ in _alarms(m, sec, U, Y)]
    k = int(round(SWITCH / 0.01))
    print(name, "first alarm after the switch (s):",
          (min(t for t in rows if t >= k) - k) * 0.01 if any(t >= k for t in rows) else None)
    assert not any(t < k for t in rows)
    assert any(k <= t <= k + 50 for t in rows)
