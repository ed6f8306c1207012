"""Why the flight-model monitor false-alarms when the model lacks the rotors' lag, and what
removes it. A measurement, not a benchmark: `python benchmarks/monitor_missing_lag.py` (about
4 minutes on one core).

Set-up (session 7's finding): the independent quad generator (tests/models/quad_generator.py)
with a 30 ms first-order rotor lag; QuadPhysics fitted on a 20 s flight (seed 3), its monitor
calibrated there (evaluate.monitor.calibrate, 200 paths); six clean 60 s flights (seeds
10-15) with the same lag. Printed:
1. the monitor as calibrated (no lag in the model): alarms per flight, channel and statistic;
2. why: per flight and channel the std of the normalised residual z (the fast part) and of its
   EWMA (the part below ~1.6 Hz that the EWMA and the CUSUM accumulate), against the training
   flight's; and how much of the training residual a linear map of the last input increments
   (squared rotor speeds, 6 lags) explains: the missing lag's signature, a model error driven
   by the manoeuvres, whose low-frequency power differs from flight to flight;
3. calibrations tried: thresholds from AR models of the training record's segments (4 x 5 s,
   each at its own level, paths pooled), the residual corrected by that input-increment map
   before the monitor, and thresholds the largest over four training flights: alarms per
   flight;
4. the model's lag chosen from the training flight (one-step error of velocity and rates on
   its last 5 s, the model fitted on the first 15 s, lags 0-50 ms): alarms per flight, and the
   alarm delays of three effects switched on at t = 10 s on lag flights (thrust -10 %,
   payload +25 %, drag x3), and the lag-free flights' check (seeds 10-20) with a lag chosen
   the same way there.
"""
import sys
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

from cdam_core.evaluate.monitor import (K, _ar_fit, calibrate, one_step_residuals,
                                        run_monitor)
from cdam_core.models.flight.physics import QuadPhysics

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "models"))
from quad_generator import TRUTH, flight  # noqa: E402

LAG = 0.03
DT = 0.01
LAGS_TRIED = (0.0, 0.01, 0.02, 0.03, 0.04, 0.05)
EFFECTS = {"thrust loss 10 %": dict(TRUTH, kT=0.9 * TRUTH["kT"]),
           "payload +25 %": dict(TRUTH, mass=1.25 * TRUTH["mass"]),
           "drag x3": dict(TRUTH, drag_xy=3 * TRUTH["drag_xy"], drag_z=3 * TRUTH["drag_z"])}


def choose_lag(U, Y, n_fit=1500):
    """The lag of LAGS_TRIED whose model (fitted on the first n_fit rows) has the least sum of
    log one-step RMS errors of velocity and rates on the rest of the flight."""
    scores = {}
    for T in LAGS_TRIED:
        m = QuadPhysics(lag=T).fit(U[:n_fit], Y[:n_fit])
        R = (Y - m.predict(U, Y, mode="one_step"))[n_fit + 50:]
        scores[T] = float(np.sum(np.log(np.sqrt(np.mean(R[:, [3, 4, 5, 10, 11, 12]] ** 2, 0)))))
    return min(scores, key=scores.get), scores


def increments(U, lags=6):
    u2 = (U / U.mean()) ** 2
    d = np.r_[np.zeros((1, 4)), np.diff(u2, axis=0)]
    F = np.hstack([np.roll(d, j, axis=0) for j in range(lags)])
    F[:lags] = 0
    return np.c_[F, np.ones(len(F))]


def segment_section(sec, R, nseg=4, paths=100, seed=0):
    """Thresholds from AR models of each segment of the training residual at its own level."""
    lam = sec["lambda"]
    n = int(round(60.0 / DT))
    q = 1 - 0.05 / (3 * R.shape[1])
    h, L = [], []
    for c in range(R.shape[1]):
        z = (R[:, c] - sec["mean"][c]) / sec["std"][c]
        mc, me = [], []
        for k, seg in enumerate(np.array_split(z, nseg)):
            a, s2 = _ar_fit(seg)
            rng = np.random.default_rng(seed + 100 * c + k)
            den = np.r_[1.0, -a]
            imp = lfilter([1.0], den, np.r_[1.0, np.zeros(20000)])
            x = lfilter([1.0], den, rng.standard_normal((paths, n + 2000)), axis=1)[:, 2000:]
            x = x * np.std(seg) / np.sqrt(np.sum(imp ** 2))
            up, dn, ew = (np.zeros(paths) for _ in range(3))
            top_c, top_e = np.zeros(paths), np.zeros(paths)
            for j in range(n):
                up = np.maximum(up + x[:, j] - K, 0)
                dn = np.maximum(dn - x[:, j] - K, 0)
                ew = ew + lam * (x[:, j] - ew)
                top_c = np.maximum(top_c, np.maximum(up, dn))
                top_e = np.maximum(top_e, np.abs(ew))
            mc.append(top_c)
            me.append(top_e)
        h.append(float(np.quantile(np.concatenate(mc), q)))
        L.append(float(np.quantile(np.concatenate(me), q)))
    return {**sec, "h": h, "ewma_limit": L}


def alarms(m, sec, U, Y, correct=None):
    R, valid = one_step_residuals(m, U, Y)
    if correct is not None:
        R = (R - increments(U) @ correct).astype(np.float32)
    return run_monitor(sec, R, valid).alarms


def main():
    U, Y, _ = flight(seconds=20.0, seed=3, lag=LAG)
    m = QuadPhysics().fit(U, Y)
    sec = calibrate(m, U, Y, DT, paths=200, seed=0)
    R0, v0 = one_step_residuals(m, U, Y)
    tests = {s: flight(seconds=60.0, seed=s, lag=LAG)[:2] for s in range(10, 16)}
    lam = sec["lambda"]
    mean, std = np.asarray(sec["mean"]), np.asarray(sec["std"])

    def ewma_std(R):
        return lfilter([lam], [1, -(1 - lam)], (R - mean) / std, axis=0).std(axis=0)

    print("1. model without the lag, monitor as calibrated")
    for s, (U2, Y2) in tests.items():
        print(f"   flight {s}: alarms (row, channel, flags)", alarms(m, sec, U2, Y2)[:6])
    print("2. z std and EWMA std per flight over the training flight's (channels vx vy vz wx "
          "wy wz)")
    ch = [3, 4, 5, 10, 11, 12]
    base = ewma_std(R0[v0].astype(float))
    for s, (U2, Y2) in tests.items():
        R, v = one_step_residuals(m, U2, Y2)
        z = ((R[v] - mean) / std).std(axis=0)
        print(f"   flight {s}: z std {np.round(z[ch], 2)}, EWMA std / training "
              f"{np.round(ewma_std(R[v].astype(float))[ch] / base[ch], 2)}")
    F0 = increments(U)
    B = np.linalg.lstsq(F0[v0], R0[v0].astype(float), rcond=None)[0]
    Rc = R0[v0] - F0[v0] @ B
    print("   training residual variance explained by the last 6 input increments:",
          np.round(1 - Rc.var(axis=0)[ch] / R0[v0].var(axis=0)[ch], 2))
    print("3a. thresholds from 4 segments of the training residual")
    seg = segment_section(sec, R0[v0].astype(float))
    for s, (U2, Y2) in tests.items():
        print(f"   flight {s}:", alarms(m, seg, U2, Y2)[:6])
    print("3b. residual corrected by the input-increment map, thresholds recalibrated")
    Rc32 = Rc.astype(np.float32)
    cm, cs = Rc32.astype(float).mean(0), Rc32.astype(float).std(0, ddof=1)
    csec = dict(sec, mean=cm.tolist(), std=cs.tolist())
    csec = segment_section(csec, Rc32.astype(float), nseg=1, paths=200)
    for s, (U2, Y2) in tests.items():
        print(f"   flight {s}:", alarms(m, csec, U2, Y2, correct=B)[:6])
    print("3c. thresholds (and std) the largest of four 20 s training flights' calibrations "
          "(seeds 3-6)")
    secs = [sec] + [calibrate(m, *flight(seconds=20.0, seed=s, lag=LAG)[:2], DT, paths=200,
                              seed=0) for s in (4, 5, 6)]
    msec = dict(sec, **{k: np.max([x[k] for x in secs], axis=0).tolist()
                        for k in ("h", "ewma_limit", "std")})
    for s, (U2, Y2) in tests.items():
        print(f"   flight {s}:", alarms(m, msec, U2, Y2)[:6])
    T, scores = choose_lag(U, Y)
    print(f"4. lag chosen from the training flight: {T} s (scores {scores})")
    ml = QuadPhysics(lag=T).fit(U, Y)
    secl = calibrate(ml, U, Y, DT, paths=200, seed=0)
    for s, (U2, Y2) in tests.items():
        print(f"   flight {s}:", alarms(ml, secl, U2, Y2)[:6])
    k = int(round(10.0 / DT))
    for name, plant in EFFECTS.items():
        U2, Y2, _ = flight(seconds=15.0, seed=21, lag=LAG, effect=(10.0, plant))
        rows = [t for t, _, _ in alarms(ml, secl, U2, Y2)]
        after = [t for t in rows if t >= k]
        print(f"   {name}: alarms before the switch {sum(t < k for t in rows)}, delay "
              f"{(after[0] - k) * DT if after else None} s")
    U0, Y0, _ = flight(seconds=20.0, seed=3)
    T0, _ = choose_lag(U0, Y0)
    m0 = QuadPhysics(lag=T0).fit(U0, Y0)
    sec0 = calibrate(m0, U0, Y0, DT, paths=200, seed=0)
    counts = {s: len(alarms(m0, sec0, *flight(seconds=60.0, seed=s)[:2])) for s in range(10, 21)}
    print(f"   lag-free flights: lag chosen {T0} s, false alarms per 60 s flight {counts}")


if __name__ == "__main__":
    main()
