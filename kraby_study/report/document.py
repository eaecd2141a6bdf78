"""A report page as a list of blocks, written out as Markdown and as HTML.

Both outputs come from the same blocks, so ``index.md`` and ``index.html`` always show the same
figures, tables and links (all relative to the page).
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

import pandas as pd


@dataclass(frozen=True)
class Heading:
    """A section title; level 1 is the page title."""

    text: str
    level: int = 2


@dataclass(frozen=True)
class Text:
    """A paragraph of plain text."""

    text: str


@dataclass(frozen=True)
class Image:
    """A figure (or animation) shown inline, with a short title and a caption."""

    path: str
    title: str
    caption: str


@dataclass(frozen=True)
class Table:
    """A table of preformatted cells; ``marks`` highlight rows in HTML: "best", "equivalent"
    (a sweep's answers), "tie" (a search front's trials admitted beside the best) or ""."""

    header: list[str]
    rows: list[list[str]]
    marks: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class Items:
    """A bulleted list of plain-text items."""

    items: list[str]


@dataclass(frozen=True)
class Links:
    """A line of links: (label, relative path)."""

    label: str
    links: list[tuple[str, str]]


Block = Heading | Text | Image | Table | Items | Links


def _href(path: str) -> str:
    return quote(path, safe="/.-_~")


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured Markdown table (numbers right-aligned, text left-aligned)."""
    def numeric(column: int) -> bool:
        cells = [row[column] for row in rows if row[column] not in ("", "-")]
        return bool(cells) and all(_looks_numeric(cell) for cell in cells)

    align = ["---:" if numeric(i) else ":---" for i in range(len(header))]
    lines = ["| " + " | ".join(_md_cell(h) for h in header) + " |", "|" + "|".join(align) + "|"]
    lines += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _looks_numeric(cell: str) -> bool:
    head = cell.split(" ")[0].replace("\u2212", "-").replace(",", "")
    try:
        float(head)
    except ValueError:
        return False
    return True


def to_markdown(blocks: Sequence[Block]) -> str:
    """The page as Markdown."""
    parts: list[str] = []
    for block in blocks:
        if isinstance(block, Heading):
            parts.append("#" * block.level + " " + block.text)
        elif isinstance(block, Text):
            parts.append(block.text)
        elif isinstance(block, Image):
            parts.append(f"![{block.title}]({_href(block.path)})\n\n*{block.caption}*")
        elif isinstance(block, Table):
            parts.append(markdown_table(block.header, block.rows))
        elif isinstance(block, Items):
            parts.append("\n".join(f"- {item}" for item in block.items))
        elif isinstance(block, Links):
            links = " · ".join(f"[{label}]({_href(path)})" for label, path in block.links)
            parts.append(f"{block.label}: {links}")
    return "\n\n".join(parts) + "\n"


STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; max-width: 1100px;
       margin: 2em auto; padding: 0 1em; color: #222; line-height: 1.45; }
h1, h2, h3 { line-height: 1.2; }
h2 { border-bottom: 1px solid #ddd; padding-bottom: .2em; margin-top: 2em; }
figure { margin: 1.2em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { color: #555; font-size: .92em; }
table { border-collapse: collapse; margin: 1em 0; font-size: .92em; }
th, td { border: 1px solid #ddd; padding: .3em .6em; }
th { background: #f5f5f5; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
tr.best td { background: #fbe3e0; font-weight: 600; }
tr.tie td, tr.equivalent td { background: #fdf3f2; }
"""


def _html_table(block: Table) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in block.header)
    body = []
    for index, row in enumerate(block.rows):
        mark = block.marks[index] if index < len(block.marks) else ""
        cells = "".join(
            f'<td class="num">{html.escape(c)}</td>' if _looks_numeric(c)
            else f"<td>{html.escape(c)}</td>" for c in row)
        body.append(f'<tr class="{mark}">{cells}</tr>' if mark else f"<tr>{cells}</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def to_html(blocks: Sequence[Block], title: str) -> str:
    """The page as a self-contained HTML document (figures linked, not embedded)."""
    parts = [f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
             f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>"]
    for block in blocks:
        if isinstance(block, Heading):
            parts.append(f"<h{block.level}>{html.escape(block.text)}</h{block.level}>")
        elif isinstance(block, Text):
            parts.append(f"<p>{html.escape(block.text)}</p>")
        elif isinstance(block, Image):
            parts.append(f'<figure><a href="{_href(block.path)}"><img src="{_href(block.path)}" '
                         f'alt="{html.escape(block.title)}"></a>'
                         f"<figcaption>{html.escape(block.caption)}</figcaption></figure>")
        elif isinstance(block, Table):
            parts.append(_html_table(block))
        elif isinstance(block, Items):
            items = "".join(f"<li>{html.escape(item)}</li>" for item in block.items)
            parts.append(f"<ul>{items}</ul>")
        elif isinstance(block, Links):
            links = " · ".join(f'<a href="{_href(path)}">{html.escape(label)}</a>'
                               for label, path in block.links)
            parts.append(f"<p>{html.escape(block.label)}: {links}</p>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


CSV_DIGITS = 6
"""Significant digits of every float the report's CSV files hold."""


def write_csvs(folder: Path, frames: Sequence[tuple[str, pd.DataFrame]]) -> list[Path]:
    """Write named tables as CSV files in a folder, floats to
    [`CSV_DIGITS`][kraby_study.report.document.CSV_DIGITS] significant digits; returns their
    paths."""
    paths = []
    for name, frame in frames:
        path = folder / name
        frame.to_csv(path, index=False, float_format=f"%.{CSV_DIGITS}g")
        paths.append(path)
    return paths
