"""The EMPS linear baseline's Jacobian (evaluate.lti_oe, session 18): the exact Jacobian of the
free run (``_simulate_jac``) against what the fit used before, scipy's forward differences
(``approx_derivative``, one free run per coefficient), on all of DATA_EMPS (24841 samples), in
the same process. Also the forward differences' largest error against the exact Jacobian,
relative to its largest entry: near the pole at 1 they are wrong, not only slower."""
from __future__ import annotations

import time

import numpy as np

from timing import best_of


def lti_jacobian() -> dict:
    from scipy.optimize._numdiff import approx_derivative

    from cdam_core.evaluate.lti_oe import _arx_init, _simulate, _simulate_jac
    from cdam_core.record.realdata.emps import load_emps
    d = load_emps("DATA_EMPS")
    u, y = d["vir"], d["qm"]
    out = {}
    for n in (2, 5):
        th = _arx_init(n, False, [(u, y)])
        exact = best_of(lambda: _simulate_jac(th, n, False, u, y[:20]), clock=time.process_time)
        fd = best_of(lambda: approx_derivative(lambda t: _simulate(t, n, False, u, y[:20]), th,
                                               method="2-point"), clock=time.process_time)
        J = _simulate_jac(th, n, False, u, y[:20])[1]
        Jf = approx_derivative(lambda t: _simulate(t, n, False, u, y[:20]), th, method="2-point")
        out[f"order_{n}"] = {"seconds": exact, "reference_seconds": fd, "ratio": fd / exact,
                             "fd_error": float(np.max(np.abs(Jf - J)) / np.max(np.abs(J)))}
    o = out["order_2"]
    return {"seconds": o["seconds"], "reference_seconds": o["reference_seconds"],
            "ratio": o["ratio"],
            "reference": "scipy approx_derivative, 2-point, one free run per coefficient",
            **out}


BENCHMARKS = {"lti_jacobian": lti_jacobian}

if __name__ == "__main__":
    print(lti_jacobian())
