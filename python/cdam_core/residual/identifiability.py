"""Is the measured deflection of a flexible joint a cable's deflection?

A cable deflects by d = tau_l / Ks, and the link equation makes tau_l = I q'' + Dl q' + G sin q:
the deflection follows the link's *acceleration*. A timing skew s between the motor and the
link encoders shows as d = s q' (proportional to velocity), and a cable stiffer than the
encoders resolve leaves only noise; in both cases the flexible model is not identifiable and
its least-squares fit returns numbers without meaning. The check regresses the measured
motor-minus-link angle on q'', q', sin q and a constant (``statsmodels`` OLS with Newey-West
standard errors, lags from the residual's correlation time): the acceleration term must be
positive (I / Ks), significant at level ``alpha``, and carry more variance than the encoders'
noise leaves in the filtered deflection (``noise_var``: the sum over both encoders of their
white-noise density times their filter's cut-off). A large share proportional to velocity is
reported (a skew, or link damping: the two look alike here).
"""
from __future__ import annotations

import numpy as np

from cdam_core.residual import diagnostics as dg

__all__ = ["deflection_check"]


def deflection_check(sig: dict, trim: int, noise_var: float = 0.0, alpha: float = 0.01) -> dict:
    """``{"identifiable": bool, "p_value", "t_statistic", "acceleration_share", ...}`` for the
    prepared signals of a flexible joint (``theta_m``, ``q`` and their derivatives)."""
    import statsmodels.api as sm   # here, not at import: about 0.5 s that other models never need
    n = np.asarray(sig["t"]).size
    keep = slice(trim, n - trim)
    d = (np.asarray(sig["theta_m"], dtype=float) - np.asarray(sig["q"], dtype=float))[keep]
    X = np.column_stack([np.asarray(sig["q_dd"], dtype=float)[keep],
                         np.asarray(sig["q_d"], dtype=float)[keep],
                         np.sin(np.asarray(sig["q"], dtype=float)[keep]), np.ones(d.size)])
    scale = np.where(np.std(X, axis=0) > 0, np.std(X, axis=0), 1.0)
    scale[-1] = 1.0
    ols = sm.OLS(d, X / scale).fit()
    tau = dg.effective_sample_size(ols.resid)["tau_int"]
    lags = int(max(1, min(np.ceil(2 * tau), d.size // 4)))
    hac = sm.OLS(d, X / scale).fit(cov_type="HAC", cov_kwds={"maxlags": lags})
    t_acc, p_acc = float(hac.tvalues[0]), float(hac.pvalues[0])
    contrib = hac.params[0] * X[:, 0] / scale[0]
    share = float(np.var(contrib) / np.var(d)) if np.var(d) > 0 else 0.0
    vel = hac.params[1] * X[:, 1] / scale[1]
    acc_var = float(np.var(contrib))
    return {"identifiable": bool(p_acc < alpha and hac.params[0] > 0 and acc_var > noise_var),
            "deflection_signal_variance": acc_var, "encoder_noise_variance": float(noise_var),
            "p_value": p_acc, "t_statistic": t_acc, "acceleration_share": share,
            "velocity_share": float(np.var(vel) / np.var(d)) if np.var(d) > 0 else 0.0,
            "newey_west_lags": lags,
            "velocity_coefficient_s": float(hac.params[1] / scale[1]),   # a skew or Dl / Ks
            "rule": "motor-minus-link angle regressed on q'', q', sin q, 1 (OLS, Newey-West "
                    f"errors): the q'' term (I / Ks > 0) significant at {alpha:g} and above "
                    "the encoders' filtered noise"}
