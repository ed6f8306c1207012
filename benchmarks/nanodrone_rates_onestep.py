"""Is there a one-step body-rates predictor better than the raw ARX's first step on a held-out
trajectory type? (issue [flights], the rates at h = 1 of the four-way protocol). A
measurement on the training types only: `python benchmarks/nanodrone_rates_onestep.py`.

On the 17 nano-drone flights, for each fold (test type left out, never read here) and each of
its three training types held out in turn: every candidate fitted by least squares on the
other two types' flights, scored one step ahead on the held-out type's flights (rows t >= 8 of
every segment, the same rows for all), RMSE of the rates vector (wx, wy, wz) over the raw
ARX's with the fold's orders (evaluate.crossfold's choice: (2, 2, 2) for random1, (2, 3, 2)
otherwise). First the autocorrelation of that ARX's rates equation error on each fold's
training flights (the least-squares ARX is the best one-step predictor only when it is white).
Candidates (plain numpy regressors, the ARX's plus):
  delay1      the newest rotor speed (orders (na, nb + 1, 1))
  lags6/8     6 or 8 lags of the rates; nb6: 6 rotor-speed lags
  torque      the mixer's omega_i^2 roll / pitch / yaw / thrust combinations (physics features)
  gyro        the gyroscopic products wy wz, wx wz, wx wy
  rotor_acc   d omega_i / dt (yaw reaction torque): spanned by the lagged speeds, no change
  armax3/6    two-stage ARMAX: an AR(3) / AR(6) on the ARX's one-step residual
  ridge       delay1 with a ridge penalty lam * N on the standardised regressors
  mix W       delay1 and the ARX mixed row by row, lambda d1 + (1 - lambda) arx, lambda the
              least-squares weight of their one-step errors over the W rows before (causal;
              ArxDirect first_mix)
Last, per flight: the share of the rates' one-sample change w(t+1) - w(t) explained (R^2, least
squares with w(t)) by the mixer's roll / pitch / yaw torque combinations of the rotor speeds
at t - L, L = 0, 1, 2 samples: where the rotor speeds sit in time against the rates.
About 30 s on one core.

Measured (session 11; docs/examples/nanodrone/anchored_first_step/ has the table in words):
the equation error is coloured (lag 2 -0.04..-0.16, lag 3 up to +0.34 on the yaw rate,
2/sqrt(N) = 0.008); delay1 -4..-11 % on square, random2, multisine held out, +4.8..+9 % on
random1 held out; no candidate lower on every held-out type of a fold except delay1 (and its
ridge) in the fold whose test type is random1 and nb6 in the random2 fold (-0.1..-0.8 %).
mix 100: -0.8..-10.5 % on every held-out type of every fold (50..400 rows within 0.15 %).
Per flight the best torque lag L is 0 on 7 flights, 1 on 8, 2 on 2 (random1: 1, 1, 2, 1;
multisine runs 1-2: 0, runs 3-4: 1; square 2, 1, 0, 0, 1): the rotor speeds' alignment
against the rates moves by 10-20 ms from flight to flight, within a type too, so no fixed
input delay is the best one-step predictor on every flight.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import sys  # noqa: E402

import numpy as np  # noqa: E402

from cdam_core.models.arx import physics_features  # noqa: E402
from cdam_core.record.realdata.nanodrone import (load_nanodrone, nanodrone_files,  # noqa: E402
                                                 trajectory_type)

TYPES = ("square", "random1", "random2", "multisine")
ORDERS = {"square": (2, 3, 2), "random1": (2, 2, 2), "random2": (2, 3, 2),
          "multisine": (2, 3, 2)}
R = slice(10, 13)          # wx, wy, wz among the 13 states
FIRST = 8


def segments():
    """{type: [(U, Y) of each segment longer than 50 rows]}."""
    out = {t: [] for t in TYPES}
    for f in nanodrone_files(None):
        ds = load_nanodrone(f)
        U, Y = ds.select(ds.inputs), ds.select(ds.outputs)
        for a, b in ds.segments:
            if b - a > 50:
                out[trajectory_type(f)].append((np.asarray(U[a:b], float),
                                                np.asarray(Y[a:b], float)))
    return out


def _lag(A, j):
    return A[FIRST - j:A.shape[0] - j]


def design(U, Y, c, scale):
    """Regressors of the rows t >= FIRST (targets Y[t], origin t - 1) and the rate targets."""
    na, nb, nk = c["orders"]
    cols = [_lag(Y, j) for j in range(1, na + 1)]
    cols += [_lag(Y[:, R], j) for j in range(na + 1, c.get("rate_lags", na) + 1)]
    F = physics_features(U, scale)[0] if c.get("torque") else U / scale
    cols += [_lag(F, nk + j) for j in range(nb)]
    if c.get("gyro"):
        w = Y[:, R]
        cols.append(_lag(np.c_[w[:, 1] * w[:, 2], w[:, 0] * w[:, 2], w[:, 0] * w[:, 1]], 1))
    if c.get("rotor_acc"):
        cols.append(_lag(np.diff(U / scale, axis=0, prepend=U[:1] / scale), nk))
    cols.append(np.ones((Y.shape[0] - FIRST, 1)))
    return np.hstack(cols), Y[FIRST:, R]


def residuals(train, test, c, lam=0.0):
    """One-step rate errors on ``test`` of the least squares (ridge ``lam``) on ``train``."""
    scale = np.max(np.abs(np.vstack([u for u, _ in train])), axis=0)
    X, T = (np.vstack(v) for v in zip(*[design(u, y, c, scale) for u, y in train]))
    mu, sd = X[:, :-1].mean(0), X[:, :-1].std(0)
    sd[sd == 0] = 1.0

    def z(X):
        return np.c_[(X[:, :-1] - mu) / sd, X[:, -1:]]

    Z = z(X)
    P = lam * len(Z) * np.eye(Z.shape[1])
    P[-1, -1] = 0.0
    W = np.linalg.solve(Z.T @ Z + P, Z.T @ T)
    return [T - z(X) @ W for X, T in (design(u, y, c, scale) for u, y in test)]


def armax(train, test, c, p):
    """Two-stage ARMAX: the ARX's one-step residual e, then e(t) on e(t-1..t-p) (least
    squares on ``train``); the second stage's errors on ``test``."""
    def stage2(E):
        X = np.vstack([np.hstack([e[p - j:len(e) - j] for j in range(1, p + 1)]) for e in E])
        return X, np.vstack([e[p:] for e in E])
    X, T = stage2(residuals(train, train, c))
    C = np.linalg.lstsq(X, T, rcond=None)[0]
    X, T = stage2(residuals(train, test, c))
    return [T - X @ C]


def mix(E1, E2, window):
    """Errors of lambda p1 + (1 - lambda) p2 per segment, lambda from the past window's
    errors E1, E2 of the two predictors (least squares, clipped to [0, 1])."""
    out = []
    for e1, e2 in zip(E1, E2):
        d = e1 - e2
        a = np.concatenate([[0.0], np.cumsum(np.sum(-d * e2, 1))])
        q = np.concatenate([[0.0], np.cumsum(np.sum(d * d, 1))])
        r = np.arange(len(e1))
        lo = np.maximum(r - window, 0)
        A, B = a[r] - a[lo], q[r] - q[lo]
        lam = np.clip(np.divide(A, B, out=np.zeros_like(A), where=B > 0), 0, 1)[:, None]
        out.append(lam * e1 + (1 - lam) * e2)
    return out


def rmse(E):
    E = np.vstack(E)
    return float(np.sqrt(np.mean(np.sum(E ** 2, axis=1))))


def main() -> int:
    try:
        segs = segments()
    except FileNotFoundError as exc:
        print(f"nanodrone_rates_onestep.py: error: the flights are not here: {exc}",
              file=sys.stderr)
        return 3
    for T in TYPES:
        o = ORDERS[T]
        na, nb, nk = o
        trt = [t for t in TYPES if t != T]
        E = residuals([s for t in trt for s in segs[t]], [s for t in trt for s in segs[t]],
                      {"orders": o})
        acf = np.array([sum(np.sum(e[k:] * e[:-k], 0) for e in E) / sum(np.sum(e * e, 0)
                                                                         for e in E)
                        for k in range(1, 7)])
        n = sum(len(e) for e in E)
        print(f"fold {T}: rates equation error autocorrelation, lags 1..6 (wx / wy / wz; "
              f"2/sqrt(N) {2 / np.sqrt(n):.4f}):")
        for k, row in enumerate(acf, 1):
            print(f"  lag {k}: " + " / ".join(f"{v:+.3f}" for v in row))
        cands = {"delay1": {"orders": (na, nb + 1, 1)},
                 "lags6": {"orders": o, "rate_lags": 6}, "lags8": {"orders": o, "rate_lags": 8},
                 "nb6": {"orders": (na, 6, nk)}, "torque": {"orders": o, "torque": True},
                 "gyro": {"orders": o, "gyro": True}, "rotor_acc": {"orders": o, "rotor_acc": 1}}
        rows = {}
        for V in trt:
            train = [s for t in trt if t != V for s in segs[t]]
            base = rmse(residuals(train, segs[V], {"orders": o}))
            for name, c in cands.items():
                rows.setdefault(name, []).append(rmse(residuals(train, segs[V], c)) / base)
            for p in (3, 6):
                rows.setdefault(f"armax{p}", []).append(
                    rmse(armax(train, segs[V], {"orders": o}, p)) / base)
            E1 = residuals(train, segs[V], cands["delay1"])
            E2 = residuals(train, segs[V], {"orders": o})
            for w in (50, 100, 200, 400):
                rows.setdefault(f"mix {w}", []).append(rmse(mix(E1, E2, w)) / base)
            for lam in (1e-4, 1e-3, 1e-2):
                rows.setdefault(f"ridge {lam:g}", []).append(
                    rmse(residuals(train, segs[V], cands["delay1"], lam)) / base)
        print(f"  one-step rates RMSE over the raw ARX {o}, held out: {' / '.join(trt)}")
        for name, r in rows.items():
            r = np.asarray(r)
            print(f"  {name:12s} " + " / ".join(f"{100 * (v - 1):+6.2f} %" for v in r)
                  + f"   mean {100 * (r.mean() - 1):+6.2f} %"
                  + ("   (lower on every type)" if np.all(r < 1) else ""))
    print("per flight: R^2 of w(t+1) - w(t) on the torque combinations at t - L (and w(t)), "
          "L = 0 / 1 / 2")
    for f in nanodrone_files(None):
        ds = load_nanodrone(f)
        U, Y = ds.select(ds.inputs), ds.select(ds.outputs)
        r2 = []
        for L in (0, 1, 2):
            X, T = [], []
            for a, b in ds.segments:
                if b - a > 50:
                    F = physics_features(np.asarray(U[a:b], float), np.full(4, 3000.0))[0][:, 5:]
                    w = np.asarray(Y[a:b], float)[:, R]
                    tt = np.arange(6, b - a - 1)
                    X.append(np.c_[F[tt - L], w[tt], np.ones(len(tt))])
                    T.append(w[tt + 1] - w[tt])
            X, T = np.vstack(X), np.vstack(T)
            E = T - X @ np.linalg.lstsq(X, T, rcond=None)[0]
            r2.append(1 - np.sum(E ** 2) / np.sum((T - T.mean(0)) ** 2))
        print(f"  {f.name:34s} " + " / ".join(f"{v:.3f}" for v in r2)
              + f"   best L {int(np.argmax(r2))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
