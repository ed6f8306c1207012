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
