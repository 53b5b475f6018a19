"""Tables on the console: columns as wide as their widest cell, names in natural order, and a
confusion matrix that stays readable with long class names and counts of any size.

Examples
--------
>>> sorted(["S10", "S2", "S1", "S11"], key=natural_key)
['S1', 'S2', 'S10', 'S11']
>>> print("\\n".join(text_table(["subject", "accuracy"], [["S1", "98.2%"], ["S10", "7.5%"]])))
subject  accuracy
S1          98.2%
S10          7.5%
>>> print("\\n".join(confusion_lines(["supine", "left"], [[1234, 5], [0, 987]])))
        supine    left
supine    1234       5
  left       0     987
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["confusion_lines", "natural_key", "text_table"]


def natural_key(text: Any) -> tuple[Any, ...]:
    """A sort key that orders the numbers in names by value: S1, S2, ..., S10."""
    return tuple(
        (1, int(part), "") if part.isdigit() else (0, 0, part.lower())
        for part in re.split(r"(\d+)", str(text))
        if part
    )


def text_table(columns: Sequence[str], rows: Sequence[Sequence[Any]], align: str = "") -> list[str]:
    """Lines of a table: the first column left-aligned, the others right-aligned (or as
    ``align`` says, one ``l`` / ``r`` per column), two spaces between columns."""
    cells = [[str(c) for c in columns], *[[str(c) for c in r] for r in rows]]
    widths = [max(len(r[k]) for r in cells) for k in range(len(columns))]
    align = align or "l" + "r" * (len(columns) - 1)
    return [
        "  ".join(
            v.ljust(w) if a == "l" else v.rjust(w) for v, w, a in zip(r, widths, align, strict=True)
        ).rstrip()
        for r in cells
    ]


def confusion_lines(
    labels: Sequence[Any], matrix: Any, names: Mapping[str, str] | None = None, short: int = 8
) -> list[str]:
    """A confusion matrix (rows true, columns predicted). Columns are headed by the label
    when it has at most ``short`` characters, else by a number ``c1``, ``c2``, ...; rows
    name the class in full (``names`` maps labels to names, e.g. PMD's posture numbers),
    and a legend follows when a code or name differs from the label."""
    m = np.asarray(matrix)
    labels = [str(v) for v in labels]
    codes = [v if len(v) <= short else f"c{k + 1}" for k, v in enumerate(labels)]
    full = [str(names.get(v, v)) if names else v for v in labels]
    width = max(max(len(c) for c in codes), len(str(int(m.max(initial=0))))) + 2
    row_names = [f"{c} {f}" if f != c else c for c, f in zip(codes, full, strict=True)]
    row_w = min(max(len(r) for r in row_names), 40)
    lines = [" " * row_w + "".join(c.rjust(width) for c in codes)]
    for name, row in zip(row_names, m, strict=True):
        name = name if len(name) <= row_w else name[: row_w - 1] + "…"
        lines.append(name.rjust(row_w) + "".join(str(int(v)).rjust(width) for v in row))
    legend = [f"{c} = {f}" for c, f in zip(codes, full, strict=True) if c != f]
    if legend:
        lines.append("classes: " + "; ".join(legend))
    return lines
