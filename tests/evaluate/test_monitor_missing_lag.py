"""The monitor on flights whose rotors lag 30 ms (the independent quad generator): a model
without the lag false-alarms on clean flights, because its residual is a model error that
follows the manoeuvres (most of the vertical-velocity and rate residual is a linear map of the
last input increments) and its low-frequency power differs from flight to flight; no
threshold from the training flights covers that (benchmarks/monitor_missing_lag.py: AR
thresholds per segment, an input-increment correction and the largest thresholds of four
training flights leave 4, 5 and 3 of 6 flights with alarms). With the lag chosen from the training flight's own held-out one-step error the
clean flight raises none and the effects still alarm at once. A campaign (about 90 s: two
calibrations, six fits, a 60 s flight): fuzz marker.
"""
import sys
from pathlib import Path

import numpy as np
import pytest

from cdam_core.evaluate.monitor import calibrate, one_step_residuals, run_monitor
from cdam_core.models.flight.physics import QuadPhysics

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "models"))
from quad_generator import TRUTH, flight  # noqa: E402

LAG = 0.03
LAGS = (0.0, 0.01, 0.02, 0.03, 0.04, 0.05)
N_FIT = 1500          # the training flight's first 15 s; its last 5 s choose the lag


def choose_lag(U, Y):
    """The lag whose model, fitted on the first N_FIT rows, has the least sum of log one-step
    RMS errors of velocity and rates on the rest (plain numpy on the model's predictions)."""
    score = {}
    for T in LAGS:
        m = QuadPhysics(lag=T).fit(U[:N_FIT], Y[:N_FIT])
        R = (Y - m.predict(U, Y, mode="one_step"))[N_FIT + 50:]
        score[T] = np.sum(np.log(np.sqrt(np.mean(R[:, [3, 4, 5, 10, 11, 12]] ** 2, axis=0))))
    return min(score, key=score.get)


@pytest.fixture(scope="module")
def training():
    U, Y, _ = flight(seconds=20.0, seed=3, lag=LAG)
    return U, Y


def _alarms(m, sec, U, Y):
    return run_monitor(sec, *one_step_residuals(m, U, Y)).alarms


@pytest.mark.fuzz
def test_missing_lag_alarms_and_the_chosen_lag_does_not(training):
    U, Y = training
    U2, Y2, _ = flight(seconds=60.0, seed=13, lag=LAG)
    m0 = QuadPhysics().fit(U, Y)
    sec0 = calibrate(m0, U, Y, 0.01, paths=200, seed=0)
    wrong = _alarms(m0, sec0, U2, Y2)
    print("model without the lag: alarms", wrong)
    assert len(wrong) > 0          # the limitation this file documents
    T = choose_lag(U, Y)
    assert T == LAG                # the held-out rule finds the generator's lag
    m = QuadPhysics(lag=T).fit(U, Y)
    sec = calibrate(m, U, Y, 0.01, paths=200, seed=0)
    assert _alarms(m, sec, U2, Y2) == []
    # a thrust loss of 10 % at t = 10 s still alarms within 0.5 s, and not before
    U3, Y3, _ = flight(seconds=12.0, seed=21, lag=LAG,
                       effect=(10.0, dict(TRUTH, kT=0.9 * TRUTH["kT"])))
    rows = [t for t, _, _ in _alarms(m, sec, U3, Y3)]
    assert rows and min(rows) >= 1000 and min(rows) <= 1050
