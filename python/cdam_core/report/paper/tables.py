"""The paper's tables beside ours: Table 2 (test), Table 3 (validation), fitness and run time.

:func:`paper_tables` turns a section result (see :mod:`.runner`) into plain numbers (what
results.json stores under "tables"); :func:`markdown_tables` renders exactly those numbers, four
decimals for r and fitness, so the Markdown shows the JSON values rounded.

"Reaches the paper" for an output: for every algorithm, our mean r over seeds is at least the
paper's published r of that algorithm.
"""
from __future__ import annotations

from cdam_core.report.paper.published import FITNESS, LABEL, OUTPUTS, RUN_TIME_S, TABLE2, TABLE3

__all__ = ["paper_tables", "markdown_tables", "fmt_pm", "reach_summary", "mode_label"]

_PUBLISHED = {"test": TABLE2, "validation": TABLE3}
_TABLE_NAME = {"test": "Table 2 (test: last half of each experiment)",
               "validation": "Table 3 (validation records)"}


def mode_label(mode: str) -> str:
    """'one_step' -> 'one-step', 'free_run' -> 'free-run', 'k_step_0.1s' -> 'k-step 0.1 s'."""
    if mode.startswith("k_step_") and mode.endswith("s"):
        return f"k-step {mode[len('k_step_'):-1]} s"
    return mode.replace("_", "-")


def fmt_pm(mean, std, digits=4) -> str:
    """'mean ± std' with ``digits`` decimals; 'n/a' when the mean is missing."""
    if mean is None:
        return "n/a"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def paper_tables(section: dict) -> dict:
    """{"r": {record: {mode: {output: {algo: {mean, std, paper, reached}}, "reached": ...}}},
    "fitness": {algo: {mean, std, paper}}, "run_time_s": {algo: {mean, std, paper}}}."""
    summary = section["summary"]
    algos = list(summary)
    out = {"r": {}, "fitness": {}, "run_time_s": {}, "optimise_time_s": {}}
    first = summary[algos[0]]["records"]
    for rec, modes in first.items():
        out["r"][rec] = {}
        for mode in modes:
            rows = {}
            for o in OUTPUTS:
                row = {}
                for a in algos:
                    agg = summary[a]["records"][rec][mode][o]["r"]
                    paper = _PUBLISHED[rec][o].get(a)
                    reached = (None if paper is None or agg["mean"] is None
                               else bool(round(agg["mean"], 4) >= paper))
                    row[a] = {"mean": agg["mean"], "std": agg["std"], "paper": paper,
                              "reached": reached}
                flags = [v["reached"] for v in row.values() if v["reached"] is not None]
                row["all_reached"] = bool(flags) and all(flags)
                rows[o] = row
            out["r"][rec][mode] = rows
    for a in algos:
        s = summary[a]
        out["fitness"][a] = {**s["fitness"], "paper": FITNESS.get(a)}
        out["run_time_s"][a] = {**s["seconds"], "paper": RUN_TIME_S.get(a)}
        out["optimise_time_s"][a] = dict(s["optimise_seconds"])
    return out


def _num(x, digits):
    return "n/a" if x is None else f"{x:.{digits}f}"


def reach_summary(tables_by_section: dict) -> dict:
    """{output: {"section/record/mode": all_reached}} across sections."""
    res = {o: {} for o in OUTPUTS}
    for sec, t in tables_by_section.items():
        for rec, modes in t["r"].items():
            for mode, rows in modes.items():
                for o in OUTPUTS:
                    res[o][f"{sec}/{rec}/{mode}"] = rows[o]["all_reached"]
    return res


def markdown_tables(tables: dict, *, title_prefix: str = "") -> list[str]:
    """Markdown lines: fitness and run time beside the paper's, then Table 2 and 3 per mode."""
    algos = list(tables["fitness"])
    lines = [f"### {title_prefix}Final fitness and run time (mean ± std over seeds)", "",
             "| algorithm | fitness (ours) | fitness (paper) | run time s (ours) | "
             "run time s (paper) | of which optimiser s |", "|---|---|---|---|---|---|"]
    for a in algos:
        f, rt, ot = tables["fitness"][a], tables["run_time_s"][a], tables["optimise_time_s"][a]
        lines.append(f"| {LABEL[a]} | {fmt_pm(f['mean'], f['std'])} | {_num(f['paper'], 4)} | "
                     f"{fmt_pm(rt['mean'], rt['std'], 2)} | {_num(rt['paper'], 1)} | "
                     f"{fmt_pm(ot['mean'], ot['std'], 2)} |")
    for rec, modes in tables["r"].items():
        for mode, rows in modes.items():
            lines += ["", f"### {title_prefix}{_TABLE_NAME[rec]}, {mode_label(mode)}: "
                          "Pearson r", "",
                      "| output | " + " | ".join(f"{LABEL[a]} (ours) | {LABEL[a]} (paper)"
                                                  for a in algos) + " | reaches the paper |",
                      "|---" * (2 * len(algos) + 2) + "|"]
            for o in OUTPUTS:
                row = rows[o]
                cells = []
                for a in algos:
                    v = row[a]
                    cells += [fmt_pm(v["mean"], v["std"]), _num(v['paper'], 4)]
                n_ok = sum(1 for a in algos if row[a]["reached"])
                verdict = "yes" if row["all_reached"] else f"no ({n_ok}/{len(algos)})"
                lines.append(f"| {o} | " + " | ".join(cells) + f" | {verdict} |")
    return lines
