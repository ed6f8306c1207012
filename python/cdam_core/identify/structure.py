"""Structure of the linear part chosen on the training record only (never the test data)."""
from __future__ import annotations

from cdam_core.base.checks import as_2d
from cdam_core.base.metrics import mean_pearson
from cdam_core.models.arx import ArxModel

__all__ = ["select_structure"]


def select_structure(U, Y, *, decimations=(1,), orders=(2, 3, 4), delays=(0, 1),
                     features=("raw", "physics"), validation_fraction=0.2) -> dict:
    """Choose (decimation, narx, features) of an ARX model by free-run mean Pearson r on the
    last ``validation_fraction`` of the training record U, Y.

    Each decimation d keeps every d-th sample of U, Y (1: the record's own rate; the caller
    decimates the test record the same way); na = nb = each of ``orders``, nk each of
    ``delays``. Returns {"decimation", "narx", "features", "validation_r",
    "table": [(r, decimation, narx, features), ...] best first}.
    """
    U = as_2d(U, "U")
    Y = as_2d(Y, "Y")
    table = []
    for d in decimations:
        if int(d) < 1:
            raise ValueError(f"decimations: must be >= 1, got {d!r}")
        Ud, Yd = U[::int(d)], Y[::int(d)]
        n_fit = int(round(len(Ud) * (1 - validation_fraction)))
        for feat in features:
            for o in orders:
                for nk in delays:
                    model = ArxModel((o, o, nk), feat)
                    try:
                        model.fit(Ud[:n_fit], Yd[:n_fit])
                        v0 = n_fit - model.t0
                        P = model.predict(Ud[v0:], Yd[v0:], mode="free_run")
                    except ValueError:
                        continue
                    r = mean_pearson(Yd[n_fit:], P[model.t0:])
                    table.append((r, int(d), (o, o, nk), feat))
    if not table:
        raise ValueError("U, Y: no structure could be fitted (record too short?)")
    table.sort(key=lambda row: -row[0])
    r, d, narx, feat = table[0]
    return {"decimation": d, "narx": narx, "features": feat, "validation_r": r, "table": table}
