"""A short report for commands whose result is a few numbers (``cdam merge``, ``cdam demo``):
``index.md`` (and ``index.html``) with the title, the source, the lines the command printed and an explanation, and
``results.json`` (computes nothing)."""
from __future__ import annotations

import json
from pathlib import Path

from cdam_core.base.jsonio import plain, write_text_atomic
from cdam_core.report.page import write_page

__all__ = ["write_summary_report"]


def write_summary_report(folder, title: str, lines: list[str], results: dict, *,
                         source: str | None = None, notes: str | None = None) -> Path:
    """Write ``folder/index.md``, ``index.html`` and ``results.json``; returns the index path."""
    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    md = [f"# {title}", ""]
    if source:
        md += [f"Source: {source}", ""]
    md += ["```", *lines, "```", ""]
    if notes:
        md += [notes, ""]
    md += ["All numbers: [results.json](results.json)."]
    write_text_atomic(d / "results.json", json.dumps(plain(results), indent=1,
                                                     allow_nan=False) + "\n")
    return write_page(d / "index.md", md, title)
