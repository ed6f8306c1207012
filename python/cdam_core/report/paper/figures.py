"""Figures matching the paper's Figs. 8-15 (matplotlib, Agg backend).

- Figs. 8-10: raw and smoothed data at 1 kHz (quadrotor outputs and inputs from experiment
  (i); manipulator inputs and outputs from experiment (ii));
- Fig. 11: convergence of the initial-weight search, adaptation value 1 / (1 + MSE) of the best
  individual per iteration (mean over seeds, min-max band);
- Figs. 12-15: identified against actual, best-training-fitness seed of each algorithm, on the
  test record (12 quadrotor, 13 manipulator) and the validation record (14, 15), drawn from the
  saved prediction arrays; the record's segments are pooled, a dashed line marks the seam.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdam_core.base.metrics import adaptation_value
from cdam_core.base.jsonio import atomic_target
from cdam_core.record.dataset import STANDARD_UNITS
from cdam_core.report.paper.published import LABEL

__all__ = ["preprocessing_figure", "convergence_figure", "identified_figure"]

QUADROTOR = ("phi", "theta", "psi", "X", "Y", "Z")
MANIPULATOR = ("q1", "q2")
_DPI = 90


def _label(name: str) -> str:
    """An axis label with the channel's unit (the dataset format's SI units)."""
    return f"{name} [{STANDARD_UNITS.get(name, '-')}]"


def _finish(fig, path, top_inches=0.45, bottom_inches=0.5):
    """Fixed margins (cheaper than tight_layout, which draws the figure twice), save, close."""
    h = fig.get_figheight()
    fig.subplots_adjust(left=0.1, right=0.98, top=1 - top_inches / h,
                        bottom=bottom_inches / h, hspace=0.15 if len(fig.axes) > 2 else 0.3)
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=_DPI)
    import matplotlib.pyplot as plt
    plt.close(fig)


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def preprocessing_figure(t, raw, smooth, names, path: Path, title: str) -> None:
    """Raw (grey) and smoothed (colour) channels, one panel each (Figs. 8-10)."""
    plt = _plt()
    m = len(names)
    fig, axes = plt.subplots(m, 1, figsize=(8, 1.5 * m + 0.7), sharex=True, squeeze=False)
    for k, name in enumerate(names):
        ax = axes[k, 0]
        ax.plot(t, raw[:, k], color="0.65", lw=0.6, label="raw")
        ax.plot(t, smooth[:, k], color="C0", lw=0.9, label="smoothed")
        ax.set_ylabel(_label(name))
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=2)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title, fontsize=10)
    _finish(fig, path)


def convergence_figure(sections: dict, path: Path) -> None:
    """Fig. 11: one panel per section ({label: section result})."""
    plt = _plt()
    fig, axes = plt.subplots(1, len(sections), figsize=(5.5 * len(sections), 3.8), squeeze=False)
    for ax, (label, sec) in zip(axes[0], sections.items()):
        for algo, data in sec["algorithms"].items():
            curves = [r["curve_mse"] for r in data["runs"] if r["curve_mse"] is not None]
            if not curves:
                continue
            fit = adaptation_value(np.asarray(curves, dtype=np.float64))
            it = np.arange(fit.shape[1])
            ax.plot(it, fit.mean(axis=0), label=LABEL[algo])
            ax.fill_between(it, fit.min(axis=0), fit.max(axis=0), alpha=0.2)
        ax.set_xlabel("iteration [-]")
        ax.set_ylabel("adaptation value 1 / (1 + MSE) [-]")
        ax.set_title(f"{label}: best individual per iteration", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.subplots_adjust(left=0.07, right=0.99, top=0.9, bottom=0.14, wspace=0.2)
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=_DPI)
    plt.close(fig)


def identified_figure(measured, predicted: dict, outputs, names, rate, seams, path: Path,
                      title: str) -> None:
    """Identified ({algo: (N, m) array}) against actual (N, m) for the outputs ``names``."""
    plt = _plt()
    idx = [list(outputs).index(n) for n in names]
    x = np.arange(measured.shape[0]) / rate
    fig, axes = plt.subplots(len(idx), 1, figsize=(8, 1.6 * len(idx) + 0.8), sharex=True,
                             squeeze=False)
    for row, k in enumerate(idx):
        ax = axes[row, 0]
        ax.plot(x, measured[:, k], "k", lw=1.3, label="actual")
        for algo, P in predicted.items():
            ax.plot(x, P[:, k], lw=0.9, label=LABEL[algo])
        for s in seams:
            ax.axvline(s / rate, color="0.4", ls="--", lw=0.8)
        ax.set_ylabel(_label(outputs[k]))
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(loc="upper right", fontsize=7, ncol=len(predicted) + 1)
    axes[-1, 0].set_xlabel("time in the pooled record [s]; dashed: seam (i) | (ii)")
    fig.suptitle(title, fontsize=10)
    _finish(fig, path)
