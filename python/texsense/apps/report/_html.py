"""The report as one self-contained HTML file: tables as HTML tables, figures as embedded PNG."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path
from typing import TYPE_CHECKING

from texsense.apps.report._figures import (
    health_figure,
    maps_figure,
    series_figure,
    sides_figure,
)
from texsense.data.files import pyplot, write_text

if TYPE_CHECKING:
    from texsense.apps.report._content import ReportContent, Table

__all__ = ["write_html"]

_STYLE = """
body { font: 14px/1.45 system-ui, sans-serif; max-width: 980px; margin: 24px auto; color: #1d2430; }
h1 { font-size: 22px; } h2 { font-size: 17px; margin-top: 28px; }
table { border-collapse: collapse; margin: 6px 0; font-variant-numeric: tabular-nums; }
td, th { padding: 3px 10px; border-bottom: 1px solid #e5e7eb; text-align: right; }
td.l, th.l { text-align: left; } th { background: #f3f4f6; }
.note { color: #677189; font-size: 13px; } img { max-width: 100%; }
"""


def _table(t: Table) -> str:
    aligns = t.aligns()
    out = [f"<h2>{html.escape(t.title)}</h2><table>"]
    if any(t.columns):
        out.append(
            "<tr>"
            + "".join(
                f'<th class="{a}">{html.escape(c)}</th>'
                for c, a in zip(t.columns, aligns, strict=True)
            )
            + "</tr>"
        )
    for r in t.rows:
        out.append(
            "<tr>"
            + "".join(
                f'<td class="{a}">{html.escape(str(v))}</td>'
                for v, a in zip(r, aligns, strict=True)
            )
            + "</tr>"
        )
    out.append("</table>")
    if t.note:
        out.append(f'<p class="note">{html.escape(t.note)}</p>')
    return "\n".join(out)


def _png(fig: object) -> str:
    plt = pyplot()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)  # type: ignore[attr-defined]
    plt.close(fig)
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    return f'<img alt="figure" src="data:image/png;base64,{data}">'


def write_html(c: ReportContent, out: Path) -> Path:
    """Write the report to ``out`` (atomically)."""

    plt = pyplot()
    maps = plt.figure(figsize=(9.5, 5.5))
    maps_figure(maps, (0.0, 0.06, 1.0, 0.84), c)
    series = plt.figure(figsize=(9.5, 8), layout="constrained")
    series_figure(series, c)
    health = plt.figure(figsize=(9.5, 5.5))
    health_figure(health, (0.0, 0.02, 0.62, 0.93), c)
    if c.sides is not None:
        sides_figure(health.add_axes((0.68, 0.25, 0.28, 0.5)), c)
    parts = [
        f"<!doctype html><html lang='en'><head><meta charset='utf-8'><title>"
        f"{html.escape(c.title)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>{html.escape(c.title)}</h1>",
        _table(c.identity),
        _table(c.summary),
        "<h2>Maps</h2>" + _png(maps),
        "<h2>Over time</h2>" + _png(series),
        _table(c.regions),
        _table(c.events),
        "<h2>Sensor health" + (" and time per side" if c.sides else "") + "</h2>" + _png(health),
    ]
    if c.sides is not None:
        parts.append(_table(c.sides))
    parts += [_table(c.health), "</body></html>"]
    return write_text(out, "\n".join(parts))
