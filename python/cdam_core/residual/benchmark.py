"""The residual loop's models scored under a simulation protocol on a test record.

The declared fit and the final (augmented) fit of a :class:`~cdam_core.residual.selection.
Selection` become ``greybox`` models and are simulated open loop on the test record from its
first ``n_init`` outputs (:func:`cdam_core.evaluate.simulation.simulation_score`).
"""
from __future__ import annotations

import numpy as np

from cdam_core.evaluate.simulation import simulation_score
from cdam_core.models.greybox.augmented import GreyBox

__all__ = ["greybox_of", "protocol_scores"]


def greybox_of(fitted, dt: float) -> GreyBox:
    """The ``greybox`` model of an IDIM fit (the filter and external columns it used)."""
    filt = fitted.signals.get("filter")
    extra = [e.column for e in fitted.effects if getattr(e, "column", "")]
    cut = None if filt is None else (dict(filt.per_signal) if getattr(filt, "per_signal", ())
                                     else filt.cutoff_hz)
    return GreyBox.from_fit(fitted, dt=dt, cutoff_hz=cut,
                            filter_order=4 if filt is None else filt.order, extra_columns=extra)


def protocol_scores(sel, test: dict, n_init: int, scale: float = 1.0) -> dict:
    """``{"declared": SimulationScore, "final": SimulationScore}`` on the test record.

    ``test`` maps the model's signal names (its inputs, positions and any external-force
    column) to arrays, plus ``t``; the test record must be sampled like the training record.
    """
    t = np.asarray(test["t"], dtype=float)
    dt = float(np.mean(np.diff(t)))
    out = {}
    for label, fitted in (("declared", sel.declared), ("final", sel.final)):
        g = greybox_of(fitted, dt)
        m = fitted.model
        missing = [c for c in list(m.inputs) + list(g.extra_columns) + list(m.positions)
                   if c not in test]
        if missing:
            raise ValueError(f"test: missing signal(s) {', '.join(missing)}")
        U = np.column_stack([test[c] for c in list(m.inputs) + list(g.extra_columns)])
        Y = np.column_stack([test[p] for p in m.positions])
        out[label] = simulation_score(g, U, Y, n_init, scale)
    return out
