"""The residual monitor's report (`cdam monitor MODEL RECORD --report DIR`): per output the
residual statistics and thresholds of the model file's ``monitor`` section, the alarms, and one
figure: the normalised one-step residual with its EWMA against the EWMA limit, and the two
CUSUMs against their threshold, alarms marked. ``index.md``, ``index.html``, ``monitor.png``."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from cdam_core.base.jsonio import atomic_target
from cdam_core.record.dataset import STANDARD_UNITS
from cdam_core.report.page import figure, write_page

__all__ = ["write_monitor_report"]


def write_monitor_report(folder, t, outputs: list[str], result, section: dict, alarms: list,
                         title: str, source: str = "", units: dict | None = None) -> Path:
    """Write the report into ``folder``; returns the path of ``index.md``.

    ``t`` (N,) times in s; ``result`` the ``evaluate.monitor.MonitorResult`` of the record;
    ``alarms`` the command's alarm dicts (``t``, ``output``, ``statistics``); ``units`` the
    outputs' units (the dataset format's where not given)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    units = {**STANDARD_UNITS, **(units or {})}
    t = np.asarray(t, float)
    _figure(folder / "monitor.png", t, outputs, result, section)
    lines = [f"# {title}", ""]
    if source:
        lines += [f"Data: {source}", ""]
    lines += [f"{int(result.valid.sum())} of {len(t)} rows monitored (rows with a one-step "
              f"prediction), {len(alarms)} alarm(s). Residual z = (y - y_hat - mean) / std with "
              "the training record's mean and std; EWMA with lambda "
              f"{section['lambda']:.4g}; two-sided CUSUM with reference k {section['k']:.4g} "
              "(in residual standard deviations); each statistic restarts at 0 after an alarm "
              "of its output.", "",
              "| output | residual mean | residual std | CUSUM threshold h [std] | "
              "EWMA limit [std] | alarms | first alarm [s] |", "|---|---|---|---|---|---|---|"]
    watched = section.get("watched") or [1] * len(outputs)   # absent: every output
    for c, name in enumerate(outputs):
        u = units.get(name, "output units")
        mine = [a["t"] for a in alarms if a["output"] == name]
        first = f"{mine[0]:.4f}" if mine else "-"
        if not watched[c]:
            first = "not watched"
        lines.append(f"| {name} | {section['mean'][c]:.4g} {u} | {section['std'][c]:.4g} {u} | "
                     f"{section['h'][c]:.4g} | {section['ewma_limit'][c]:.4g} | {len(mine)} | "
                     f"{first} |")
    lines += [""] + figure("monitor.png", "monitor",
                           "Figure 1: per output, top: the normalised one-step residual z (grey) "
                           "and its EWMA (blue) against the EWMA limit (dashed); bottom: the "
                           "upper (red) and lower (green) CUSUM against the threshold h "
                           "(dashed); alarms of that output as vertical lines. Statistics in "
                           "residual standard deviations, time in s.")
    if alarms:
        lines += ["## Alarms", "", "| t [s] | output | statistics |", "|---|---|---|"]
        lines += [f"| {a['t']:.4f} | {a['output']} | {'+'.join(a['statistics'])} |"
                  for a in alarms[:200]]
        if len(alarms) > 200:
            lines += ["", f"... {len(alarms) - 200} more (--json has them all)."]
        lines.append("")
    return write_page(folder / "index.md", lines, title)


def _figure(path: Path, t, outputs, res, section) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    k = len(outputs)
    fig, axes = plt.subplots(2 * k, 1, figsize=(7.5, 2.9 * k + 0.6), squeeze=False, sharex=True)
    v = res.valid
    for c, name in enumerate(outputs):
        top, bottom = axes[2 * c, 0], axes[2 * c + 1, 0]
        top.plot(t[v], res.z[v, c], color="0.6", lw=0.5, label="z")
        top.plot(t[v], res.ewma[v, c], color="tab:blue", lw=1.0, label="EWMA")
        L, h = float(section["ewma_limit"][c]), float(section["h"][c])
        for s in (L, -L):
            top.axhline(s, color="tab:blue", ls="--", lw=0.8)
        bottom.plot(t[v], res.up[v, c], color="tab:red", lw=1.0, label="CUSUM up")
        bottom.plot(t[v], res.down[v, c], color="tab:green", lw=1.0, label="CUSUM down")
        bottom.axhline(h, color="k", ls="--", lw=0.8)
        hit = np.flatnonzero(res.flags[:, c])
        for ax in (top, bottom):
            for j in hit[:200]:
                ax.axvline(t[j], color="tab:red", lw=0.6, alpha=0.6)
            ax.grid(True, alpha=0.3)
        top.set_ylabel(f"{name}: z, EWMA [std]", fontsize=8)
        bottom.set_ylabel(f"{name}: CUSUM [std]", fontsize=8)
        if c == 0:
            top.legend(loc="upper left", fontsize=7, ncol=2)
            bottom.legend(loc="upper left", fontsize=7, ncol=2)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    with atomic_target(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
