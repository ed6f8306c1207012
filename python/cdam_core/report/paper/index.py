"""index.md and index.html of ``cdam paper`` (the HTML rendered by Python-Markdown)."""
from __future__ import annotations

import html
from pathlib import Path

import markdown

from cdam_core.base.jsonio import write_text_atomic

__all__ = ["write_index", "markdown_to_html"]


def markdown_to_html(lines: list[str], title: str) -> str:
    """A standalone HTML page of the Markdown lines (tables through the ``tables`` extension)."""
    body = markdown.markdown("\n".join(lines), extensions=["tables"])
    style = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
             "table{border-collapse:collapse;margin:0.5em 0;font-size:0.9em}"
             "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}"
             "td:first-child,th:first-child{text-align:left}img{max-width:100%}")
    return (f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{html.escape(title)}"
            f"</title><style>{style}</style></head><body>\n" + body + "\n</body></html>\n")


def write_index(directory: Path, lines: list[str], title: str) -> tuple[Path, Path]:
    """Write index.md and index.html; returns their paths."""
    d = Path(directory)
    md, page = d / "index.md", d / "index.html"
    write_text_atomic(md, "\n".join(lines) + "\n")
    write_text_atomic(page, markdown_to_html(lines, title))
    return md, page
