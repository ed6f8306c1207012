"""Every report as Markdown and as a standalone HTML page (rendered by Python-Markdown), so
that each opens in a browser with its figures; figures are captioned in italics under them."""
from __future__ import annotations

import html
from pathlib import Path

import markdown

from cdam_core.base.jsonio import write_text_atomic

__all__ = ["markdown_to_html", "write_page", "figure"]

_STYLE = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;padding:0 1em}"
          "table{border-collapse:collapse;margin:0.5em 0;font-size:0.9em}"
          "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}"
          "td:first-child,th:first-child{text-align:left}img{max-width:100%}"
          "p>em:only-child{color:#333}")


def markdown_to_html(lines: list[str], title: str) -> str:
    """A standalone HTML page of the Markdown lines (tables through the ``tables`` extension,
    fenced code through ``fenced_code``)."""
    body = markdown.markdown("\n".join(lines), extensions=["tables", "fenced_code"])
    return (f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{html.escape(title)}"
            f"</title><style>{_STYLE}</style></head><body>\n" + body + "\n</body></html>\n")


def write_page(md_path, lines: list[str], title: str) -> Path:
    """Write ``md_path`` (Markdown) and the same stem ``.html`` beside it; returns md_path."""
    md = Path(md_path)
    write_text_atomic(md, "\n".join(lines) + "\n")
    write_text_atomic(md.with_suffix(".html"), markdown_to_html(lines, title))
    return md


def figure(file: str, alt: str, caption: str) -> list[str]:
    """The Markdown lines of a figure and its caption (one paragraph in italics under it)."""
    return [f"![{alt}]({file})", "", f"*{caption}*", ""]
