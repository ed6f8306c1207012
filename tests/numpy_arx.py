"""An independent multi-output ARX in plain numpy (least squares and its own regressor and
simulation loops), the reference the ARX baselines of the AR.Drone tests are checked against."""
import numpy as np


def arx_free_run(U, Y, Ut, Yt, na=4, nb=4, nk=1):
    """Multi-output ARX(na, nb, nk) on the raw inputs: every output regressed on the last na
    values of all outputs and u(t-nk) .. u(t-nk-nb+1) of all inputs plus a constant, fitted by
    least squares on (U, Y); simulated on (Ut, Yt) from the first t0 measured outputs. Returns
    the (len(Ut), m) prediction, the first t0 rows measured."""
    t0 = max(na, nk + nb - 1)

    def row(Uc, Yc, t):
        return np.concatenate([Yc[t - j] for j in range(1, na + 1)]
                              + [Uc[t - nk - j] for j in range(nb)] + [[1.0]])

    A = np.array([row(U, Y, t) for t in range(t0, len(U))])
    W = np.linalg.lstsq(A, Y[t0:], rcond=None)[0]
    P = Yt.copy()
    for t in range(t0, len(Ut)):
        P[t] = row(Ut, P, t) @ W
    return P
