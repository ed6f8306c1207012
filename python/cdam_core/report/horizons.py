"""Renders :class:`~cdam_core.evaluate.horizons.HorizonScores`: a Markdown table and the plot
of error against horizon (computes nothing)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdam_core.base.jsonio import write_text_atomic

__all__ = ["horizon_table", "write_horizon_report"]


def horizon_table(scores, at=None) -> str:
    """Markdown table: RMSE of each output for each predictor at the horizons ``at``."""
    hs = scores.horizons
    at = [h for h in (at or sorted({hs[0], hs[len(hs) // 2], hs[-1]})) if h in hs]
    head = "| predictor | h | " + " | ".join(scores.outputs) + " |"
    lines = [head, "|" + "---|" * (len(scores.outputs) + 2)]
    for name, R in scores.rmse.items():
        for h in at:
            row = R[hs.index(h)]
            lines.append(f"| {name} | {h} | " + " | ".join(f"{v:.4g}" for v in row) + " |")
    return "\n".join(lines)


def write_horizon_report(scores, folder, title: str, dt: float | None = None,
                         units: dict | None = None) -> Path:
    """``index.md`` and ``rmse_vs_horizon.png`` (one panel per output) in ``folder``."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    units = units or {}
    m = len(scores.outputs)
    fig, axes = plt.subplots(m, 1, figsize=(6.4, 2.2 * m + 0.6), squeeze=False, sharex=True)
    x = np.asarray(scores.horizons, dtype=float) * (dt if dt else 1.0)
    for j, (ax, o) in enumerate(zip(axes[:, 0], scores.outputs)):
        for name, R in scores.rmse.items():
            ax.plot(x, R[:, j], marker="." if len(x) < 60 else None, label=name)
        ax.set_ylabel(f"RMSE {o} [{units.get(o, 'output units')}]")
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="upper left", fontsize=8)
    axes[-1, 0].set_xlabel("horizon [s]" if dt else "horizon [samples]")
    fig.tight_layout()
    fig.savefig(folder / "rmse_vs_horizon.png", dpi=110)
    plt.close(fig)
    md = [f"# {title}", "", horizon_table(scores), "",
          "![RMSE against horizon](rmse_vs_horizon.png)", "",
          "*Figure: root-mean-square error of each output against the prediction horizon, for "
          "the model and the naive predictor y(t) = y(t - h), on the same rows.*", ""]
    write_text_atomic(folder / "index.md", "\n".join(md))
    return folder / "index.md"
