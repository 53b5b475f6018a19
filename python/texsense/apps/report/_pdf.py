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
#: Characters per line of the monospaced tables.
WIDTH = 108
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


def _text_page(
    pdf: Any,
    plt: Any,
    lines: list[tuple[str, str]],
    header: str,
    fig: Any = None,
    top: float = _TOP,
) -> None:
    """Lines of tables from ``top`` down (on ``fig``, a page with a figure above, or a new
    page)."""
    fig = plt.figure(figsize=A4) if fig is None else fig
    fig.text(0.06, 0.975, header, fontsize=SMALL, color="#677189")
    y = top
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
    """The identity and the summary, then the maps as large as the rest of the page allows."""
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
    maps_figure(fig, (0.02, _BOTTOM, 0.96, max(y - _BOTTOM, 0.2)), c)
    pdf.savefig(fig)
    plt.close(fig)


#: The lowest line of a page (figure fraction), and the top of the tables under the health map.
_BOTTOM, _UNDER_HEALTH = 0.035, 0.56


def write_pdf(c: ReportContent, out: Path) -> Path:
    """Write the report's pages to ``out`` (atomically): the recording and its maps; the
    statistics over time; sensor health (and a bed's time per side) with the tables under it,
    running on as many pages as they need."""
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
        health_figure(fig, (0.02, _UNDER_HEALTH + 0.01, 0.62 if c.sides else 0.96, 0.38), c)
        if c.sides is not None:
            sides_figure(fig.add_axes((0.72, _UNDER_HEALTH + 0.08, 0.24, 0.24)), c)
        lines: list[tuple[str, str]] = []
        for table in (c.regions, c.events, c.sides, c.health):
            if table is not None:
                lines += table_lines(table)
        pages = _paginate(lines, _UNDER_HEALTH - _BOTTOM, _TOP - _BOTTOM)
        _text_page(pdf, plt, pages[0], header, fig, top=_UNDER_HEALTH)
        for more in pages[1:]:
            _text_page(pdf, plt, more, header)
    return out


def _paginate(
    lines: list[tuple[str, str]], first: float, height: float
) -> list[list[tuple[str, str]]]:
    """The lines split into pages: the first ``first`` high (figure fraction), the others
    ``height``; a title takes its extra space, and no page starts or ends with blank lines (a
    page of nothing but the blank line after the last table was once written)."""
    while lines and not lines[-1][1]:
        lines = lines[:-1]
    pages: list[list[tuple[str, str]]] = [[]]
    room = first
    # the title and head of the table being written, repeated where it runs on
    title, head = "", list[tuple[str, str]]()
    for k, (style, text) in enumerate(lines):
        need = _LINE + (0.006 if style == "title" else 0.0)
        # a table's title, head and first row stay together (no title alone at a page's foot)
        keep = 3 * _LINE if style == "title" and len(lines) - k > 1 else 0.0
        if need + keep > room and (pages[-1] or len(pages) == 1):
            pages.append([])
            room = height
            if style in ("row", "note") and text and title:
                pages[-1] = [("title", f"{title} (continued)"), *head]
                room -= _LINE + 0.006 + _LINE * len(head)
        if not pages[-1] and not text:
            continue
        if style == "title":
            title, head = text, []
        elif style == "head":
            head.append((style, text))
        pages[-1].append((style, text))
        room -= need
    return pages
