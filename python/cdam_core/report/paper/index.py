"""index.md and index.html of ``cdam paper`` (the HTML rendered by Python-Markdown)."""
from __future__ import annotations

from pathlib import Path

from cdam_core.report.page import markdown_to_html, write_page

__all__ = ["write_index", "markdown_to_html"]


def write_index(directory: Path, lines: list[str], title: str) -> tuple[Path, Path]:
    """Write index.md and index.html; returns their paths."""
    md = write_page(Path(directory) / "index.md", lines, title)
    return md, md.with_suffix(".html")
