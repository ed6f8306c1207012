"""The batch's aggregate: per record, algorithm and section (the paper's model section), the
mean, sample standard deviation (ddof 1, as `cdam paper`'s and `cdam identify`'s summaries; 0
for one value), minimum and maximum of every numeric metric over the seeds and folds of the
tasks that completed, with the count of finite values; and the tasks that failed or were
cancelled, each with its error. NaN (a diverged free run) is left out of a metric's figures and
shows as a smaller count. ``write_report`` renders it as index.md and index.html
(``report.paper.index.write_index``); it computes nothing.
"""
from __future__ import annotations

import math
from pathlib import Path

__all__ = ["summarise_rows", "GROUP", "report_lines", "write_report"]

GROUP = ("record", "algorithm", "section")
# the row's own fields (graph.FIRST), never aggregated as metrics (but "seconds" is)
_FIELDS = {"task", "command", "record", "algorithm", "seed_index", "seed", "fold", "section",
           "model", "status", "error"}


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _stats(values: list) -> dict:
    v = [float(x) for x in values if _number(x) and math.isfinite(x)]
    if not v:
        return {"n": 0, "mean": None, "std": None, "min": None, "max": None}
    mean = math.fsum(v) / len(v)
    std = (math.sqrt(math.fsum((x - mean) ** 2 for x in v) / (len(v) - 1))
           if len(v) > 1 else 0.0)
    return {"n": len(v), "mean": mean, "std": std, "min": min(v), "max": max(v)}


def summarise_rows(rows: list[dict]) -> dict:
    """{"status": {ok, error, cancelled}, "groups": [{record, algorithm, section, tasks, ok,
    metrics: {name: {n, mean, std, min, max}}}], "failed": [{task, record, algorithm, seed,
    fold, section, status, error}]}; groups in order of first appearance (task order)."""
    groups: dict[tuple, list] = {}
    for r in rows:
        groups.setdefault(tuple(r.get(k) for k in GROUP), []).append(r)
    out = []
    for key, members in groups.items():
        ok = [r for r in members if r.get("status") == "ok"]
        names = []
        for r in ok:
            names += [k for k, v in r.items()
                      if k not in _FIELDS and _number(v) and k not in names]
        out.append({**dict(zip(GROUP, key)), "tasks": len(members), "ok": len(ok),
                    "metrics": {k: _stats([r.get(k) for r in ok]) for k in names}})
    failed = [{k: r.get(k) for k in ("task", "record", "algorithm", "seed", "fold", "section",
                                     "status", "error")}
              for r in rows if r.get("status") != "ok"]
    status = {s: sum(r.get("status") == s for r in rows) for s in ("ok", "error", "cancelled")}
    return {"status": status, "groups": out, "failed": failed}


def _fmt(v) -> str:
    return "-" if v is None else f"{v:.6g}"


def _name(record) -> str:
    if not record:
        return "-"
    parts = str(record).split(";")
    return Path(parts[0]).name if len(parts) == 1 else f"{len(parts)} records"


def report_lines(summary: dict, *, title: str, command: str, source: dict,
                 seconds: float | None = None, workers: str | None = None,
                 table: str = ".") -> list[str]:
    """The Markdown of the batch report: what ran, the failures, then per group a table of
    every metric (n, mean, std, min, max); ``table``: the batch's --out folder, relative to
    the report."""
    st = summary["status"]
    lines = [f"# {title}", "",
             f"`cdam batch`, command `{command}`: {sum(st.values())} task(s), {st['ok']} done, "
             f"{st['error']} failed, {st['cancelled']} cancelled"
             + (f", {seconds:.1f} s" if seconds is not None else "")
             + (f" on {workers}" if workers else "") + ".", "",
             "Each figure is over the seeds and folds of the group's completed tasks: mean, "
             "sample standard deviation (ddof 1), min, max and n, the count of finite values "
             "(a diverged free run gives NaN and is left out). Every row: "
             f"[results.parquet]({table}/results.parquet), [results.json]({table}/results.json).",
             "",
             "Spec:", "", "```json"]
    import json
    lines += json.dumps(source, indent=1).splitlines() + ["```", ""]
    if summary["failed"]:
        lines += ["## Failed or cancelled tasks", "", "| task | status | error |",
                  "|---|---|---|"]
        lines += [f"| {f['task']} | {f['status']} | "
                  f"{str(f['error'] or '').replace('|', '/')} |" for f in summary["failed"]]
        lines.append("")
    lines += ["## Groups", "", "| record | algorithm | section | tasks | done |",
              "|---|---|---|---|---|"]
    for g in summary["groups"]:
        lines.append(f"| {_name(g['record'])} | {g['algorithm'] or '-'} | {g['section'] or '-'} "
                     f"| {g['tasks']} | {g['ok']} |")
    lines.append("")
    for g in summary["groups"]:
        head = " / ".join(x for x in (_name(g["record"]), g["algorithm"], g["section"]) if x)
        lines += [f"### {head}", "", "| metric | n | mean | std | min | max |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {k} | {s['n']} | {_fmt(s['mean'])} | {_fmt(s['std'])} | "
                  f"{_fmt(s['min'])} | {_fmt(s['max'])} |" for k, s in g["metrics"].items()]
        lines.append("")
    return lines


def write_report(folder, summary: dict, **kw) -> tuple[Path, Path]:
    """index.md and index.html of :func:`report_lines` in ``folder``; returns their paths."""
    from cdam_core.report.paper.index import write_index
    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    return write_index(d, report_lines(summary, **kw), kw["title"])
