"""An independent generator for the monitor's tests: a two-output plant at 1 kHz with process
and measurement noise, and three effects that switch on at a given time (not the simulator:
it has no time-switched effects)."""
import numpy as np

DT = 1e-3
ONSET_S = 10.0
EFFECTS = ("bias", "gain", "friction")


def plant(n, seed, effect=None, onset_s=ONSET_S):
    """(U, Y) of n rows; from row onset_s / DT on ``effect`` acts: 'bias' an external force on
    input 0 (+0.02), 'gain' actuator 1 at 85 % of its gain, 'friction' a Coulomb-like force
    of 0.002 against output 0's motion."""
    rng = np.random.default_rng(seed)
    hold = 200
    U = np.repeat(rng.uniform(-1, 1, (n // hold + 1, 2)), hold, axis=0)[:n]
    W = 1e-3 * rng.standard_normal((n, 2))
    V = 5e-4 * rng.standard_normal((n, 2))
    X = np.zeros((n, 2))
    on = int(round(onset_s / DT))
    for t in range(2, n):
        u0, u1 = U[t - 1]
        fr = 0.0
        if effect is not None and t >= on:
            if effect == "bias":
                u0 = u0 + 0.02
            elif effect == "gain":
                u1 = 0.85 * u1
            elif effect == "friction":
                fr = -0.002 * np.sign(X[t - 1, 0] - X[t - 2, 0])
        X[t, 0] = 1.6 * X[t - 1, 0] - 0.64 * X[t - 2, 0] + 0.04 * u0 + fr + W[t, 0]
        X[t, 1] = 0.9 * X[t - 1, 1] + 0.05 * X[t - 1, 0] + 0.1 * u1 + W[t, 1]
    return U, X + V


def measure(seeds=range(20, 30), clean_seeds=range(40, 45)):
    """Alarm delays per effect over ``seeds`` (12 s records, onset at 10 s) and false alarms
    over ``clean_seeds`` (60 s records without effect), for the model and monitor the tests
    use (ARX (2, 2, 1) on 60 s, seed 1; thresholds with 1,000 paths, seed 0)."""
    from cdam_core.evaluate.monitor import calibrate, one_step_residuals, run_monitor
    from cdam_core.models import ArxModel
    U, Y = plant(60_000, seed=1)
    m = ArxModel((2, 2, 1)).fit(U, Y)
    sec = calibrate(m, U, Y, DT, paths=1000, seed=0)
    onset = int(round(ONSET_S / DT))
    out = {"h": sec["h"], "ewma_limit": sec["ewma_limit"], "ar_order": sec["ar_order"]}
    for effect in EFFECTS:
        delays, before = [], 0
        for s in seeds:
            R, valid = one_step_residuals(m, *plant(12_000, seed=s, effect=effect))
            alarms = run_monitor(sec, R, valid).alarms
            before += sum(a[0] < onset for a in alarms)
            after = [a[0] for a in alarms if a[0] >= onset]
            delays.append(round((after[0] - onset) * DT, 3) if after else None)
        out[effect] = {"delays_s": delays, "alarms_before_onset": before}
    out["false_alarms_60s"] = [len(run_monitor(sec, *one_step_residuals(
        m, *plant(60_000, seed=s))).alarms) for s in clean_seeds]
    return out


if __name__ == "__main__":   # the figures of the report: python tests/evaluate/_monitor_plant.py
    import json
    print(json.dumps(measure(), indent=1))
