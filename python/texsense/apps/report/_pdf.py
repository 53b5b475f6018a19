"""The report as a PDF of A4 pages (matplotlib's PdfPages, fonts embedded as TrueType so that
every table is text a reader can select and copy)."""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import TYPE_CHECKING, Any

from texsense.apps.report._figures import (
    NORMAL,
    SMALL,
    health_figure,
    maps_figure,
    series_figure,
    sides_figure,
)
from texsense.data.files import atomic_path, pyplot

if TYPE_CHECKING:
    from texsense.apps.report._content import ReportContent, Table

__all__ = ["table_lines", "write_pdf"]

A4 = (8.27, 11.69)
#: Characters per line of the monospaced tables, lines per page.
WIDTH, LINES = 108, 78
_TOP, _LINE = 0.95, 0.0118  # figure fraction


def table_lines(table: Table, width: int = WIDTH) -> list[tuple[str, str]]:
    """A table as lines of monospaced text: (style, text), style ``title``, ``head``,
    ``row`` or ``note``. Columns are as wide as their widest cell; the last column wraps."""
    cols = len(table.columns)
    cells = [table.columns, *table.rows]
    widths = [max(len(str(r[k])) for r in cells) for k in range(cols)]
    fixed = sum(widths[:-1]) + 2 * (cols - 1)
    widths[-1] = max(12, min(widths[-1], width - fixed))
    aligns = table.aligns()

    def line(row: list[str]) -> list[str]:
        last = textwrap.wrap(str(row[-1]), widths[-1]) or [""]
        out = []
        for j, piece in enumerate(last):
            parts = [
                (str(v) if j == 0 else "").ljust(w)
                if a == "l"
                else (str(v) if j == 0 else "").rjust(w)
                for v, w, a in zip(row[:-1], widths[:-1], aligns[:-1], strict=True)
            ]
            parts.append(piece.ljust(widths[-1]) if aligns[-1] == "l" else piece.rjust(widths[-1]))
            out.append("  ".join(parts).rstrip())
        return out

    lines: list[tuple[str, str]] = [("title", table.title)]
    if any(table.columns):
        lines += [("head", t) for t in line(table.columns)]
    for r in table.rows:
        lines += [("row", t) for t in line(r)]
    if table.note:
        lines += [("note", t) for t in textwrap.wrap(table.note, width)]
    return [*lines, ("row", "")]


def _text_page(pdf: Any, plt: Any, lines: list[tuple[str, str]], header: str) -> None:
    fig = plt.figure(figsize=A4)
    fig.text(0.06, 0.975, header, fontsize=SMALL, color="#677189")
    y = _TOP
    for style, text in lines:
        if style == "title":
            fig.text(0.06, y - 0.004, text, fontsize=NORMAL + 1, weight="bold")
            y -= 0.006
        else:
            fig.text(
                0.06,
                y,
                text,
                fontsize=SMALL,
                family="DejaVu Sans Mono",
                weight="bold" if style == "head" else "normal",
                color="#555" if style == "note" else "black",
            )
        y -= _LINE
    pdf.savefig(fig)
    plt.close(fig)


def _first_page(pdf: Any, plt: Any, c: ReportContent) -> None:
    fig = plt.figure(figsize=A4)
    fig.text(0.06, 0.955, c.title, fontsize=14, weight="bold")
    lines = table_lines(c.identity, 100) + table_lines(c.summary, 100)
    y = 0.925
    for style, text in lines:
        if style == "title":
            fig.text(0.06, y, text, fontsize=NORMAL + 1, weight="bold")
            y -= 0.004
        else:
            fig.text(0.06, y, text, fontsize=SMALL, family="DejaVu Sans Mono")
        y -= _LINE
    maps_figure(fig, (0.02, 0.05, 0.96, max(0.25, y - 0.11)), c)
    pdf.savefig(fig)
    plt.close(fig)


def write_pdf(c: ReportContent, out: Path) -> Path:
    """Write the report's pages to ``out`` (atomically)."""
    from matplotlib.backends.backend_pdf import PdfPages

    plt = pyplot()
    header = f"{c.title}  ·  texsense"
    with atomic_path(out) as tmp, PdfPages(tmp, metadata={"Title": c.title}) as pdf:
        _first_page(pdf, plt, c)
        fig = plt.figure(figsize=A4, layout="constrained")
        series_figure(fig, c)
        pdf.savefig(fig)
        plt.close(fig)
        fig = plt.figure(figsize=A4)
        ax = fig.add_axes((0.1, 0.45 if c.sides else 0.2, 0.75, 0.5))
        health_figure(ax, c)
        if c.sides is not None:
            sides_figure(fig.add_axes((0.2, 0.08, 0.6, 0.25)), c)
        pdf.savefig(fig)
        plt.close(fig)
        lines: list[tuple[str, str]] = []
        for table in (c.regions, c.events, c.sides, c.health):
            if table is not None:
                lines += table_lines(table)
        for start in range(0, len(lines), LINES):
            _text_page(pdf, plt, lines[start : start + LINES], header)
    return out
